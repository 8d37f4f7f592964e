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

from dataclasses import replace
import time
from typing import Optional, TYPE_CHECKING

import numpy as np

from .lean import lean_library
from .motion import adapt_library, DEFAULT_STAY_CLOSE, typical_points
from .result import LibraryResult, reference_result
from .settings import RecoverySettings
from ..optimize.base import Clock

if TYPE_CHECKING:
    from ..model.gestures import GestureLibrary
    from ..model.robot import RobotModel


def structure_changed(faults, settings, robot=None):
    """Return True if the library must be adapted: a fault, a tool, a learned correction."""
    return (bool(faults) or settings.tool_length_mm > 0
            or bool(robot is not None and robot.learned))


def learned_record(robot) -> dict:
    """Return ``{side: correction dict}`` of the corrections ``robot`` carries (learned)."""
    return {a.correction.side: a.correction.to_dict() for a in robot.learned}


def recover(robot: 'RobotModel', library: 'GestureLibrary', faults: Optional[dict] = None,
            settings: Optional[RecoverySettings] = None, *, seed: Optional[int] = None,
            clock: Optional[Clock] = None, measured: Optional[dict] = None,
            quantisations: Optional[dict] = None,
            optimizer_overrides: Optional[dict] = None) -> LibraryResult:
    """
    Adapt ``library`` to a fault set (and a tool); return a :class:`LibraryResult`.

    A ``robot`` carrying corrections learned on the robot (``robot.with_learned``,
    :mod:`~..model.structure`) is searched on its corrected model, its nominal
    kinematics the reference; the result records them (``corrections``).
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
    library holds a motion (a gesture of several keyframes) the explored keyframes of
    its motions are also drawn gently towards their designed poses
    (``DEFAULT_STAY_CLOSE`` per deg^2), so that neighbouring keyframes stay on one
    redundant branch; its single poses are not (they have no neighbour).  On a robot
    whose arms hang from shared joints, ``settings.expand_shared`` adds the last stage
    of the staged expansion, the torso's lean (:mod:`.lean`).
    """
    settings = settings or RecoverySettings()
    faults = dict(faults or {})
    if clock is None:
        clock = Clock(settings.deadline_sec)
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    seed = int(seed)
    if not structure_changed(faults, settings, robot):
        budget = None if clock.end is None else float(clock.end - clock.start)
        return reference_result(library, budget, settings.public(), seed,
                                velocity_limits=robot.joint_velocity_limits)
    began = time.monotonic()
    if quantisations is None:
        quantisations = typical_points(robot, library, settings.vq_distortion_mm, clock=clock)
    motion = any(len(g.keyframes) > 1 for g in library)
    stay_close = DEFAULT_STAY_CLOSE if motion else 0.0
    result = adapt_library(robot, library, faults, settings, seed=seed, clock=clock,
                           measured=measured, quantisations=quantisations,
                           optimizer_overrides=optimizer_overrides or None,
                           stay_close=stay_close)
    result = lean_library(robot, library, result, settings, clock=clock, seed=seed,
                          stay_close=stay_close,
                          dense=tuple(n for n, q in quantisations.items() if q is not None))
    # The run's wall time counts the typical points too, for the library and each gesture.
    wall = float(time.monotonic() - began)
    return replace(result, wall_time=wall, corrections=learned_record(robot),
                   gestures=tuple(replace(g, wall_time=wall) for g in result.gestures))
