"""
The ``retarget`` command of ``namo-recovery``: a gesture library for another robot.

``namo-recovery retarget --from LIBRARY --to PROFILE [--out FILE] [--seed N]`` loads
LIBRARY on Namo (the DH robot file, ``--robot-file``), retargets every gesture to the
robot of PROFILE (:mod:`..recovery.retarget`: the landmarks in each arm's shoulder
frame, scaled by arm length, matched with the engine's objective), writes the library
(or prints it), and prints each gesture's score against the scaled reference and
whether a capsule pair still penetrates.  The written library loads on that robot
(``load_library`` checks it, as the node does).
"""

import argparse
import math
from pathlib import Path

import numpy as np
import yaml

from .common import UsageError, writing_out


def _degrees(robot, side, q):
    """Return angles (rad) in degrees to 4 decimals, rounded inside the joints' limits."""
    arm = robot.arms[side]
    lo = [math.ceil(math.degrees(v) * 1e4) / 1e4 for v in arm.lower]
    hi = [math.floor(math.degrees(v) * 1e4) / 1e4 for v in arm.upper]
    return [min(max(round(math.degrees(v), 4), a), b) for v, a, b in zip(q, lo, hi)]


PACE_MARGIN = 1.01      # keyframes paced a little slower than the player's bound needs


def paced_times(robot, times, positions) -> list:
    """
    Return keyframe times (s) that the player plays on ``robot`` without stretching.

    A retargeted motion keeps the source's timing, but the target's joints may travel
    further, or be slower: the player (:func:`~..playback.timing.plan_motion`, from rest)
    would then slow its segments down.  Those segments are slowed down here instead, as
    the player would (and by :data:`PACE_MARGIN` more), so the library is played as
    timed.  The first keyframe keeps its time (the approach is the player's rule).
    """
    from ..playback.timing import plan_motion
    times = [float(t) for t in times]
    limits = np.asarray(robot.joint_velocity_limits, dtype=float)
    names = robot.joint_names
    plan = plan_motion(names, np.zeros(len(names)), times, positions, limits)
    later = plan.waypoint_times[1:]
    if plan.stretch <= 1.0 or len(later) != len(times):
        return times
    return [times[0] + float(t - later[0]) * PACE_MARGIN for t in later]


def library_text(result, library, profile_path, source_path, robot):
    """Return the YAML text of a retargeted library (angles in degrees)."""
    gestures = []
    for gesture, done in zip(library, result):
        times = paced_times(robot, [kf.time_from_start for kf in gesture.keyframes],
                            np.concatenate([done.right, done.left], axis=1))
        frames = [{'time_from_start': round(times[k], 4),
                   'right': _degrees(robot, 'right', done.right[k]),
                   'left': _degrees(robot, 'left', done.left[k])}
                  for k, kf in enumerate(gesture.keyframes)]
        entry = {'name': gesture.name}
        if gesture.description:
            entry['description'] = gesture.description
        entry.update({'arms': list(gesture.arms), 'two_handed': bool(gesture.two_handed),
                      'keyframes': frames})
        gestures.append(entry)
    head = (f'# Gesture library retargeted by `namo-recovery retarget` from {source_path}\n'
            f'# to the robot of {profile_path}; per gesture, the score against the '
            'scaled reference\n'
            + ''.join(f'#   {g.name}: {np.mean(g.scores):.2f} (keyframes '
                      f'{", ".join(f"{s:.2f}" for s in g.scores)})'
                      f'{"; a capsule pair still penetrates" if g.collides.any() else ""}\n'
                      for g in result))
    body = yaml.safe_dump({'robot': robot.name, 'units': 'deg', 'gestures': gestures},
                          sort_keys=False, default_flow_style=None, width=95)
    return head + body


