"""
A library version explored on the robot (origin ``explored``), scored by what was measured.

Free of ROS.  The gesture player explores one motion of one arm with real trials and the
fingertip tracker, and hands the node the explored keyframes and the correction it fitted
(:class:`~..model.structure.ArmCorrection`).  :func:`explored_library` makes of them the
version the node publishes: the library version the motion was explored from, with that
gesture replaced by the explored keyframes.  Its scores are the tracker's, not the
model's: ``score_after`` / ``tip_error_max_mm`` the largest fingertip error measured at
the typical points, ``score_mean`` / ``tip_error_mm`` their mean (mm); ``score_before``
/ ``score_before_mean`` / ``tip_error_before_mm`` the same of what the first trial at
each typical point measured (the poses of the version explored from).
"""

from dataclasses import replace

import numpy as np

from ..model.robot import ARMS
from ..recovery import pacing
from ..recovery.result import GestureResult

ORIGIN = 'explored'


def explored_library(robot, current, name, times, positions, correction):
    """
    Return ``current`` with gesture ``name`` explored: ``positions`` (T, J) rad at ``times``.

    Raises ValueError (one line) if ``name`` is not in ``current``, the keyframes do
    not match its keyframe count, or its published version leans the torso (the
    exploration moves the arms only).
    """
    if name not in current.names:
        raise ValueError(f'explored gesture {name!r} is not in the library '
                         f'({", ".join(current.names)})')
    base = current[name]
    if base.shared:
        raise ValueError(f'explored {name}: its published version leans the torso '
                         f'({", ".join(base.shared)}); a leaned gesture is not explored')
    positions = np.asarray(positions, dtype=float)
    if positions.shape != (len(base.times), len(robot.joint_names)):
        raise ValueError(f'explored {name}: {positions.shape[0]} keyframes of '
                         f'{positions.shape[-1]} joints; expected {len(base.times)} of '
                         f'{len(robot.joint_names)}')
    lower = np.concatenate([robot.arms[s].lower for s in ARMS if s in robot.arms])
    upper = np.concatenate([robot.arms[s].upper for s in ARMS if s in robot.arms])
    positions = np.clip(positions, lower, upper)   # the profile's limits, to 9 digits
    errors = tuple(float(e) for e in correction.measured_error_mm) or (float('nan'),)
    worst, mean = float(max(errors)), float(np.mean(errors))
    old = correction.unadapted_error_mm
    before = (float(max(old)), float(np.mean(old))) if old else (base.score_after,
                                                                 base.score_mean)
    message = (f'{name}: explored on the robot ({correction.side} arm, {correction.trials} '
               f'trials, {correction.method}): measured {mean:.2f} mm mean, {worst:.2f} mm '
               f'max at {len(correction.measured_error_mm)} typical points; correction '
               f'{correction.describe()}')
    gesture = GestureResult(
        name=name, times=tuple(float(t) for t in times),
        positions=tuple(tuple(float(a) for a in q) for q in positions),
        score_before=before[0], score_after=worst, score_mean=mean,
        score_before_mean=before[1], status='converged', message=message,
        method=ORIGIN, typical_points=len(correction.measured_error_mm),
        tip_error_mm=mean, tip_error_max_mm=worst,
        tip_error_before_mm=before[1] if old else base.tip_error_mm,
        free_joints=base.free_joints, stage=base.stage,
        speed_ratio=pacing.speed_ratio(robot.joint_velocity_limits, list(times), positions),
        right_joints=len(robot.arms['right'].joint_names))
    gestures = tuple(gesture if g.name == name else g for g in current.gestures)
    corrections = dict(current.corrections, **{correction.side: correction.to_dict()})
    return replace(current, gestures=gestures, origin=ORIGIN, corrections=corrections,
                   notes=tuple(current.notes) + (message,), refined_after=None,
                   refines_version=0, wall_time=0.0)
