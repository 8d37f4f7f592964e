"""
The ``bench`` and ``plot`` commands of ``namo-recovery``.

:func:`register` adds them to the main parser's subcommands.  The benchmarks print
their figures on stdout (progress goes to stderr) and write their files under
``bench_out/`` unless told otherwise.
"""

from dataclasses import replace
import math
from pathlib import Path
import sys

from .common import add_setting_options, engine_settings, gesture_and_keyframe
from .common import parse_faults, Parser, UsageError
from ..errors import EXIT_USAGE

# ``bench explore``'s runs (benchmarks.explore.RUNS, named here so that the parser does not
# import the simulator; a test checks that they agree).
EXPLORE_RUNS = ('sa', 'ours', 'every', 'ik_true')
# Its motions (benchmarks.explore.MOTIONS, likewise).
EXPLORE_MOTIONS = ('circle', 'bye', 'paper_circle')
# Where the SA starts at each typical point (explore.annealing.START_POSES, likewise).
EXPLORE_SA_STARTS = ('design', 'previous', 'kriging')


def _usage(message):
    return UsageError(message)


def _positive_int(option, value, minimum=1):
    if value is None or value < minimum:
        raise _usage(f'{option}: expected an integer >= {minimum}, got {value}')
    return value


def models_of(args):
    """Return (robot, library) of a command's ``--robot-file`` and ``--gesture-file``."""
    from ..benchmarks import common
    return common.models(getattr(args, 'robot_file', None), getattr(args, 'gesture_file', None))


def _cases_or_usage(robot, library, gestures, joints):
    from ..benchmarks import common
    try:
        return common.select_cases(robot, library, gestures, joints)
    except (KeyError, ValueError) as exc:
        raise _usage(exc.args[0]) from None


def _keys_or_usage(keys, option='--algorithms'):
    from ..benchmarks import common
    try:
        return [common.lookup_spec(k).key for k in keys]
    except ValueError as exc:
        raise _usage(f'{option}: {exc}') from None


def out_dir_of(args, name):
    """Return a command's ``--out`` directory (default ``bench_out/<name>``)."""
    from ..benchmarks import common
    return Path(args.out) if args.out else Path(common.DEFAULT_OUT_ROOT) / name


def cmd_bench_paper(args, out):
    """Reproduce the paper's Tables 3-6 (resumable; see benchmarks.paper)."""
    from ..benchmarks import common, paper
    reps = args.reps if args.reps is not None else (paper.QUICK_REPS if args.quick else 100)
    _positive_int('--reps', reps)
    _positive_int('--jobs', args.jobs)
    joints = args.joints or (list(paper.QUICK_JOINTS) if args.quick else None)
    robot, library = models_of(args)
    _cases_or_usage(robot, library, args.gestures, joints)
    keys = _keys_or_usage(args.algorithms)
    if args.deadline is not None and not (math.isfinite(args.deadline) and args.deadline > 0):
        raise _usage(f'--deadline: expected a number of seconds > 0, got {args.deadline}')
    out_dir = out_dir_of(args, 'paper-quick' if args.quick else 'paper')
    run = paper.PaperRun(reps=reps, jobs=args.jobs, keys=keys, gestures=args.gestures,
                         joints=joints, seed_base=args.seed_base, deadline=args.deadline)
    paper.run_paper(out, out_dir, run, common.ModelFiles.from_args(args),
                    plots=not args.no_plots, progress=not args.quiet)
    return 0


def cmd_bench_optimum(args, out):
    """Find (or load) the best-known optimum of every case and print the gaps to it."""
    from ..benchmarks import common, optimum
    _positive_int('--starts', args.starts, 0)
    _positive_int('--seeds', args.seeds, 0)
    _positive_int('--maxiter', args.maxiter)
    robot, library = models_of(args)
    cases = _cases_or_usage(robot, library, args.gestures, args.joints)
    keys = _keys_or_usage(args.algorithms)
    write = None
    if args.write_to:
        write = Path(args.write_to)
    elif args.write:
        write = optimum.best_known_path()
    if write is not None and args.stored:
        raise _usage('--write/--write-to: nothing to write with --stored')
    try:
        search = optimum.Multistart(starts=args.starts, seed=args.seed, maxiter=args.maxiter)
        doc = optimum.run_optimum(robot, library, out, cases, search, write=write, keys=keys,
                                  seeds=args.seeds, use_stored=args.stored,
                                  progress=not args.quiet)
    except FileNotFoundError as exc:
        raise _usage(f'--stored: {exc}') from None
    out_dir = out_dir_of(args, 'optimum')
    common.write_json(out_dir / 'summary.json', doc)
    out.write(f'written: {out_dir / "summary.json"}\n')
    return 0