def cmd_retarget(args, out):
    """Retarget ``--from`` to ``--to``; write ``--out`` or print; return 0."""
    from ..model.gestures import load_library
    from ..model.profile_robot import robot_from_profile
    from ..model.robot import load_robot
    from ..recovery.retarget import rest_palms, retarget_gesture
    source = load_robot(args.robot_file)
    library = load_library(source, args.source)
    target = robot_from_profile(args.to)
    rng = np.random.default_rng(args.seed)
    rest = rest_palms(source, target, rng)
    result = [retarget_gesture(source, target, g, rng, rest) for g in library]
    text = library_text(result, library, args.to, args.source, target)
    for g in result:
        out.write(f'{g.name}: score {np.mean(g.scores):.2f} against the scaled reference'
                  f'{" (a capsule pair still penetrates)" if g.collides.any() else ""}\n')
    if args.out is None:
        out.write(text)
        return 0
    _write_checked(text, args.out, target, out)
    out.write(f'wrote {args.out}; it loads on {target.name}\n')
    return 0


def _write_checked(text, path, robot, out):
    """
    Write the library ``text`` to ``path`` only if it loads on ``robot`` (as the node checks).

    It is checked in a file beside ``path`` first: a library the node would refuse is
    not left where the node would be pointed at it.  The refusal says which profile
    keys to look at when a capsule pair is too deep (the capsules may be fatter than
    the robot's body).
    """
    from ..errors import ConfigError
    from ..model.gestures import load_library
    path = Path(path)
    trial = path.with_name(f'.{path.name}.checking')
    with writing_out(path):
        trial.write_text(text, encoding='utf-8')
    try:
        load_library(robot, trial, on_warning=lambda line: out.write(line + '\n'))
    except ConfigError as exc:
        hint = ''
        if 'interpenetrate' in str(exc):
            hint = ('; if the body is slimmer than its capsules, set smaller radii in the '
                    "profile's capsules key (upper_arm, forearm, hand, torso_radius; mm) and "
                    'retarget again (bench meshes compares them with the URDF meshes)')
        where = f"key '{exc.key}': " if exc.key else ''
        raise UsageError(f'{path} not written: the retargeted library does not load on '
                         f'{robot.name}: {where}{exc.problem}{hint}') from None
    else:
        with writing_out(path):
            trial.replace(path)
    finally:
        trial.unlink(missing_ok=True)          # refused, or anything else went wrong


def register(sub):
    """Add the ``retarget`` subcommand to the main parser's subcommands."""
    p = sub.add_parser('retarget', help="retarget a gesture library to another robot's profile")
    p.add_argument('--from', dest='source', required=True, metavar='LIBRARY',
                   help="a gesture library of Namo's (the DH robot file)")
    p.add_argument('--to', required=True, metavar='PROFILE', help="the robot's recovery profile")
    p.add_argument('--out', default=None, metavar='FILE',
                   help='write the library to FILE (default: print it)')
    # SUPPRESS: given after the command it wins; absent, the global option stands.
    p.add_argument('--robot-file', default=argparse.SUPPRESS, metavar='FILE',
                   help="the source robot file (default: the global --robot-file, Namo's)")
    p.add_argument('--seed', type=int, default=0, help='seed of the random starts (0)')
    p.set_defaults(func=cmd_retarget)
    return p


def cmd_bench_robots(args, out):
    """Run ``bench robots`` (optima with ``--update-optima``, then quality); return 0."""
    import yaml
    from ..benchmarks import robots
    if args.seeds < 1 or args.optima_seeds < 1:
        raise UsageError(f'--seeds/--optima-seeds: expected integers >= 1, got '
                         f'{args.seeds}/{args.optima_seeds}')
    bench = _bench_robot(args)
    joints = args.joints.split(',') if args.joints else None
    if args.update_optima:
        doc = robots.generate_optima(out, bench, seeds=args.optima_seeds, joints=joints)
        try:
            doc = robots.keep_lower(doc, robots.load_optima(bench))
        except FileNotFoundError:
            pass
        bench.optima.write_text(yaml.safe_dump(doc, sort_keys=False), encoding='utf-8')
        out.write(f'wrote {bench.optima} ({doc.get("kept", 0)} lower values kept from '
                  'the earlier file)\n')
    if not args.skip_quality:
        try:
            best = robots.load_optima(bench)
        except FileNotFoundError as exc:
            raise UsageError(f'no best-known optima for {bench.name} ({exc}); run with '
                             '--update-optima first') from None
        robots.run_quality(out, bench, best, seeds=args.seeds, joints=joints,
                           deadline=args.deadline, expand_shared=args.expand_shared)
    return 0


