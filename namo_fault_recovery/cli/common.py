"""What the ``namo-recovery`` subcommands share: the usage error, faults, settings options."""

import argparse
from contextlib import contextmanager
import math


class UsageError(Exception):
    """A bad command-line value; reported on one line with exit code 2."""


@contextmanager
def writing_out(path):
    """Write ``--out`` within it: a failed write is one UsageError naming the file and why."""
    try:
        yield path
    except OSError as exc:
        raise UsageError(f'--out: cannot write {path}: {exc.strerror or exc}') from None


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors become UsageError instead of exiting."""

    def error(self, message):
        raise UsageError(message)


# The commands that take the global --robot-profile (a robot from its URDF); the others run
# on a DH robot file and refuse it (main()).
PROFILE_COMMANDS = ('show', 'score', 'solve', 'export', 'precompute')


def option_models(args):
    """
    Return ``(robot, library)`` of ``--robot-file`` or ``--robot-profile`` and ``--gesture-file``.

    The options are read as the node reads its ``robot_file`` and ``robot_profile``
    parameters (:func:`~..runtime.robot_source.robot_source`: the two exclude each other).
    """
    from ..runtime.robot_source import load_models, robot_source
    try:
        source = robot_source({'robot_file': getattr(args, 'robot_file', None),
                               'robot_profile': getattr(args, 'robot_profile', None)})
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return load_models(source, getattr(args, 'gesture_file', None))


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


def setting_options():
    """Return the engine's settings that are command-line options (``Setting.cli``)."""
    from ..recovery.settings import SETTINGS
    return tuple(s for s in SETTINGS if s.cli)


def add_setting_options(p, deadline=False):
    """
    Add the engine's setting options (``--deadline-sec`` only with ``deadline``).

    Each option is named like the node's parameter (``--vq-distortion-mm`` for
    ``vq_distortion_mm``, plus its aliases), with its choices, default and help from the
    declaration (:mod:`~namo_fault_recovery.recovery.settings`); a flag gets
    ``--name`` / ``--no-name``.  Shared by ``solve`` and ``precompute``;
    :func:`engine_settings` reads them back.
    """
    for s in setting_options():
        if s.name == 'deadline_sec' and not deadline:
            continue
        names = [s.option] + [a for a in s.aliases if not a.startswith('--no-')]
        kwargs = {'default': s.default, 'help': s.cli_help}
        if s.value_type is bool:
            kwargs['action'] = argparse.BooleanOptionalAction
        elif s.choices is not None:
            kwargs['choices'] = s.choices
        else:
            kwargs.update(type=s.value_type, metavar=s.metavar)
        p.add_argument(*names, **kwargs)
        for alias in s.aliases:
            if alias.startswith('--no-'):
                p.add_argument(alias, dest=s.name, action='store_false',
                               help=f'same as --no-{s.option[2:]}')


def engine_settings(args, omit=()):
    """
    Return the RecoverySettings of the setting options that ``args`` has.

    The options are those of :func:`add_setting_options`; a setting without its option,
    or named in ``omit``, keeps the node's default.  A bad value is a UsageError naming
    the option.
    """
    from ..recovery.settings import RecoverySettings
    values = {s.name: getattr(args, s.name) for s in setting_options()
              if hasattr(args, s.name) and s.name not in omit}
    try:
        return RecoverySettings(**values)
    except ValueError as exc:
        raise UsageError(f'--{str(exc).replace("_", "-", str(exc).index(":"))}'
                         if ':' in str(exc) else str(exc)) from None