def cmd_bench_speed(args, out):
    """Time the whole library: our default against the paper ABC, with quality."""
    from ..benchmarks import common, speed
    _positive_int('--reps', args.reps)
    _positive_int('--sequential-reps', args.sequential_reps, 0)
    robot, library = models_of(args)
    _cases_or_usage(robot, library, None, args.joints)
    if args.deadline is not None and not (math.isfinite(args.deadline) and args.deadline > 0):
        raise _usage(f'--deadline: expected a number of seconds > 0, got {args.deadline}')
    speed.run_speed(out, out_dir_of(args, 'speed'), reps=args.reps, joints=args.joints,
                    seed_base=args.seed_base, deadline=args.deadline,
                    files=common.ModelFiles.from_args(args), progress=not args.quiet,
                    sequential_reps=args.sequential_reps)
    return 0


def cmd_bench_deadline(args, out):
    """Measure the worst deadline overrun, idle and with a CPU burner."""
    from ..benchmarks import deadline
    _positive_int('--reps', args.reps)
    for d in args.deadlines:
        if not (math.isfinite(d) and d > 0):
            raise _usage(f'--deadlines: expected seconds > 0, got {d}')
    unknown = [k for k in args.algorithms if k not in deadline.UNBOUNDED]
    if unknown:
        raise _usage(f'--algorithms: unknown key {unknown[0]!r}; expected some of '
                     f'{", ".join(deadline.UNBOUNDED)}')
    deadline.run_deadline(out, out_dir_of(args, 'deadline'), deadlines=tuple(args.deadlines),
                          reps=args.reps, keys=tuple(args.algorithms), burner=not args.no_burner,
                          robot_file=args.robot_file, gesture_file=args.gesture_file,
                          progress=not args.quiet)
    return 0


def cmd_bench_playability(args, out):
    """Count the libraries the player would have to stretch (benchmarks.playability)."""
    from ..benchmarks import common, playability
    _positive_int('--seeds', args.seeds, 0)
    _positive_int('--deadline-seeds', args.deadline_seeds, 0)
    _positive_int('--jobs', args.jobs)
    _positive_int('--lock-angles', args.lock_angles, 0)
    try:
        robot = playability.playability_models(args.library, args.robot)[0]
    except ValueError as exc:
        raise _usage(str(exc)) from None
    unknown = [j for j in args.joints or () if j not in robot.joint_names]
    if unknown:
        raise _usage(f'--joints: unknown joint {unknown[0]!r}; expected names such as '
                     f'{robot.joint_names[0]}')
    summary = playability.run_playability(
        out, args.library, seeds=args.seeds, deadline_seeds=args.deadline_seeds,
        joints=args.joints, jobs=args.jobs, seed_base=args.seed_base,
        progress=not args.quiet, robot_name=args.robot, lock_angles=args.lock_angles)
    path = out_dir_of(args, 'playability') / 'summary.json'
    common.write_json(path, summary)
    out.write(f'written: {path}\n')
    return 0


def monitor_of(args):
    """Return the MonitorThresholds of a command's detector options (None: the defaults)."""
    from ..playback.monitor import MonitorThresholds
    values = {'fault_threshold': None if args.threshold_deg is None
              else math.radians(args.threshold_deg),
              'fault_hold': args.hold_sec, 'tracking_lag': args.lag_sec,
              'tracking_delay': args.delay_sec, 'tracking_time_constant': args.tau_sec}
    values = {k: v for k, v in values.items() if v is not None}
    try:
        return MonitorThresholds(**values)
    except ValueError as exc:
        raise _usage(str(exc)) from None


