"""
Population optimisers with one scipy/pymoo-shaped API, free of ROS.

A :class:`Problem` holds bounds and a batched objective; an algorithm object holds the
settings; :func:`minimize` runs one on the other under a wall-clock deadline and returns
an :class:`OptimizeResult`::

    res = minimize(problem, ABC.paper(), deadline=1.0, seed=0)
    res.x, res.fun, res.nfev, res.nit, res.status, res.message, res.wall_time
"""

from .base import (Algorithm, Clock, minimize, OptimizeResult, Problem, STATUS_CANCELLED,
                   STATUS_DEADLINE, STATUS_DONE)
from .bee_colony import ABC
from .bfoa import BFOA
from .ga import GA
from .gd import GradientDescent
from .polish import polish
from .registry import ALGORITHMS, make_algorithm, PRESETS

__all__ = [
    'ABC', 'ALGORITHMS', 'Algorithm', 'BFOA', 'Clock', 'GA', 'GradientDescent', 'OptimizeResult',
    'PRESETS', 'Problem', 'STATUS_CANCELLED', 'STATUS_DEADLINE', 'STATUS_DONE',
    'make_algorithm', 'minimize', 'polish',
]
