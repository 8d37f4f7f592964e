"""What every ``namo-recovery`` subcommand shares: the one-line usage error."""

import argparse
import math


class UsageError(Exception):
    """A bad command-line value; reported on one line with exit code 2."""


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors become UsageError instead of exiting."""

    def error(self, message):
        raise UsageError(message)


def parse_faults(robot, specs):
    """
    Parse ``--fault JOINT[=DEG]`` options into ``{joint: lock angle (rad) or None}``.

    Raises UsageError naming the option for an unknown joint or a bad angle.
    """
    faults = {}
    for spec in specs:
        joint, sep, value = spec.partition('=')
        try:
            robot.locate_joint(joint)
        except KeyError as exc:
            raise UsageError(f'--fault: {exc.args[0]}') from None
        angle = None
        if sep:
            try:
                angle = math.radians(float(value))
            except ValueError:
                raise UsageError(f'--fault {spec}: expected JOINT=DEG with DEG a number of '
                                 f'degrees, e.g. right_arm_joint2=-14.25') from None
            if not math.isfinite(angle):
                raise UsageError(f'--fault {spec}: the lock angle must be finite')
        faults[joint] = angle
    return faults


def gesture_and_keyframe(library, name, keyframe):
    """Return the gesture named by ``--gesture`` after checking ``--keyframe`` exists."""
    try:
        gesture = library[name]
    except KeyError as exc:
        raise UsageError(f'--gesture: {exc.args[0]}') from None
    if not 0 <= keyframe < len(gesture.keyframes):
        raise UsageError(f'--keyframe: gesture {gesture.name} has keyframes '
                         f'0..{len(gesture.keyframes) - 1}, got {keyframe}')
    return gesture