def cmd_bench_detection_suite(args, out):
    """Run the detector over both libraries, idle and busy; print the figures."""
    import json
    from ..benchmarks import common, detection_suite as suite
    from ..model.robot import load_robot
    _positive_int('--reps', args.reps, 0)
    _positive_int('--stuck-reps', args.stuck_reps, 0)
    if not (math.isfinite(args.noise_deg) and args.noise_deg >= 0):
        raise _usage(f'--noise-deg: expected a number >= 0, got {args.noise_deg}')
    if not (math.isfinite(args.lateness_sec) and args.lateness_sec >= 0):
        raise _usage(f'--lateness-sec: expected seconds >= 0, got {args.lateness_sec}')
    robot = load_robot(args.robot_file)
    libraries = suite.load_libraries(robot, args.library, args.gesture_file)
    options = suite.SuiteOptions(reps=args.reps, stuck_reps=args.stuck_reps,
                                 noise_deg=args.noise_deg,
                                 start_spread_deg=args.start_spread_deg, seed=args.seed,
                                 monitor=monitor_of(args))
    lateness = _lateness_of(args, suite)
    doc = suite.run_suite(robot, libraries, args.condition, options, lateness,
                          progress=None if args.quiet else (lambda s: sys.stderr.write(s + '\n')))
    out_dir = out_dir_of(args, 'detection_suite')
    common.write_json(out_dir / 'suite.json', doc)
    if args.json:
        out.write(json.dumps(common.plain(doc), indent=1) + '\n')
    else:
        suite.write_summary(out, doc)
    out.write(f'written: {out_dir / "suite.json"}\n')
    return 0


def _lateness_of(args, suite):
    """Return {condition: lateness}: measured now, or read from ``--lateness-from``."""
    import json
    if not args.lateness_from:
        return {c: suite.measure_lateness(c, args.lateness_sec, args.domain_id)
                if args.lateness_sec else [] for c in args.condition}
    try:
        doc = json.loads(Path(args.lateness_from).read_text())
        return {c: [float(v) for v in doc['conditions'][c]['lateness_s']]
                for c in args.condition}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise _usage(f'--lateness-from {args.lateness_from}: expected a suite.json of '
                     f'bench detection-suite with conditions {args.condition} '
                     f'({type(exc).__name__}: {exc})') from None


def add_detector_options(p):
    """Add the detector's threshold options (default: the player's defaults)."""
    p.add_argument('--threshold-deg', type=float, default=None,
                   help='fault threshold off the predicted angle (deg)')
    p.add_argument('--hold-sec', type=float, default=None, help='fault hold (s)')
    p.add_argument('--lag-sec', type=float, default=None,
                   help='band of the prediction a reading may lag behind (s)')
    p.add_argument('--delay-sec', type=float, default=None,
                   help="the tracking model's delay (s)")
    p.add_argument('--tau-sec', type=float, default=None,
                   help="the tracking model's first-order time constant (s)")


def cmd_plot(args, out):
    """
    Draw one gesture before and after adaptation (matplotlib optional).

    A single pose is drawn as arm skeletons; a motion (several keyframes) as fingertip
    paths: desired, unadapted and adapted, like the second source paper's Fig. 5-7.
    """
    from ..benchmarks import plotting
    from ..model.gestures import load_library
    robot = models_of(args)[0]
    library = load_library(robot, getattr(args, 'gesture_file', None))
    gesture = gesture_and_keyframe(library, args.gesture, args.keyframe)
    faults = parse_faults(robot, args.fault or [])
    settings = engine_settings(args)
    if not faults and not settings.tool_length_mm:
        raise _usage('nothing changed: give --fault JOINT[=DEG] and/or --tool-length-mm MM')
    try:
        plotting.figure((1, 1))
    except plotting.MatplotlibMissing as exc:
        sys.stderr.write(f'namo-recovery: error: {exc}\n')
        return EXIT_USAGE
    tool = settings.tool_length_mm
    tag = '_'.join([j.replace('_arm_joint', '') for j in faults]
                   + ([f'tool{tool:g}'] if tool else []))
    path = Path(args.out) if args.out else Path(f'{gesture.name}_{tag}.png')
    try:
        plotting.plot_gesture(out, robot, library, gesture.name, faults, settings, path,
                              seed=args.seed, deadline=settings.deadline_sec,
                              keyframe=args.keyframe)
    except ValueError as exc:
        raise _usage(str(exc)) from None
    return 0


def _add_common(p):
    p.add_argument('--out', default=None, metavar='DIR',
                   help='output directory (default: bench_out/<benchmark>)')
    p.add_argument('--quiet', action='store_true', help='no progress lines on stderr')


