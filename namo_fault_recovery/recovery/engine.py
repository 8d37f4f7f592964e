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
    result.locks, result['wai'].score_after
"""

from dataclasses import asdict, dataclass, field, replace
import math
import time

import numpy as np

from .keyframes import BIMANUAL_MODES
from .locks import check_strategy, frozen_arms
from .motion import adapt_library, DEFAULT_CONTINUITY, DEFAULT_DISTORTION_MM, METHODS
from .motion import typical_points
from .result import GestureResult, LibraryResult, reference_result
from ..model.robot import ARMS
from ..objective.score import ScoreWeights
from ..optimize import ALGORITHMS, PRESETS
from ..optimize.base import Clock


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
        check_strategy(self.lock_strategy)
        for name, value, choices in (('optimizer', self.optimizer, tuple(ALGORITHMS)),
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
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > low):
                raise ValueError(f'{name}: expected a finite number > {max(low, 0.0):g}, '
                                 f'got {str(value)[:80]!r}')

    def with_changes(self, **changes):
        """Return a copy with some settings changed (validated again)."""
        return replace(self, **changes)

    def public(self):
        """Return the settings as a JSON-ready dict (what a result records)."""
        return asdict(self)


def structure_changed(faults, settings):
    """Return True if the library must be adapted: a fault, or a tool in a hand."""
    return bool(faults) or settings.tool_length_mm > 0


def recover(robot, library, faults=None, settings=None, *, seed=None, clock=None,
            measured=None, quantisations=None):
    """
    Adapt ``library`` to a fault set (and a tool); return a :class:`LibraryResult`.

    ``faults`` maps joint names to a lock angle (rad) or None (the lock strategy chooses).
    ``measured`` maps joints to their measured angles, for the ``measured`` strategy.
    ``clock`` owns the deadline and the cancel flag; None runs with
    ``settings.deadline_sec`` from now, and ``Clock(None)`` runs without a deadline.
    ``quantisations`` are the library's typical points, if the caller keeps them (they
    depend on the library and ``vq_distortion_mm`` only).  ``seed`` None draws one; the
    result records it.
    """
    settings = settings or RecoverySettings()
    faults = dict(faults or {})
    if clock is None:
        clock = Clock(settings.deadline_sec)
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    public = settings.public()
    public['seed'] = seed
    if not structure_changed(faults, settings):
        return reference_result(library, settings.deadline_sec, public)
    began = time.monotonic()
    if quantisations is None:
        quantisations = typical_points(robot, library, settings.vq_distortion_mm, clock=clock)
    report = adapt_library(
        robot, library, faults, method=settings.trajectory_method,
        tool_mm=settings.tool_length_mm, tool_arm=settings.tool_arm,
        distortion_mm=settings.vq_distortion_mm, continuity=settings.continuity_weight,
        quantisations=quantisations, algorithm=settings.optimizer,
        preset=settings.optimizer_preset, clock=clock, seed=seed,
        weights=settings.weights, lock_strategy=settings.lock_strategy,
        measured=measured, bimanual=settings.bimanual,
        collision=settings.collision_check)
    wall = time.monotonic() - began
    public['notes'] = list(report.notes)
    engine = report.typical_result
    gestures = []
    for g in report.gestures:
        e = engine[g.name] if engine is not None else None
        gestures.append(GestureResult(
            name=g.name,
            times=tuple(float(kf.time_from_start) for kf in g.keyframes),
            positions=tuple(tuple(float(a) for a in kf.positions()) for kf in g.keyframes),
            score_before=float(g.score_before_max),
            score_after=float(g.score_max),
            wall_time=float(wall), status=str(g.status),
            message=str(e.message if e and g.method == 'keyframes' else g.message),
            collides=bool(g.collides),
            breakdown={k: float(v) for k, v in dict(e.breakdown if e else {}).items()},
            stage=int(e.stage if e else 1),
            colliding_pairs=tuple(str(p) for p in g.colliding_pairs),
            method=g.method, typical_points=len(g.typical),
            tip_error_mm=float(g.tip_error_mean_mm),
            max_jump_deg=float(g.jump_after_deg)))
    # ``per_point`` runs no typical-point engine: its statuses say it all.
    success = (report.deadline_met and (engine is None or engine.success)
               and all(math.isfinite(g.score_after) for g in gestures))
    return LibraryResult(
        gestures=tuple(gestures), faults=faults,
        locks={j: float(a) for j, a in report.locks.items()},
        frozen_arms=frozen_arms(robot, report.locks),
        wall_time=float(wall), deadline=settings.deadline_sec,
        deadline_met=bool(report.deadline_met), success=bool(success),
        cancelled=report.cancelled, settings=public,
        tool_mm=settings.tool_length_mm, tool_arm=settings.tool_arm)
