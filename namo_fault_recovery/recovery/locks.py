"""
Fault sets and lock angles: which joints are locked, and where.

A fault set maps joint names to a lock angle in radians, or to None when the lock
strategy chooses the angle.  Strategies: ``average`` (the paper's: the mean over the
gestures the arm takes part in), ``measured`` (where the joint stopped, from the fault
report or the latest joint state, else the average), ``optimal`` (chosen to be best for
the whole library; see :func:`.keyframes.reconfigure_library`).
"""

import math

import numpy as np

from ..model.robot import ARMS

LOCK_STRATEGIES = ('average', 'measured', 'optimal')


def check_strategy(lock_strategy):
    """Return ``lock_strategy`` or raise a ValueError naming the choices."""
    if lock_strategy not in LOCK_STRATEGIES:
        raise ValueError(f'unknown lock strategy {lock_strategy!r}; expected one of '
                         f'{", ".join(LOCK_STRATEGIES)}')
    return lock_strategy


def validate_angle(robot, joint, angle, what='lock angle'):
    """Return ``(arm, index)`` of ``joint`` after checking ``angle`` (rad) is usable."""
    try:
        side, index = robot.locate_joint(joint)
    except KeyError as exc:
        raise ValueError(exc.args[0]) from None
    if angle is None:
        return side, index
    if isinstance(angle, bool) or not isinstance(angle, (int, float, np.floating)):
        raise ValueError(f'{what} of {joint}: expected a number of radians, got {angle!r}')
    if not math.isfinite(angle):
        raise ValueError(f'{what} of {joint}: expected a finite angle, got {angle!r}')
    arm = robot.arms[side]
    if not robot.within_limits(side, index, angle):
        raise ValueError(f'{what} of {joint}: {angle:.6g} rad ({math.degrees(angle):.2f} deg) '
                         f'is outside the joint limits [{arm.lower[index]:.6g}, '
                         f'{arm.upper[index]:.6g}] rad')
    return side, index


def clamp_lock(robot, joint, angle):
    """
    Return ``angle`` (rad) clamped into the limits of ``joint``, exactly.

    :func:`validate_angle` accepts an angle within ``robot.within_limits``'s tolerance
    of a limit (1e-9 rad); a lock must still never be published beyond the limit, so
    every accepted lock passes through here.  An arm's joint, or one both arms hang from
    (a torso, ``RobotJoints.joint_bounds``).
    """
    lower, upper, _ = robot.joint_bounds(joint)
    return float(min(max(float(angle), lower), upper))


def resolve_locks(robot, library, faults, lock_strategy='average', measured=None):
    """
    Return ``{joint: lock angle (rad)}`` for a fault set, and a list of notes.

    Every angle is clamped into its joint's limits (:func:`clamp_lock`).
    Explicit angles in ``faults`` always win.  Otherwise ``measured`` takes the angle
    from ``measured`` (joint -> rad) when present and falls back to ``average`` with a
    note; ``optimal`` joints get their average here, as the starting point that
    :func:`.keyframes.reconfigure_library` improves on.
    """
    check_strategy(lock_strategy)
    measured = measured or {}
    locks = {}
    notes = []
    for joint, angle in dict(faults).items():
        side, index = validate_angle(robot, joint, angle)
        if angle is None and lock_strategy == 'measured':
            if joint in measured and measured[joint] is not None:
                angle = float(measured[joint])
                validate_angle(robot, joint, angle, 'measured angle')
            else:
                notes.append(f'{joint}: no measured angle; locked at the library average')
        if angle is None:
            angle = float(library.lock_averages(side)[index])
        locks[joint] = clamp_lock(robot, joint, angle)
    return locks, notes


def frozen_arms(robot, joints):
    """Return the arms (in robot order) whose joints are all in ``joints``."""
    joints = set(joints)
    return tuple(side for side in ARMS if set(robot.arms[side].joint_names) <= joints)
