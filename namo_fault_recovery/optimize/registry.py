"""Algorithms by name, and their presets: the paper's and the product default."""

from .base import Algorithm
from .bee_colony import ABC
from .bfoa import BFOA
from .ga import GA
from .gd import GradientDescent

ALGORITHMS = {'abc': ABC, 'ga': GA, 'bfoa': BFOA, 'gd': GradientDescent}
PRESETS = ('default', 'paper')

# The product default: a small colony started from the problem's own sources (kinematic
# ones for the keyframe search), run on all gestures at once, then a batched
# quasi-Newton polish of five starts (the best, the reference start and the 3 best
# sources away from the best), restarted from steepest descent where it stalls on a
# kink, for 40 iterations: the keyframe search's least-squares refinement walks the
# rest of the way to the floor.  A polish iteration is one batched call for all starts,
# so five starts for 40 iterations cost about what two for 100 did, and find the best
# basin more often (2026-12-04, `bench robots` against the same optima: Talos 87.9 ->
# 93.6 %, TIAGo++ 86.4 -> 95.0 % of runs within 1 %; solve p95 +10-20 %).  Chosen with
# `namo-recovery bench speed` and `bench robots`; see README "Product default" and
# "Other robots".
DEFAULT_ABC = {'n_sources': 8, 'max_cycles': 8, 'limit': 20, 'polish': 5,
               'polish_maxiter': 40, 'polish_ftol': 1e-7, 'use_x0': True,
               'polish_restart': True, 'informed_starts': True}


def make_algorithm(optimizer: str, optimizer_preset: str = 'default',
                   **optimizer_overrides) -> Algorithm:
    """
    Return an algorithm object by name and preset, with optional option overrides.

    ``optimizer`` and ``optimizer_preset`` are named like the settings they come from
    (:class:`~namo_fault_recovery.recovery.engine.RecoverySettings`); the overrides change
    single options of the preset (e.g. ``max_cycles``).
    """
    if optimizer not in ALGORITHMS:
        raise ValueError(f'unknown algorithm {optimizer!r}; expected one of '
                         f'{", ".join(ALGORITHMS)}')
    if optimizer_preset not in PRESETS:
        raise ValueError(f'unknown preset {optimizer_preset!r}; expected one of '
                         f'{", ".join(PRESETS)}')
    cls = ALGORITHMS[optimizer]
    options = {}
    if optimizer == 'abc' and optimizer_preset == 'default':
        options.update(DEFAULT_ABC)
    elif optimizer == 'abc':
        options.update(ABC.paper().options())
    options.update(optimizer_overrides)
    return cls(**options)
