"""
``namo-recovery``: the command line of the numerical core (no ROS needed).

Bad arguments get a one-line error and exit code 2, never a traceback.
"""

import json
import sys

import numpy as np

from .common import add_setting_options, engine_settings, gesture_and_keyframe
from .common import option_models, parse_faults, Parser, PROFILE_COMMANDS, UsageError
from ..errors import ConfigError, EXIT_USAGE
from ..model.kinematics import arm_joint_count, forward_kinematics
from ..objective.score import COMPONENTS, ScoreWeights, SimilarityScore


def _fmt_vec(v, width=8, prec=2):
    return '(' + ', '.join(f'{x:{width}.{prec}f}' for x in v) + ')'


def _fmt_deg(q):
    return '[' + ', '.join(f'{x:7.2f}' for x in np.degrees(q)) + ']'


def cmd_show(args, out):
    """Print the gesture library with every keyframe's landmarks."""
    robot, library = option_models(args)
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


def _parse_angles(values, option, count):
    if values is None:
        return None
    if len(values) != count:
        raise UsageError(f'{option}: expected {count} angles in degrees, got {len(values)}')
    try:
        q = np.radians([float(v) for v in values])
    except ValueError as exc:
        raise UsageError(f'{option}: {exc}') from None
    if not np.all(np.isfinite(q)):
        raise UsageError(f'{option}: angles must be finite, got {" ".join(values)}')
    return q


def cmd_score(args, out):
    """Score one pose against a gesture and print the breakdown."""
    robot, library = option_models(args)
    gesture = gesture_and_keyframe(library, args.gesture, args.keyframe)
    q_right = _parse_angles(args.right, '--right', arm_joint_count(robot, 'right'))
    q_left = _parse_angles(args.left, '--left', arm_joint_count(robot, 'left'))
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


SOLVE_SCHEMA = 'namo_fault_recovery.solve/2'


def solve_document(result, robot, library):
    """
    Return the JSON document of ``solve``: one :class:`LibraryResult`, as the node has it.

    Schema ``namo_fault_recovery.solve/2``.  Angles in radians, as the node publishes
    them, unless a key ends in ``_deg``.  Top level:

    - ``schema``; ``robot`` (model name); ``library`` (gesture file read);
    - ``seed``: the seed of the run (rerun with ``--seed`` for the same library);
    - ``settings``: the run's settings, named like the node's parameters
      (``deadline_sec``, ``lock_strategy``, ``optimizer``, ``optimizer_preset``,
      ``bimanual``, ``collision_check``, ``tool_length_mm``, ``tool_arm``,
      ``trajectory_method``, ``vq_distortion_mm``, ``continuity_weight``, ``weights``);
    - ``deadline``: the budget in s (null: no deadline); ``deadline_met``, ``cancelled``,
      ``success``; ``wall_time`` (s); ``nfev`` (objective evaluations of the run);
      ``origin`` (how the library was made); ``refined_after`` and ``refines_version``
      (a node's refined version only: null and 0 here);
    - ``faults``: joint -> requested lock angle (rad; null: chosen by the strategy);
      ``locks``: joint -> lock angle used (rad); ``locks_deg``: the same in degrees;
      ``frozen_arms``; ``notes``; ``tool_mm``, ``tool_arm``;
    - ``total_score``: the sum of the gestures' ``score_after``;
    - ``gestures``: one entry per gesture, the fields of
      :class:`~namo_fault_recovery.recovery.result.GestureResult`: ``name``, ``times``
      (s) and ``positions`` (per keyframe 14 angles, right arm joints 1-7 then left),
      ``score_before`` / ``score_after`` (worst keyframe: locks applied and nothing
      re-optimised / as published), ``score_before_mean`` / ``score_mean``,
      ``breakdown``, ``status``, ``message``, ``stage``, ``stage1_score``,
      ``expansion_stage``, ``free_joints``, ``nfev``, ``wall_time``, ``collides``,
      ``colliding_pairs``, ``method``, ``typical_points``, ``typical_indices``,
      ``kriging_sigma_deg``, ``tip_error_before_mm``, ``tip_error_mm``,
      ``tip_error_max_mm``, ``max_jump_designed_deg``, ``max_jump_before_deg`` and
      ``max_jump_deg``.
    """
    doc = {'schema': SOLVE_SCHEMA, 'robot': robot.name, 'library': str(library.source)}
    doc.update(result.to_dict())
    doc['locks_deg'] = {j: float(np.degrees(a)) for j, a in result.locks.items()}
    doc['total_score'] = result.total_score
    return doc


