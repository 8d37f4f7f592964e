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

from .keyframes import SearchOptions
from .lean import held_angles, held_lean, lean_library, with_held
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

    A library with a motion draws its motions' keyframes gently towards their design
    (``DEFAULT_STAY_CLOSE`` per deg^2: neighbouring keyframes stay on one branch).  On a
    robot whose arms hang from shared joints (a torso, :mod:`.lean`),
    ``settings.expand_shared`` adds the torso's lean as the last expansion stage, and a
    shared joint in ``faults`` (stuck) holds its lean in every gesture, made up for by
    the arms.
    """
    settings = settings or RecoverySettings()
    reported = dict(faults or {})
    clock = Clock(settings.deadline_sec) if clock is None else clock
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    seed = int(seed)
    faults, held = held_lean(robot, reported, measured)        # a torso that stuck
    given, t = {j: a for j, a in reported.items() if j in held}, held_angles(robot, held)
    if not structure_changed(faults, settings, robot) and t is None:
        budget = None if clock.end is None else float(clock.end - clock.start)
        return with_held(robot, reference_result(
            library, budget, settings.public(), seed,
            velocity_limits=robot.joint_velocity_limits), held, given)
    began = time.monotonic()
    if quantisations is None:
        quantisations = typical_points(robot, library, settings.vq_distortion_mm, clock=clock)
    motion = any(len(g.keyframes) > 1 for g in library)
    options = SearchOptions(stay_close=DEFAULT_STAY_CLOSE if motion else 0.0,
                            leans=None if t is None else {g.name: t for g in library})
    result = adapt_library(robot, library, faults, settings, seed=seed, clock=clock,
                           measured=measured, quantisations=quantisations,
                           optimizer_overrides=optimizer_overrides or None, options=options)
    if held:
        result = with_held(robot, result, held, given)
    else:
        result = lean_library(robot, library, result, settings, clock=clock, seed=seed,
                              stay_close=options.stay_close, dense=tuple(
                                  n for n, q in quantisations.items() if q is not None))
    # The run's wall time counts the typical points too, for the library and each gesture.
    wall = float(time.monotonic() - began)
    return replace(result, wall_time=wall, corrections=learned_record(robot),
                   gestures=tuple(replace(g, wall_time=wall) for g in result.gestures))