def _add_paper(bench_sub):
    """Add ``bench paper``: the paper's Tables 3-6."""
    from ..benchmarks.common import ALGORITHM_SPECS, PAPER_LINEUP
    keys = ', '.join(ALGORITHM_SPECS)
    p = bench_sub.add_parser('paper', help="reproduce the paper's Tables 3-6 (resumable)")
    p.add_argument('--reps', type=int, default=None,
                   help='repetitions per case (default 100; 5 with --quick)')
    p.add_argument('--quick', action='store_true',
                   help='a short version (5 reps, joint 2 only; under 2 minutes)')
    p.add_argument('--jobs', type=int, default=1, help='worker processes (default 1)')
    p.add_argument('--algorithms', nargs='+', default=list(PAPER_LINEUP), metavar='KEY',
                   help=f'algorithm keys (default: {" ".join(PAPER_LINEUP)}); from {keys}')
    p.add_argument('--gestures', nargs='+', default=None, metavar='G',
                   help='gestures (default: the whole library)')
    p.add_argument('--joints', nargs='+', default=None, metavar='J',
                   help='failed right-arm joints, names or numbers 1-7 (default: all)')
    p.add_argument('--seed-base', type=int, default=0, help='seed of repetition 0')
    p.add_argument('--deadline', type=float, default=None,
                   help='deadline per gesture in s (default: none, as in the paper)')
    p.add_argument('--no-plots', action='store_true', help='skip the box plots')
    _add_common(p)
    p.set_defaults(func=cmd_bench_paper)


def _add_optimum(bench_sub):
    """Add ``bench optimum``: the best-known optima and the gaps."""
    from ..benchmarks.common import ALGORITHM_SPECS, PAPER_LINEUP
    keys = ', '.join(ALGORITHM_SPECS)
    p = bench_sub.add_parser('optimum', help='best-known optimum of every case, and the gaps')
    p.add_argument('--starts', type=int, default=1000,
                   help='random starts per case besides the reference start (default 1000)')
    p.add_argument('--seed', type=int, default=0, help='seed of the random starts')
    p.add_argument('--maxiter', type=int, default=300, help='polish iterations per start')
    p.add_argument('--write', action='store_true',
                   help='store the optima in the package config (best_known_optima.yaml)')
    p.add_argument('--write-to', default=None, metavar='FILE',
                   help='store the optima in FILE instead')
    p.add_argument('--stored', action='store_true',
                   help='use the stored optima instead of searching (prints the gaps only)')
    p.add_argument('--seeds', type=int, default=3,
                   help='seeds per algorithm and case for the gaps (default 3; 0: none)')
    p.add_argument('--algorithms', nargs='+', default=list(PAPER_LINEUP), metavar='KEY',
                   help=f'algorithms whose gap is printed; from {keys}')
    p.add_argument('--gestures', nargs='+', default=None, metavar='G', help='gestures')
    p.add_argument('--joints', nargs='+', default=None, metavar='J',
                   help='failed right-arm joints, names or numbers 1-7')
    _add_common(p)
    p.set_defaults(func=cmd_bench_optimum)


def _add_speed(bench_sub):
    """Add ``bench speed``: whole-library time and quality."""
    p = bench_sub.add_parser('speed', help='whole-library time and quality: ours vs paper ABC')
    p.add_argument('--reps', type=int, default=100, help='seeds per failed joint (default 100)')
    p.add_argument('--joints', nargs='+', default=None, metavar='J',
                   help='failed right-arm joints, names or numbers 1-7 (default: all)')
    p.add_argument('--seed-base', type=int, default=0, help='seed of repetition 0')
    p.add_argument('--deadline', type=float, default=1.0,
                   help="our default's library deadline in s (default 1.0)")
    p.add_argument('--sequential-reps', type=int, default=10,
                   help='seeds per joint on which the paper ABC is also timed one gesture '
                        'at a time, as the paper ran it (default 10; 0: skip)')
    _add_common(p)
    p.set_defaults(func=cmd_bench_speed)


def _add_deadline(bench_sub):
    """Add ``bench deadline``: the worst deadline overrun."""
    from ..benchmarks.deadline import DEADLINES, DEFAULT_KEYS
    p = bench_sub.add_parser('deadline', help='worst deadline overrun, idle and with a burner')
    p.add_argument('--deadlines', nargs='+', type=float, default=list(DEADLINES),
                   metavar='S', help='deadlines in s (default 0.05 0.1 0.25 1)')
    p.add_argument('--reps', type=int, default=10,
                   help='runs per deadline and algorithm (default 10)')
    p.add_argument('--algorithms', nargs='+', default=list(DEFAULT_KEYS), metavar='KEY',
                   help=f'algorithms (default: {" ".join(DEFAULT_KEYS)})')
    p.add_argument('--no-burner', action='store_true', help='skip the CPU-burner pass')
    _add_common(p)
    p.set_defaults(func=cmd_bench_deadline)