def solve_settings(args):
    """
    Return ``(RecoverySettings, clock)`` from the ``solve`` options.

    Options are named like the node's parameters and default to the node's values.
    ``--deadline-sec 0`` or ``--no-deadline`` runs without a deadline.
    """
    from ..optimize.base import Clock
    no_deadline = args.no_deadline or args.deadline_sec == 0
    settings = engine_settings(args, omit=('deadline_sec',) if no_deadline else ())
    return settings, Clock(None if no_deadline else settings.deadline_sec)


def cmd_solve(args, out):
    """Recover the library for a fault set with :func:`recover`; print the result."""
    from dataclasses import replace
    from ..benchmarks.common import recover_subset
    robot, library = option_models(args)
    faults = parse_faults(robot, args.fault or [])
    settings, clock = solve_settings(args)
    for name in args.gesture or ():
        if name not in library.names:
            raise UsageError(f'--gesture: unknown gesture {name!r}; expected one of '
                             f'{", ".join(library.names)}')
    try:
        result, notes = recover_subset(robot, library, faults, settings, args.gesture,
                                       seed=args.seed, clock=clock)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    result = replace(result, faults=dict(faults), notes=tuple(notes) + result.notes)
    if args.json:
        out.write(json.dumps(solve_document(result, robot, library), indent=2) + '\n')
        return 0
    write_solve_text(result, out)
    return 0


def write_solve_text(result, out):
    """Print a LibraryResult for a person: settings, locks, and every gesture's keyframes."""
    s = result.settings
    deadline = 'none' if result.deadline is None else f'{result.deadline:g} s'
    out.write(f"optimizer {s['optimizer']} ({s['optimizer_preset']}), lock strategy "
              f"{s['lock_strategy']}, bimanual {s['bimanual']}, collision check "
              f"{'on' if s['collision_check'] else 'off'}, trajectory method "
              f"{s['trajectory_method']}, seed {result.seed}, deadline {deadline}, "
              f'library time {result.wall_time * 1000:.1f} ms, total score '
              f'{result.total_score:.4f}\n')
    if result.tool_mm > 0:
        out.write(f'tool: {result.tool_mm:g} mm in the {result.tool_arm} hand\n')
    out.write('locks (deg): ' + (', '.join(f'{j} = {np.degrees(a):.2f}'
                                           for j, a in result.locks.items()) or 'none') + '\n')
    for note in result.notes:
        out.write(f'note: {note}\n')
    for g in result.gestures:
        extra = ' stage 2 (both arms)' if g.stage == 2 else ''
        if g.method != 'keyframes':
            extra += f' {g.method}'
        if g.collides:
            extra += ' COLLIDES: ' + ', '.join(g.colliding_pairs)
        out.write(f'\n{g.name}: score {g.score_before:.4f} -> {g.score_after:.4f} '
                  f'[{g.status}]{extra}, {g.wall_time * 1000:.1f} ms\n')
        for k, kf in enumerate(g.keyframes):
            out.write(f'  keyframe {k} right (deg) {_fmt_deg(kf.right)}\n')
            out.write(f'  keyframe {k} left  (deg) {_fmt_deg(kf.left)}\n')
        if g.breakdown:
            out.write('  breakdown: ' + ', '.join(f'{c} {v:.3f}'
                                                  for c, v in g.breakdown.items()) + '\n')


