"""
``namo-recovery``: the command line of the numerical core (no ROS needed).

Bad arguments get a one-line error and exit code 2, never a traceback.
"""

import argparse
import json
import sys

import numpy as np

from .errors import ConfigError
from .gestures import load_library
from .kinematics import forward_kinematics
from .robot_model import load_robot
from .score import COMPONENTS, ScoreWeights, SimilarityScore

EXIT_USAGE = 2


class UsageError(Exception):
    """A bad command-line value; reported on one line with exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise UsageError(message)


def _fmt_vec(v, width=8, prec=2):
    return '(' + ', '.join(f'{x:{width}.{prec}f}' for x in v) + ')'


def _fmt_deg(q):
    return '[' + ', '.join(f'{x:7.2f}' for x in np.degrees(q)) + ']'


def _load_models(args):
    robot = load_robot(args.robot_file)
    library = load_library(robot, args.gesture_file)
    return robot, library


def cmd_show(args, out):
    """Print the gesture library with every keyframe's landmarks."""
    robot, library = _load_models(args)
    out.write(f'robot: {robot.name} ({robot.source})\n')
    out.write(f'library: {len(library)} gestures ({library.source})\n')
    for side in ('right', 'left'):
        out.write(f'lock averages, {side} arm (deg): '
                  f'{_fmt_deg(library.lock_averages(side))}\n')
    for gesture in library:
        out.write(f'\n{gesture.name}: arms {"+".join(gesture.arms)}, '
                  f'{"two-handed" if gesture.two_handed else "one-handed"}'
                  f'{" - " + gesture.description if gesture.description else ""}\n')
        for k, kf in enumerate(gesture.keyframes):
            out.write(f'  keyframe {k} at t = {kf.time_from_start:g} s\n')
            for side in ('right', 'left'):
                q = kf.arm(side)
                out.write(f'    {side:5s} q (deg) {_fmt_deg(q)}\n')
                if side not in gesture.arms:
                    continue
                lm = forward_kinematics(robot, q, side)
                out.write(f'          elbow {_fmt_vec(lm.elbow)} mm\n')
                out.write(f'          wrist {_fmt_vec(lm.wrist)} mm\n')
                out.write(f'          tip   {_fmt_vec(lm.tip)} mm\n')
    return 0


def _parse_angles(values, option):
    if values is None:
        return None
    if len(values) != 7:
        raise UsageError(f'{option}: expected 7 angles in degrees, got {len(values)}')
    try:
        q = np.radians([float(v) for v in values])
    except ValueError as exc:
        raise UsageError(f'{option}: {exc}') from None
    if not np.all(np.isfinite(q)):
        raise UsageError(f'{option}: angles must be finite, got {" ".join(values)}')
    return q


def cmd_score(args, out):
    """Score one pose against a gesture and print the breakdown."""
    robot, library = _load_models(args)
    try:
        gesture = library[args.gesture]
    except KeyError as exc:
        raise UsageError(f'--gesture: {exc.args[0]}') from None
    if not 0 <= args.keyframe < len(gesture.keyframes):
        raise UsageError(f'--keyframe: gesture {gesture.name} has keyframes '
                         f'0..{len(gesture.keyframes) - 1}, got {args.keyframe}')
    q_right = _parse_angles(args.right, '--right')
    q_left = _parse_angles(args.left, '--left')
    scorer = SimilarityScore.for_gesture(robot, gesture, args.keyframe, ScoreWeights())
    total, parts = scorer(q_right, q_left, breakdown=True)
    if args.json:
        doc = {'gesture': gesture.name, 'keyframe': args.keyframe, 'score': float(total[0]),
               'components': {c: float(parts[c][0]) for c in COMPONENTS}}
        out.write(json.dumps(doc, indent=2) + '\n')
        return 0
    out.write(f'gesture {gesture.name} (keyframe {args.keyframe}): score {total[0]:.4f}\n')
    units = {'palm': 'deg'}
    for c in COMPONENTS:
        if c.endswith('_lr') and not gesture.two_handed:
            continue
        out.write(f'  {c:9s} {parts[c][0]:10.4f} {units.get(c, "mm")}\n')
    return 0


def build_parser():
    """Build the argument parser; later issues register more subcommands here."""
    parser = _Parser(prog='namo-recovery',
                     description='Joint-failure recovery for the Namo gesture robot.')
    parser.add_argument('--robot-file', default=None,
                        help='robot model YAML (default: the packaged Namo model)')
    parser.add_argument('--gesture-file', default=None,
                        help='gesture library YAML (default: the packaged library)')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)
    sub.required = True

    p = sub.add_parser('show', help='print the gesture library and its landmarks')
    p.set_defaults(func=cmd_show)

    p = sub.add_parser('score', help='score a pose against a gesture')
    p.add_argument('--gesture', required=True, help='gesture name, e.g. wai')
    p.add_argument('--keyframe', type=int, default=0, help='keyframe index (default 0)')
    p.add_argument('--right', nargs='+', required=True, metavar='DEG',
                   help='right-arm angles q1..q7 in degrees')
    p.add_argument('--left', nargs='+', metavar='DEG',
                   help="left-arm angles q1..q7 in degrees (default: the gesture's)")
    p.add_argument('--json', action='store_true', help='print one JSON document')
    p.set_defaults(func=cmd_score)
    return parser


def main(argv=None, out=None):
    """Entry point of ``namo-recovery``; returns the exit code."""
    out = out or sys.stdout
    try:
        args = build_parser().parse_args(argv)
        return args.func(args, out)
    except UsageError as exc:
        sys.stderr.write(f'namo-recovery: error: {exc}\n')
        return EXIT_USAGE
    except (ConfigError, FileNotFoundError) as exc:
        sys.stderr.write(f'namo-recovery: error: {exc}\n')
        return EXIT_USAGE
    except BrokenPipeError:
        # The reader went away (e.g. `| head`); nothing left to say.
        sys.stderr.close()
        return 0


if __name__ == '__main__':
    sys.exit(main())