def _add_playability(bench_sub):
    """Add ``bench playability``: libraries the player would stretch."""
    p = bench_sub.add_parser('playability',
                             help='published libraries the player would have to stretch '
                                  '(joint velocity limits), every single fault')
    p.add_argument('--library', default='product', choices=['product', 'demo'],
                   help='the packaged library or the demo one (default product)')
    p.add_argument('--robot', default='namo', choices=['namo', 'talos', 'tiago_dual'],
                   help='Namo, or a shipped profile robot with its retargeted library '
                        '(example-robot-data; default namo)')
    p.add_argument('--seeds', type=int, default=2000,
                   help='seeds per single fault at the fixed small budget (default 2000; '
                        '0: skip)')
    p.add_argument('--deadline-seeds', type=int, default=0,
                   help="seeds per single fault at the node's 1 s deadline (default 0: "
                        'skip; run alone on the machine)')
    p.add_argument('--joints', nargs='+', default=None, metavar='JOINT',
                   help='single faults to run (default: all 14 joints)')
    p.add_argument('--jobs', type=int, default=2,
                   help='worker processes of the fixed-budget part (default 2)')
    p.add_argument('--seed-base', type=int, default=0, help='seed of repetition 0')
    p.add_argument('--lock-angles', type=int, default=0, metavar='N',
                   help='lock each joint at N angles across the range the library moves it '
                        'through (a joint stuck mid-gesture), each seed at each, instead of '
                        "the lock strategy's (default 0: the strategy's)")
    _add_common(p)
    p.set_defaults(func=cmd_bench_playability)


def cmd_bench_explore(args, out):
    """Adapt to unknown structure changes by trials on the (simulated) robot."""
    from ..benchmarks import explore
    _positive_int('--seeds', args.seeds)
    _positive_int('--every-seeds', args.every_seeds, 0)
    sigmas = tuple(args.sigma)
    if any(not (math.isfinite(s) and s > 0) for s in sigmas):
        raise _usage(f'--sigma: expected noise levels (mm) > 0, got {list(sigmas)}')
    labels = None
    if args.cases:
        known = [c[0] for c in explore.CASES]
        labels = [c for c in known if any(k in c for k in args.cases)]
        if not labels:
            raise _usage(f'--cases {args.cases}: matches none of {"; ".join(known)}')
    if args.merge:
        explore.merge(out, out_dir_of(args, 'explore'), args.merge)
        return 0
    if args.tune_sa:
        explore.tune_sa(out, out_dir_of(args, 'explore'), seeds=args.seeds,
                        progress=not args.quiet)
        return 0
    schedule = explore.TUNED_SA
    if args.sa_start:
        schedule = replace(schedule, start=args.sa_start)
    run = explore.ExploreRun(seeds=args.seeds, every_seeds=args.every_seeds, sigmas=sigmas,
                             motions=tuple(args.motions), labels=labels,
                             robot_kind=args.robot, sa_robot=args.sa_robot,
                             schedule=schedule, runs=tuple(args.runs))
    explore.bench_explore(out, out_dir_of(args, 'explore'), run, progress=not args.quiet)
    return 0


def _add_explore(bench_sub):
    """Add ``bench explore``: exploration on the robot after an unknown change."""
    p = bench_sub.add_parser('explore', help='adapt to a change the model does not know: '
                                             "the paper's SA, ours, every point, the IK floor")
    p.add_argument('--seeds', type=int, default=10, help='noise seeds (default 10)')
    p.add_argument('--every-seeds', type=int, default=10,
                   help='seeds of the explore-every-point upper bound (default 10)')
    p.add_argument('--sigma', type=float, nargs='+', default=[1.0, 4.0], metavar='MM',
                   help='tracker noise: the first for every run, further ones (a head '
                        'camera) for ours only (default 1 4)')
    p.add_argument('--motions', nargs='+', default=list(EXPLORE_MOTIONS),
                   choices=EXPLORE_MOTIONS,
                   help='motions (default all: circle bye paper_circle; paper_circle, the '
                        "circle placed for the paper's elbow lock, runs its two elbow cases)")
    p.add_argument('--cases', nargs='+', default=None, metavar='TEXT',
                   help='only the cases whose name contains one of these (default all)')
    p.add_argument('--runs', nargs='+', default=list(EXPLORE_RUNS), choices=EXPLORE_RUNS,
                   help='which runs (default all: sa ours every ik_true)')
    p.add_argument('--robot', default='physics', choices=['physics', 'kinematic'],
                   help='trial robot of ours / every point (default physics: the simulator)')
    p.add_argument('--sa-robot', default='kinematic', choices=['physics', 'kinematic'],
                   help="trial robot of the paper's SA (default kinematic: its thousands of "
                        'trials would take minutes of physics per run)')
    p.add_argument('--sa-start', default=None, choices=EXPLORE_SA_STARTS,
                   help="where the SA starts at each typical point: 'design' (the paper's "
                        "reading), or carried on in the motion's order from the previous "
                        "point's correction ('previous') or the Kriging of those explored "
                        "('kriging'); default: the tuned schedule's (previous)")
    p.add_argument('--merge', nargs='+', default=None, metavar='JSON',
                   help='report the rows of several explore.json files (partial runs) as one')
    p.add_argument('--tune-sa', action='store_true',
                   help='try the SA schedule grid and print the pick (uses --seeds)')
    _add_common(p)
    p.set_defaults(func=cmd_bench_explore)