def add_solve_parser(sub):
    """Add ``solve``: options named like the node's parameters, with its defaults."""
    p = sub.add_parser('solve', help='recover the library for a fault set (as the node does)')
    p.add_argument('--fault', action='append', metavar='JOINT[=DEG]',
                   help='a failed joint, optionally with the angle (deg) it is held at; '
                        'repeat for several (none: the reference library, unless a tool)')
    p.add_argument('--gesture', action='append', metavar='G',
                   help='only this gesture (repeatable; default: the whole library); lock '
                        'angles stay those of the whole library')
    add_setting_options(p, deadline=True)
    p.add_argument('--no-deadline', action='store_true', help='run without a deadline')
    p.add_argument('--seed', type=int, default=None,
                   help='seed for a reproducible run (default: drawn, and printed)')
    p.add_argument('--json', action='store_true',
                   help=f'print one JSON document (schema {SOLVE_SCHEMA})')
    p.set_defaults(func=cmd_solve)
    return p


def build_parser():
    """Build the argument parser; later issues register more subcommands here."""
    parser = Parser(prog='namo-recovery', allow_abbrev=False,
                    description='Joint-failure recovery for the Namo gesture robot.')
    parser.add_argument('--robot-file', default=None,
                        help='robot model YAML (default: the packaged Namo model)')
    parser.add_argument('--robot-profile', default=None, metavar='FILE',
                        help="any robot's recovery profile, its URDF named inside (as the "
                             "node's robot_profile; commands: " + ', '.join(PROFILE_COMMANDS)
                             + '); give its --gesture-file too')
    parser.add_argument('--gesture-file', default=None,
                        help='gesture library YAML (default: the packaged library, the '
                             'four gestures; bench motion: config/demo_motions.yaml, the '
                             'demo library with the dense circle)')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=Parser)
    sub.required = True

    p = sub.add_parser('show', help='print the gesture library and its landmarks')
    p.set_defaults(func=cmd_show)

    p = sub.add_parser('score', help='score a pose against a gesture')
    p.add_argument('--gesture', required=True, help='gesture name, e.g. wai')
    p.add_argument('--keyframe', type=int, default=0, help='keyframe index (default 0)')
    p.add_argument('--right', nargs='+', required=True, metavar='DEG',
                   help="right-arm angles in degrees, the arm's joints in order")
    p.add_argument('--left', nargs='+', metavar='DEG',
                   help="left-arm angles in degrees (default: the gesture's)")
    p.add_argument('--json', action='store_true', help='print one JSON document')
    p.set_defaults(func=cmd_score)

    add_solve_parser(sub)
    from . import bench, beyond, demo, export, node_bench, node_commands, player_commands
    from . import notice_bench
    bench_sub = bench.register(sub)
    beyond.register(bench_sub)
    notice_bench.register(bench_sub)          # bench notice
    node_commands.register(sub, parser)      # fault, clear, reconfigure, library; --namespace
    demo.register(sub)                       # demo
    node_bench.register(bench_sub)           # bench latency, stream, product
    export.register(sub)                     # export --format play_motion2
    player_commands.register(sub, bench_sub)   # play, demo-play, bench detection
    from . import urdf as urdf_cli
    urdf_cli.register(sub)                   # urdf
    from . import precompute
    precompute.register(sub)                 # precompute (the contingency table)
    from . import settings_command
    settings_command.register(sub)           # settings (the files that list them)
    from . import profile_command
    profile_command.register(sub)            # profile (a template from a URDF)
    from . import retarget_command
    retarget_command.register(sub)           # retarget (a library for another robot)
    retarget_command.register_bench(bench_sub)   # bench robots, bench meshes
    profile_command.register_bench(bench_sub)    # bench fk
    return parser


def main(argv=None, out=None):
    """Entry point of ``namo-recovery``; returns the exit code."""
    out = out or sys.stdout
    try:
        args = build_parser().parse_args(argv)
        if args.robot_profile and args.command not in PROFILE_COMMANDS:
            raise UsageError(f'--robot-profile: namo-recovery {args.command} runs on a DH '
                             'robot file (--robot-file); the commands that take a profile: '
                             f'{", ".join(PROFILE_COMMANDS)} (and bench robots / bench meshes '
                             '--profile, retarget --to)')
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
