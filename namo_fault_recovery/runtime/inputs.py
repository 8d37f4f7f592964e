"""
Validation of the node's inputs (fault reports and measured joint states), free of ROS.

Each function takes the plain arrays of a ``sensor_msgs/JointState`` and either returns
the parsed content or raises :class:`BadInput` with a one-line reason.  A rejected
message changes nothing: the caller keeps its previous state.
"""

import math

from ..recovery.locks import clamp_lock


MAX_REASON = 300      # characters: a rejected value never makes a reason unbounded
# rad: how far past a limit a *measured* angle may read and still be taken (clamped onto
# the limit).  A joint resting on its hard stop reads beyond it by its encoder's noise
# and the stop's compliance (Talos's shoulder at 0, its upper limit, read +0.0007 rad in
# the simulator); MoveIt accepts a start state this far out (start_state_max_bounds_error).
MEASURED_LIMIT_TOLERANCE = 0.05


class BadInput(ValueError):
    """An input message that is rejected as a whole; the message is the reason."""

    def __init__(self, reason):
        reason = str(reason)
        if len(reason) > MAX_REASON:
            reason = f'{reason[:MAX_REASON]}... ({len(reason)} characters)'
        super().__init__(reason)


def _fmt(value):
    return f'{value:g}' if isinstance(value, float) else repr(value)


def _check_lengths(names, arrays):
    for label, values in arrays.items():
        if len(values) and len(values) != len(names):
            raise BadInput(f'mismatched lengths: {len(names)} names but {len(values)} '
                           f'{label} values (must be empty or one per name)')


def parse_fault(robot, names, positions=(), velocities=(), efforts=()):
    """
    Parse a fault report; return an ordered dict joint -> lock angle (rad) or None.

    ``position[i]``, when present and finite, is the lock angle of ``name[i]``; when the
    position array is empty or the entry is NaN the lock strategy chooses the angle
    (None).  A joint both arms hang from (a torso) is a fault like an arm's: the engine
    holds the torso's lean there (:func:`~..recovery.lean.held_lean`).  Rejected with
    :class:`BadInput`: an empty message, an unknown or repeated
    joint name, arrays whose length does not match ``name``, an infinite position, and
    a position further than :data:`MEASURED_LIMIT_TOLERANCE` outside the joint's limits
    (one within it is clamped onto the limit: a joint stuck on its stop).
    """
    names = list(names)
    positions = list(positions)
    if not names:
        raise BadInput('empty fault message: no joint names (name[] is empty)')
    _check_lengths(names, {'position': positions, 'velocity': list(velocities),
                           'effort': list(efforts)})
    faults = {}
    for i, name in enumerate(names):
        try:                         # an arm's joint, or one both arms hang from (a torso)
            lower, upper, _ = robot.joint_bounds(name)
        except KeyError as exc:
            raise BadInput(exc.args[0]) from None
        if name in faults:
            raise BadInput(f'joint {name!r} appears twice in one fault message')
        angle = None
        if positions:
            value = float(positions[i])
            if math.isinf(value):
                raise BadInput(f'non-finite position {_fmt(value)} for joint {name!r} '
                               f'(use NaN or an empty position array to let the lock '
                               f'strategy choose)')
            if not math.isnan(value):
                if not (lower - MEASURED_LIMIT_TOLERANCE <= value
                        <= upper + MEASURED_LIMIT_TOLERANCE):
                    raise BadInput(
                        f'position {value:.6g} rad ({math.degrees(value):.4g} deg) of joint '
                        f'{name!r} is outside its limits [{lower:.6g}, {upper:.6g}] rad (by '
                        f'more than {MEASURED_LIMIT_TOLERANCE:g} rad)')
                # Within the tolerance of the limits: clamp, so that every published
                # angle is within its limits bit for bit (the engine's own clamp).
                angle = clamp_lock(robot, name, value)
        faults[name] = angle
    return faults


def parse_joint_state(robot, names, positions):
    """
    Parse a measured joint state; return joint -> angle (rad) of the arms' and torso's.

    Joints the robot model does not know (head, wheels, grippers...) are ignored, as on a
    real robot's ``/joint_states``.  Rejected with :class:`BadInput`: a message without
    names or positions, mismatched lengths, and a non-finite angle of an arm joint or one
    further than :data:`MEASURED_LIMIT_TOLERANCE` outside its limits (clamped within it).
    """
    names = list(names)
    positions = list(positions)
    if not names or not positions:
        raise BadInput('empty joint state: no names or no positions')
    _check_lengths(names, {'position': positions})
    measured = {}
    for name, value in zip(names, positions):
        try:                         # an arm's joint, or one both arms hang from (a torso)
            lower, upper, _ = robot.joint_bounds(name)
        except KeyError:
            continue
        value = float(value)
        if not math.isfinite(value):
            raise BadInput(f'non-finite measured position {_fmt(value)} for joint {name!r}')
        if not lower - MEASURED_LIMIT_TOLERANCE <= value <= upper + MEASURED_LIMIT_TOLERANCE:
            raise BadInput(f'measured position {value:.6g} rad of joint {name!r} is outside '
                           f'its limits (by more than {MEASURED_LIMIT_TOLERANCE:g} rad)')
        measured[name] = clamp_lock(robot, name, value)   # on its stop: at its limit
    return measured