def _bench_robot(args):
    """Return the BenchRobot of ``--robot``, or of ``--profile`` and ``--gesture-file``."""
    from ..benchmarks import robots
    if (args.robot is None) == (args.profile is None):
        raise UsageError('expected --robot NAME or --profile FILE (with '
                         f'--gesture-file), got {"both" if args.robot else "neither"}')
    if args.robot is not None:
        if args.gesture_file is not None:
            raise UsageError(f'--gesture-file: {args.gesture_file} is given with --robot '
                             f'{args.robot}, which has its own; expected it with --profile')
        return robots.shipped_robot(args.robot, args.optima)
    if args.gesture_file is None:
        raise UsageError(f'--profile {args.profile}: expected --gesture-file FILE too (the '
                         "robot's library, e.g. from namo-recovery retarget)")
    return robots.profile_robot(args.profile, args.gesture_file, args.optima)


def cmd_bench_meshes(args, out):
    """Run ``bench meshes``: the capsules' verdicts against the URDF meshes; return 0."""
    from ..benchmarks import meshes
    if args.seeds < 1:
        raise UsageError(f'--seeds: expected an integer >= 1, got {args.seeds}')
    joints = args.joints.split(',') if args.joints else None
    meshes.run_meshes(out, _bench_robot(args), seeds=args.seeds, joints=joints)
    return 0


def _robot_arguments(p):
    """Add the robot's arguments of ``bench robots`` and ``bench meshes``."""
    p.add_argument('--robot', default=None, choices=['talos', 'tiago_dual'],
                   help='a shipped robot (config/robots/<robot>.yaml and its library)')
    p.add_argument('--profile', default=None, metavar='FILE',
                   help='any robot: its recovery profile (with --gesture-file)')
    p.add_argument('--gesture-file', default=None, metavar='FILE',
                   help="the --profile robot's gesture library")
    p.add_argument('--joints', default=None, help='comma-separated joints to fail (all)')


def register_bench(bench_sub):
    """Add ``bench robots`` and ``bench meshes`` to the ``bench`` command's subcommands."""
    m = bench_sub.add_parser('meshes', help='what the capsules pass as clear, measured on '
                                            'the URDF collision meshes of a profile robot '
                                            '(every single fault at the deadline)')
    _robot_arguments(m)
    m.add_argument('--seeds', type=int, default=1, help='seeds per fault (default 1)')
    m.set_defaults(func=cmd_bench_meshes, optima=None)
    p = bench_sub.add_parser('robots', help='every single fault x the gestures of a robot '
                                            'from its profile (Talos, TIAGo++ or yours) at '
                                            'the deadline')
    _robot_arguments(p)
    p.add_argument('--seeds', type=int, default=10, help='seeds per fault (default 10)')
    p.add_argument('--update-optima', action='store_true',
                   help='recompute the best-known optima first (no deadline); a value '
                        'the file already holds lower for the same model is kept')
    p.add_argument('--optima-seeds', type=int, default=16,
                   help='seeds per fault of the optima (default 16)')
    p.add_argument('--skip-quality', action='store_true', help='only the optima')
    p.add_argument('--optima', default=None, metavar='FILE',
                   help='the best-known file (default <profile>_best_known.yaml beside '
                        'the profile: config/robots/<robot>_best_known.yaml)')
    p.add_argument('--deadline', type=float, default=None,
                   help="seconds (default: the node's 1 s)")
    p.add_argument('--expand-shared', action='store_true',
                   help='the setting expand_shared on: the torso leans for gestures the '
                        'arms alone cannot reach')
    p.set_defaults(func=cmd_bench_robots)
    return p
