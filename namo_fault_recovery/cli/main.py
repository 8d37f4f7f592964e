"""
``namo-recovery``: the command line of the numerical core (no ROS needed).

Bad arguments get a one-line error and exit code 2, never a traceback.
"""

import json
import sys

import numpy as np

from .common import gesture_and_keyframe, parse_faults, Parser, UsageError
from ..errors import ConfigError
from ..model.gestures import load_library
from ..model.kinematics import forward_kinematics
from ..model.robot import load_robot
from ..objective.score import COMPONENTS, ScoreWeights, SimilarityScore

EXIT_USAGE = 2


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
    gesture = gesture_and_keyframe(library, args.gesture, args.keyframe)
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


def solve_document(report, robot):
    """Return the stable JSON document of a reconfiguration (schema in the README)."""
    locks_deg = {j: float(np.degrees(a)) for j, a in report.locks.items()}
    gestures = []
    for g in report.gestures:
        frames = [{'time_from_start': kf.time_from_start,
                   'right_deg': np.degrees(kf.right).round(6).tolist(),
                   'left_deg': np.degrees(kf.left).round(6).tolist()} for kf in g.keyframes]
        gestures.append({
            'name': g.name,
            'right_deg': frames[0]['right_deg'],
            'left_deg': frames[0]['left_deg'],
            'keyframes': frames,
            'lock_deg': locks_deg,
            'free_joints': list(g.free_joints),
            'score_before': g.score_before,
            'score_after': g.score_after,
            'breakdown': g.breakdown,
            'wall_time_s': g.wall_time,
            'status': g.status,
            'stage': g.stage,
            'stage1_score': g.stage1_score,
            'collides': g.collides,
            'colliding_pairs': list(g.colliding_pairs),
        })
    return {
        'schema': 'namo_fault_recovery.solve/1',
        'robot': robot.name,
        'algorithm': report.algorithm,
        'preset': report.preset,
        'seed': report.seed,
        'deadline_s': report.deadline,
        'lock_strategy': report.lock_strategy,
        'faults': locks_deg,
        'frozen_arms': list(report.frozen_arms),
        'notes': list(report.notes),
        'wall_time_s': report.wall_time,
        'success': report.success,
        'gestures': gestures,
    }


def cmd_solve(args, out):
    """Reconfigure gestures for a fault set and print the result."""
    from ..recovery.keyframes import reconfigure_library
    robot, library = _load_models(args)
    faults = parse_faults(robot, args.fault)
    for name in args.gesture or []:
        if name not in library.names:
            raise UsageError(f'--gesture: unknown gesture {name!r}; expected one of '
                             f'{", ".join(library.names)}')
    if args.deadline is not None and not (np.isfinite(args.deadline) and args.deadline > 0):
        raise UsageError(f'--deadline: expected a positive number of seconds, '
                         f'got {args.deadline}')
    try:
        report = reconfigure_library(
            robot, library, faults, algorithm=args.algorithm, preset=args.preset,
            deadline=args.deadline, seed=args.seed, gestures=args.gesture,
            lock_strategy=args.lock_strategy, bimanual=args.bimanual,
            collision=not args.no_collision)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.json:
        out.write(json.dumps(solve_document(report, robot), indent=2) + '\n')
        return 0
    out.write(f'algorithm {report.algorithm} ({report.preset}), seed {report.seed}, '
              f'deadline {report.deadline} s, library time {report.wall_time * 1000:.1f} ms\n')
    out.write('locks (deg): ' + ', '.join(f'{j} = {np.degrees(a):.2f}'
                                          for j, a in report.locks.items()) + '\n')
    for note in report.notes:
        out.write(f'note: {note}\n')
    for g in report.gestures:
        extra = ' stage 2 (both arms)' if g.stage == 2 else ''
        if g.collides:
            extra += ' COLLIDES: ' + ', '.join(g.colliding_pairs)
        out.write(f'\n{g.name}: score {g.score_before:.4f} -> {g.score_after:.4f} '
                  f'[{g.status}]{extra}, {g.wall_time * 1000:.1f} ms\n')
        for k, kf in enumerate(g.keyframes):
            out.write(f'  keyframe {k} right (deg) {_fmt_deg(kf.right)}\n')
            out.write(f'  keyframe {k} left  (deg) {_fmt_deg(kf.left)}\n')
        out.write('  breakdown: ' + ', '.join(f'{c} {v:.3f}' for c, v in g.breakdown.items())
                  + '\n')
    return 0


def build_parser():
    """Build the argument parser; later issues register more subcommands here."""
    parser = Parser(prog='namo-recovery',
                    description='Joint-failure recovery for the Namo gesture robot.')
    parser.add_argument('--robot-file', default=None,
                        help='robot model YAML (default: the packaged Namo model)')
    parser.add_argument('--gesture-file', default=None,
                        help='gesture library YAML (default: the packaged library)')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=Parser)
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

    from ..recovery.locks import LOCK_STRATEGIES
    from ..optimize import ALGORITHMS, PRESETS
    from ..recovery.keyframes import BIMANUAL_MODES
    p = sub.add_parser('solve', help='reconfigure the library for a fault set')
    p.add_argument('--fault', action='append', required=True, metavar='JOINT[=DEG]',
                   help='a failed joint, optionally with the angle (deg) it is held at; '
                        'repeat for several')
    p.add_argument('--gesture', action='append', metavar='G',
                   help='only this gesture (repeatable; default: the whole library)')
    p.add_argument('--algorithm', choices=sorted(ALGORITHMS), default='abc')
    p.add_argument('--preset', choices=PRESETS, default='default',
                   help="'default' (our tuned ABC) or 'paper' (the paper's Table 3)")
    p.add_argument('--lock-strategy', choices=LOCK_STRATEGIES, default='average')
    p.add_argument('--bimanual', choices=BIMANUAL_MODES, default='auto',
                   help='stage 2 for two-handed gestures: the healthy arm moves too '
                        "('auto': when stage 1 scores above the threshold)")
    p.add_argument('--no-collision', action='store_true',
                   help='ignore self-collision (for comparison with the paper)')
    p.add_argument('--seed', type=int, default=None, help='seed for a reproducible run')
    p.add_argument('--deadline', type=float, default=1.0,
                   help='budget for the whole library in seconds (default 1.0)')
    p.add_argument('--json', action='store_true',
                   help='print one JSON document (schema in the README)')
    p.set_defaults(func=cmd_solve)
    from . import bench, beyond, export, player_commands, ros_commands
    bench_sub = bench.register(sub)
    beyond.register(bench_sub)
    ros_commands.register(sub)               # fault, clear, reconfigure, library, demo
    ros_commands.register_bench(bench_sub)   # bench latency
    export.register(sub)                     # export --format play_motion2
    player_commands.register(sub, bench_sub)   # play, bench detection
    from . import urdf as urdf_cli
    urdf_cli.register(sub)                   # urdf
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
