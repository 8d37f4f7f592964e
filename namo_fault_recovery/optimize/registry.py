"""Algorithms by name, and their presets: the paper's and the product default."""

from .bee_colony import ABC
from .bfoa import BFOA
from .ga import GA
from .gd import GradientDescent

ALGORITHMS = {'abc': ABC, 'ga': GA, 'bfoa': BFOA, 'gd': GradientDescent}
PRESETS = ('default', 'paper')

# The product default: a small colony seeded with the reference pose, run on all gestures
# at once, then a batched quasi-Newton polish of the best two sources (one of them the
# reference start).  Chosen with `namo-recovery bench speed`; see README "Product default".
DEFAULT_ABC = {'n_sources': 8, 'max_cycles': 8, 'limit': 20, 'polish': 2,
               'polish_maxiter': 100, 'polish_ftol': 1e-7, 'use_x0': True}


def make_algorithm(name, preset='default', **overrides):
    """Return an algorithm object by name and preset, with optional setting overrides."""
    if name not in ALGORITHMS:
        raise ValueError(f'unknown algorithm {name!r}; expected one of '
                         f'{", ".join(ALGORITHMS)}')
    if preset not in PRESETS:
        raise ValueError(f'unknown preset {preset!r}; expected one of {", ".join(PRESETS)}')
    cls = ALGORITHMS[name]
    settings = {}
    if name == 'abc' and preset == 'default':
        settings.update(DEFAULT_ABC)
    elif name == 'abc':
        settings.update(ABC.paper().settings())
    settings.update(overrides)
    return cls(**settings)
