"""
Population optimisers with one scipy/pymoo-shaped API, free of ROS.

A :class:`Problem` holds bounds and a batched objective; an algorithm object holds its
options; :func:`minimize` runs one on the other within a :class:`Clock` (the one
wall-clock deadline and cancel flag of the caller) and returns an
:class:`OptimizeResult`::

    res = minimize(problem, ABC.paper(), clock=Clock(1.0), seed=0)
    res.x, res.fun, res.nfev, res.nit, res.status, res.message, res.wall_time

- :mod:`.base`: ``Problem``, ``Algorithm``, ``minimize``, ``OptimizeResult``, ``Clock``;
- :mod:`.bee_colony`: the artificial bee colony (ABC, the paper's and our tuned one);
- :mod:`.ga`, :mod:`.bfoa`, :mod:`.gd`: the paper's comparisons (GA, BFOA, gradient
  descent);
- :mod:`.polish`: the batched quasi-Newton polish;
- :mod:`.registry`: algorithms and presets by name.
"""

from .base import (Algorithm, Clock, minimize, OptimizeResult, Problem, STATUS_CANCELLED,
                   STATUS_DEADLINE, STATUS_DONE)
from .bee_colony import ABC
from .bfoa import BFOA, CellSignal
from .ga import GA
from .gd import GradientDescent
from .polish import polish
from .registry import ALGORITHMS, make_algorithm, PRESETS

__all__ = [
    'ABC', 'ALGORITHMS', 'Algorithm', 'BFOA', 'CellSignal', 'Clock', 'GA', 'GradientDescent',
    'OptimizeResult',
    'PRESETS', 'Problem', 'STATUS_CANCELLED', 'STATUS_DEADLINE', 'STATUS_DONE',
    'make_algorithm', 'minimize', 'polish',
]