def _add_detection_suite(bench_sub):
    """Add ``bench detection-suite``: the detector over both libraries, idle and busy."""
    from ..benchmarks.detection_suite import LIBRARIES
    p = bench_sub.add_parser('detection-suite', help='stuck-joint detection: latency, false '
                             'alarms, score gap and playability over both libraries, idle '
                             'and busy (MuJoCo in lock-step, lateness measured over DDS)')
    p.add_argument('--library', nargs='+', default=list(LIBRARIES), choices=list(LIBRARIES),
                   help='libraries (default: both)')
    p.add_argument('--condition', nargs='+', default=['idle', 'busy'],
                   choices=['idle', 'busy'], help='conditions (default: both)')
    p.add_argument('--reps', type=int, default=100,
                   help='normal plays per gesture (default 100)')
    p.add_argument('--stuck-reps', type=int, default=1,
                   help='plays per stuck joint and gesture (default 1)')
    p.add_argument('--noise-deg', type=float, default=0.1,
                   help='reading noise, standard deviation in deg (default 0.1)')
    p.add_argument('--start-spread-deg', type=float, default=1.0,
                   help='uniform spread of the start pose around rest (deg, default 1)')
    p.add_argument('--lateness-sec', type=float, default=20.0,
                   help='seconds of reading lateness measured over DDS per condition '
                        '(default 20; 0: every reading on time)')
    p.add_argument('--lateness-from', default=None, metavar='SUITE_JSON',
                   help="replay the lateness measured by an earlier run's suite.json "
                        '(e.g. one with --reps 0 --stuck-reps 0 run under a lock) '
                        'instead of measuring it')
    p.add_argument('--domain-id', type=int, default=None,
                   help='ROS domain id of the lateness probe (default $ROS_DOMAIN_ID)')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--json', action='store_true', help='print the whole JSON document')
    add_detector_options(p)
    _add_common(p)
    p.set_defaults(func=cmd_bench_detection_suite)


def _add_plot(subparsers):
    """Add ``plot``: one gesture before and after adaptation."""
    p = subparsers.add_parser('plot', help='draw a gesture before and after adaptation (PNG)')
    p.add_argument('--gesture', required=True,
                   help='gesture name, e.g. wai, or circle with --gesture-file '
                        'config/demo_motions.yaml (the demo library)')
    p.add_argument('--fault', action='append', metavar='JOINT[=DEG]',
                   help='failed joint, optionally with its lock angle in degrees '
                        '(default: the library average); repeatable')
    p.add_argument('--out', default=None, metavar='FILE',
                   help='PNG file (default: <gesture>_<faults>.png)')
    p.add_argument('--seed', type=int, default=0, help='seed (default 0)')
    add_setting_options(p, deadline=True)
    p.add_argument('--keyframe', type=int, default=0, help='keyframe index (default 0)')
    p.set_defaults(func=cmd_plot)


def register(subparsers):
    """
    Add the ``bench`` and ``plot`` commands to the main parser's subparsers.

    Returns the ``bench`` command's own subparsers, so that more benchmarks can be
    added to it (``add_parser(...)`` with ``set_defaults(func=...)``).
    """
    bench = subparsers.add_parser('bench', help='benchmarks that print figures')
    bench_sub = bench.add_subparsers(dest='bench_command', metavar='BENCHMARK',
                                     parser_class=Parser)
    bench_sub.required = True
    for add in (_add_paper, _add_optimum, _add_speed, _add_deadline, _add_playability,
                _add_explore, _add_detection_suite):
        add(bench_sub)
    _add_plot(subparsers)
    return bench_sub
