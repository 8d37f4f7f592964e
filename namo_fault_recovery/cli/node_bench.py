"""
``namo-recovery bench stream``: deadline and latency while ``/joint_states`` streams.

A thin wrapper: the arguments here, the measurement in
:mod:`namo_fault_recovery.ros.stream_bench` (imported only when the command runs, so
the rest of the command line works without ROS).
"""

import argparse
import sys

EXIT_FAILURE = 1
EXIT_USAGE = 2


def _rates(text):
    try:
        rates = [float(x) for x in text.split(',') if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected comma-separated rates in Hz, got {text!r}')
    if not rates or any(r < 0 for r in rates):
        raise argparse.ArgumentTypeError(f'expected one or more rates >= 0 Hz, got {text!r}')
    return rates


def cmd_stream(args, out):
    """Run the stream benchmark; exit 1 when a run was not answered or missed the deadline."""
    from namo_fault_recovery.ros.stream_bench import BenchError, run_stream_bench
    try:
        report = run_stream_bench(
            out, rates=args.rates, burner=args.burner, faults=args.faults, reps=args.reps,
            start_node=args.start_node, gesture_file=args.gesture_file,
            robot_file=args.robot_file, domain_id=args.domain_id, out_dir=args.out,
            node_params=args.node_params,
            timeout=args.timeout, verbose=args.verbose)
    except BenchError as exc:
        sys.stderr.write(f'namo-recovery: error: {exc}\n')
        return EXIT_FAILURE
    except KeyboardInterrupt:
        sys.stderr.write('namo-recovery: interrupted\n')
        return 130
    missed = sum(c['summary']['runs'] - c['summary']['deadline_met']
                 for c in report['conditions'].values())
    return EXIT_FAILURE if missed else 0


def register(bench_subparsers):
    """Add ``stream`` to the subparsers of the ``bench`` command."""
    p = bench_subparsers.add_parser(
        'stream', help='deadline and fault -> library latency of recovery_node while '
                       '/joint_states streams (idle, 100 Hz, 500 Hz, 500 Hz + CPU burner)')
    p.add_argument('--start-node', action='store_true',
                   help='start a private recovery_node (fresh state directory) for the run')
    p.add_argument('--gesture-file', metavar='F', default=None,
                   help='with --start-node: the gesture library the node loads '
                        '(default: the packaged one)')
    p.add_argument('--robot-file', metavar='F', default=None,
                   help='with --start-node: the robot model the node loads')
    p.add_argument('--node-param', dest='node_params', action='append', default=[],
                   metavar='NAME:=VALUE',
                   help='with --start-node: a parameter of the node (repeatable), e.g. '
                        'contingency_table:=false so that every run is a live search')
    p.add_argument('--rates', type=_rates, default=[0.0, 100.0, 500.0], metavar='HZ,...',
                   help='/joint_states rates, 0 = idle (default 0,100,500)')
    p.add_argument('--burner', action=argparse.BooleanOptionalAction, default=True,
                   help='add a condition at the fastest rate with a CPU burner pinned to '
                        'another core (default on)')
    p.add_argument('--faults', nargs='+', metavar='JOINT',
                   default=[f'right_arm_joint{i}' for i in range(1, 8)],
                   help='joints faulted in turn, faults cleared between '
                        '(default right_arm_joint1..7)')
    p.add_argument('--reps', type=int, default=1, metavar='N',
                   help='passes over the fault joints per condition (default 1)')
    p.add_argument('--out', metavar='DIR', default=None,
                   help='write stream_bench.json there')
    p.add_argument('--timeout', type=float, default=60.0, metavar='SEC',
                   help='how long to wait for the node per step (default 60 s)')
    p.add_argument('--domain-id', type=int, default=None, metavar='N',
                   help='ROS domain id (default: $ROS_DOMAIN_ID; a private one with '
                        '--start-node)')
    p.add_argument('-v', '--verbose', action='store_true', help='print every run')
    p.set_defaults(func=cmd_stream)
    return p
