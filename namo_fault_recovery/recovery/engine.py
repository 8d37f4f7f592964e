"""
The engine's one entry point: a fault set and settings in, an adapted library out.

:func:`recover` is what the node, ``namo-recovery solve``, the benchmarks and the Python
API call.  It takes the robot, the reference library, the fault set, a
:class:`RecoverySettings` (one field per node parameter, with the node's defaults), a
seed and a :class:`~namo_fault_recovery.optimize.base.Clock` that owns the deadline and
the cancel flag, and returns one :class:`~.result.LibraryResult`.  With the same inputs,
the same seed and no deadline it returns the same library whoever asks.  Free of ROS::

    from namo_fault_recovery.recovery.engine import recover, RecoverySettings
    result = recover(robot, library, {'right_arm_joint2': None}, seed=0)
    result.locks, result['wai'].score_after, result.total_score
"""

from dataclasses import asdict, dataclass, field, replace
import math
import time
from typing import Optional, TYPE_CHECKING

import numpy as np

from .keyframes import BIMANUAL_MODES
from .locks import LOCK_STRATEGIES
from .motion import adapt_library, DEFAULT_CONTINUITY, DEFAULT_DISTORTION_MM
from .motion import DEFAULT_STAY_CLOSE, METHODS, typical_points
from .result import LibraryResult, reference_result
from ..model.robot import ARMS
from ..objective.score import ScoreWeights
from ..optimize import ALGORITHMS, PRESETS
from ..optimize.base import Clock

if TYPE_CHECKING:
    from ..model.gestures import GestureLibrary
    from ..model.robot import RobotModel


@dataclass(frozen=True)
class RecoverySettings:
    """
    Every setting that changes the adapted library, named as the node's parameters.

    The defaults are the node's (``config/recovery_node.yaml``).  ``weights`` is a
    :class:`~namo_fault_recovery.objective.score.ScoreWeights` (None: the paper's).
    """

    deadline_sec: float = 1.0
    lock_strategy: str = 'average'
    optimizer: str = 'abc'
    optimizer_preset: str = 'default'
    bimanual: str = 'auto'
    collision_check: bool = True
    tool_length_mm: float = 0.0
    tool_arm: str = 'right'
    trajectory_method: str = 'auto'
    vq_distortion_mm: float = DEFAULT_DISTORTION_MM
    continuity_weight: float = DEFAULT_CONTINUITY
    weights: ScoreWeights = field(default_factory=ScoreWeights)

    def __post_init__(self):
        for name, value, choices in (('lock_strategy', self.lock_strategy, LOCK_STRATEGIES),
                                     ('optimizer', self.optimizer, tuple(ALGORITHMS)),
                                     ('optimizer_preset', self.optimizer_preset,
                                      tuple(PRESETS)),
                                     ('bimanual', self.bimanual, BIMANUAL_MODES),
                                     ('tool_arm', self.tool_arm, ARMS),
                                     ('trajectory_method', self.trajectory_method, METHODS)):
            if value not in choices:
                raise ValueError(f'{name}: unknown value {str(value)[:80]!r}; expected one '
                                 f'of {", ".join(choices)}')
        for name, value, low in (('deadline_sec', self.deadline_sec, 0.0),
                                 ('tool_length_mm', self.tool_length_mm, -1e-12),
                                 ('vq_distortion_mm', self.vq_distortion_mm, 0.0),
                                 ('continuity_weight', self.continuity_weight, -1e-12)):
            if (isinstance(value, bool) or not isinstance(value, (int, float))
                    or not math.isfinite(value) or not value > low):
                raise ValueError(f'{name}: expected a finite number '
                                 f"{'>' if low >= 0 else '>='} 0, got {repr(value)[:80]}")
        if not isinstance(self.collision_check, bool):
            raise ValueError(f'collision_check: expected True or False, got '
                             f'{repr(self.collision_check)[:80]}')
        if self.weights is not None and not isinstance(self.weights, ScoreWeights):
            raise ValueError(f'weights: expected a ScoreWeights or None, got '
                             f'{repr(self.weights)[:80]}')

    def with_changes(self, **changes):
        """Return a copy with some settings changed (validated again)."""
        return replace(self, **changes)

    def public(self):
        """Return the settings as a JSON-ready dict (what a result records)."""
        return asdict(self)


def structure_changed(faults, settings):
    """Return True if the library must be adapted: a fault, or a tool in a hand."""
    return bool(faults) or settings.tool_length_mm > 0


def recover(robot: 'RobotModel', library: 'GestureLibrary', faults: Optional[dict] = None,
            settings: Optional[RecoverySettings] = None, *, seed: Optional[int] = None,
            clock: Optional[Clock] = None, measured: Optional[dict] = None,
            quantisations: Optional[dict] = None,
            optimizer_overrides: Optional[dict] = None) -> LibraryResult:
    """
    Adapt ``library`` to a fault set (and a tool); return a :class:`LibraryResult`.

    ``faults`` maps joint names to a lock angle (rad) or None (the lock strategy chooses).
    ``measured`` maps joints to their measured angles, for the ``measured`` strategy.
    ``clock`` owns the deadline and the cancel flag; None runs with
    ``settings.deadline_sec`` from now, and ``Clock(None)`` runs without a deadline.
    ``quantisations`` are the library's typical points, if the caller keeps them (they
    depend on the library and ``vq_distortion_mm`` only).  ``seed`` None draws one; the
    result records it.  ``optimizer_overrides`` change options of the optimiser's
    preset (e.g. ``{'max_cycles': 10 ** 9}`` so that a deadline binds); they are for
    benchmarks, not node parameters.  ``settings`` goes down to the optimiser unchanged.

    A library of single poses is the paper's problem and is solved as such; when the
    library holds a motion (a gesture of several keyframes) the explored keyframes are
    also drawn gently towards their designed poses (``DEFAULT_STAY_CLOSE`` per deg^2),
    so that neighbouring keyframes stay on one redundant branch.
    """
    settings = settings or RecoverySettings()
    faults = dict(faults or {})
    if clock is None:
        clock = Clock(settings.deadline_sec)
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    seed = int(seed)
    if not structure_changed(faults, settings):
        budget = None if clock.end is None else float(clock.end - clock.start)
        return reference_result(library, budget, settings.public(), seed)
    began = time.monotonic()
    if quantisations is None:
        quantisations = typical_points(robot, library, settings.vq_distortion_mm, clock=clock)
    motion = any(len(g.keyframes) > 1 for g in library)
    result = adapt_library(robot, library, faults, settings, seed=seed, clock=clock,
                           measured=measured, quantisations=quantisations,
                           optimizer_overrides=optimizer_overrides or None,
                           stay_close=DEFAULT_STAY_CLOSE if motion else 0.0)
    # The run's wall time counts the typical points too, for the library and each gesture.
    wall = float(time.monotonic() - began)
    return replace(result, wall_time=wall,
                   gestures=tuple(replace(g, wall_time=wall) for g in result.gestures))
