"""What the ``namo-recovery`` subcommands share: the usage error, faults, settings options."""

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


# The setting options (of ``solve``, ``precompute``): RecoverySettings fields, node parameters.
SETTING_OPTIONS = ('deadline_sec', 'lock_strategy', 'optimizer', 'optimizer_preset',
                   'bimanual', 'collision_check', 'tool_length_mm', 'tool_arm',
                   'trajectory_method', 'vq_distortion_mm', 'continuity_weight')


def add_setting_options(p):
    """
    Add the engine's setting options but the deadline, named like the node's parameters.

    Shared by ``solve`` and ``precompute``; :func:`engine_settings` reads them back.
    """
    import argparse
    from ..model.robot import ARMS
    from ..optimize import ALGORITHMS, PRESETS
    from ..recovery.engine import RecoverySettings
    from ..recovery.keyframes import BIMANUAL_MODES
    from ..recovery.locks import LOCK_STRATEGIES
    from ..recovery.motion import METHODS
    d = RecoverySettings()
    p.add_argument('--lock-strategy', choices=LOCK_STRATEGIES, default=d.lock_strategy)
    p.add_argument('--optimizer', '--algorithm', choices=sorted(ALGORITHMS),
                   default=d.optimizer)
    p.add_argument('--optimizer-preset', '--preset', choices=PRESETS,
                   default=d.optimizer_preset,
                   help="'default' (our tuned ABC) or 'paper' (the paper's Table 3)")
    p.add_argument('--bimanual', choices=BIMANUAL_MODES, default=d.bimanual,
                   help='stage 2 for two-handed gestures: the healthy arm moves too '
                        "('auto': when stage 1 scores above the threshold)")
    p.add_argument('--collision-check', action=argparse.BooleanOptionalAction,
                   default=d.collision_check,
                   help='keep arms and torso apart and report what still collides')
    p.add_argument('--no-collision', dest='collision_check', action='store_false',
                   help='same as --no-collision-check')
    p.add_argument('--tool-length-mm', type=float, default=d.tool_length_mm, metavar='MM',
                   help='a tool lengthening the hand of --tool-arm (mm)')
    p.add_argument('--tool-arm', choices=ARMS, default=d.tool_arm)
    p.add_argument('--trajectory-method', choices=METHODS, default=d.trajectory_method)
    p.add_argument('--vq-distortion-mm', type=float, default=d.vq_distortion_mm, metavar='MM',
                   help='typical-point threshold (mm of fingertip)')
    p.add_argument('--continuity-weight', type=float, default=d.continuity_weight,
                   metavar='W', help='per-point jump penalty (per deg^2)')


def engine_settings(args, omit=()):
    """
    Return the RecoverySettings of the setting options that ``args`` has.

    The options are those of :func:`add_setting_options` (and ``--deadline-sec``); a
    setting without its option, or named in ``omit``, keeps the node's default.  A bad
    value is a UsageError naming the option.
    """
    from ..recovery.engine import RecoverySettings
    values = {name: getattr(args, name) for name in SETTING_OPTIONS
              if hasattr(args, name) and name not in omit}
    try:
        return RecoverySettings(**values)
    except ValueError as exc:
        raise UsageError(f'--{str(exc).replace("_", "-", str(exc).index(":"))}'
                         if ':' in str(exc) else str(exc)) from None
