"""
``namo-recovery bench latency | stream | product | callers | idle``: the benchmarks of a node.

Each command parses its options and calls its benchmark
(:mod:`namo_fault_recovery.benchmarks.latency`, :mod:`~namo_fault_recovery.benchmarks.
stream`, :mod:`~namo_fault_recovery.benchmarks.product_node`,
:mod:`~namo_fault_recovery.benchmarks.callers`,
:mod:`~namo_fault_recovery.benchmarks.idle`), imported only when it runs, so the
rest of the command line works without ROS.
"""

import argparse
import json
import os
import sys

from .ros_common import (add_connection_arguments, CommandError, EXIT_FAILURE, EXIT_USAGE,
                         namespace, wrap)
from ..runtime.private_node import NodeTarget, private_domain
from ..runtime.realtime import MAX_PRIORITY


def _rates(text):
    try:
        rates = [float(x) for x in text.split(',') if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected comma-separated rates in Hz, got {text!r}')
    if not rates or any(r < 0 for r in rates):
        raise argparse.ArgumentTypeError(f'expected one or more rates >= 0 Hz, got {text!r}')
    return rates


def cmd_latency(args, out):
    """Measure fault-publish -> full-library-received latency against a node."""
    from ..benchmarks import latency
    if not args.settle >= 0:
        raise CommandError('--settle: expected a number of seconds >= 0', EXIT_USAGE)
    if not 0 <= args.client_priority <= MAX_PRIORITY:
        raise CommandError(f'--client-priority: expected 0 .. {MAX_PRIORITY}, got '
                           f'{args.client_priority}', EXIT_USAGE)
    rounds = latency.Rounds(args.count, tuple(args.joints or ()), args.settle,
                            args.joint_states_hz, args.client_priority)
    report, failures = latency.run_latency(out, rounds, args.timeout, namespace(args),
                                           NodeTarget.from_args(args), args.verbose,
                                           args.optima)
    if args.json:
        out.write(json.dumps(report, indent=2) + '\n')
    else:
        latency.write_latency(out, report, failures)
    return 0 if not failures else EXIT_FAILURE


def cmd_stream(args, out):
    """Run the stream benchmark; exit 1 when a run was not answered or missed the deadline."""
    from ..benchmarks import stream
    try:
        report = stream.run_stream_bench(
            out, rates=args.rates, burner=args.burner, faults=args.faults, reps=args.reps,
            target=NodeTarget.from_args(args), out_dir=args.out, timeout=args.timeout,
            verbose=args.verbose)
    except stream.BenchError as exc:
        sys.stderr.write(f'namo-recovery: error: {exc}\n')
        return EXIT_FAILURE
    except KeyboardInterrupt:
        sys.stderr.write('namo-recovery: interrupted\n')
        return 130
    return EXIT_FAILURE if stream.missed_runs(report) else 0


def cmd_product(args, out):
    """Run the served problem's benchmark (benchmarks.product_node)."""
    from ..benchmarks import product_node
    parts = [p.strip() for p in args.parts.split(',') if p.strip()]
    unknown = [p for p in parts if p not in product_node.PARTS]
    if unknown:
        raise CommandError(f'--parts: unknown part {unknown[0]!r}; expected some of '
                           f'{",".join(product_node.PARTS)}', EXIT_USAGE)
    for option in ('seeds', 'demo_seeds', 'jobs', 'optima_seeds', 'demo_optima_seeds',
                   'refine_reps'):
        if getattr(args, option) < 1:
            raise CommandError(f"--{option.replace('_', '-')}: expected an integer >= 1",
                               EXIT_USAGE)
    product_node.run_product(out, args, parts)
    return 0


def cmd_callers(args, out):
    """Run the callers benchmark; exit 1 when a call was left unanswered."""
    from ..benchmarks import callers
    for option in ('clients', 'outstanding', 'rounds'):
        if getattr(args, option) < 1:
            raise CommandError(f'--{option}: expected an integer >= 1', EXIT_USAGE)
    report = callers.run_callers(out, args.clients, args.outstanding, args.rounds,
                                 max(args.single, 0), args.timeout, namespace(args),
                                 NodeTarget.from_args(args))
    if args.json:
        out.write(json.dumps(report, indent=2) + '\n')
    return EXIT_FAILURE if report['unanswered'] else 0


def cmd_idle(args, out):
    """Measure a private node's idle CPU (and clean stops); exit 1 if a stop was not."""
    from ..benchmarks import idle
    for option in ('settle', 'window'):
        if not getattr(args, option) > 0:
            raise CommandError(f'--{option}: expected a number of seconds > 0', EXIT_USAGE)
    if args.stops < 0:
        raise CommandError('--stops: expected an integer >= 0', EXIT_USAGE)
    tables = {'off': (False,), 'on': (True,), 'both': (False, True), 'none': ()}[args.table]
    domain = args.domain_id
    if domain is None:
        domain = int(os.environ.get('ROS_DOMAIN_ID') or 0) or private_domain()
    report = idle.run_idle(out, domain, tables, args.settle, args.window, args.stops,
                           tuple(args.node_params))
    if args.json:
        out.write(json.dumps(report, indent=2) + '\n')
    return EXIT_FAILURE if any(s['clean'] < s['stops'] for s in report['stops']) else 0


def _add_idle(bench_subparsers):
    """Add ``idle``: a private node's idle CPU and clean stops (benchmarks.idle)."""
    p = bench_subparsers.add_parser(
        'idle', help="a private recovery_node's idle CPU (process tree, %% of one core), "
                     'contingency table off and on; --stops: SIGTERM exits')
    p.add_argument('--table', choices=('off', 'on', 'both', 'none'), default='both',
                   help='contingency_table of the measured nodes (default both; none: '
                        'only --stops)')
    p.add_argument('--settle', type=float, default=20.0, metavar='SEC',
                   help='wait this long after the node is ready (default 20)')
    p.add_argument('--window', type=float, default=60.0, metavar='SEC',
                   help='measure over this long (default 60)')
    p.add_argument('--stops', type=int, default=0, metavar='N',
                   help='then SIGTERM recovery_node and namo_sim N times each at a random '
                        'idle moment; count exits 0 within 5 s (default 0)')
    p.add_argument('--node-param', dest='node_params', action='append', default=[],
                   metavar='NAME:=VALUE', help='a parameter of the node (repeatable)')
    p.add_argument('--domain-id', type=int, default=None, metavar='N',
                   help='ROS domain id of the nodes (default: $ROS_DOMAIN_ID, else a '
                        'private one)')
    p.add_argument('--json', action='store_true', help='also print one JSON document')
    p.set_defaults(func=wrap(cmd_idle))
    return p


def add_private_node_arguments(parser):
    """Add ``--start-node`` and ``--node-param``: a private recovery_node and its parameters."""
    parser.add_argument('--start-node', action='store_true',
                        help='start a private recovery_node for the benchmark')
    parser.add_argument('--node-param', dest='node_params', action='append', default=[],
                        metavar='NAME:=VALUE',
                        help='a parameter of the private node (--start-node; repeatable)')


def _add_latency(bench_subparsers):
    """Add ``latency``: fault -> library latency (benchmarks.latency)."""
    p = bench_subparsers.add_parser(
        'latency', help='fault -> library latency against a running recovery_node')
    p.add_argument('-n', '--count', type=int, default=50, metavar='N',
                   help='number of single-joint faults (default 50)')
    p.add_argument('--joints', nargs='+', metavar='JOINT',
                   help='joints to fault in turn (default: all 14)')
    p.add_argument('--joint-states-hz', type=float, default=0.0, metavar='HZ',
                   help='stream /joint_states at HZ from another process meanwhile')
    p.add_argument('--settle', type=float, default=0.0, metavar='SEC',
                   help='wait this long after each clear before the next fault (default 0: '
                        'at once)')
    p.add_argument('--client-priority', type=int, default=0, metavar='N',
                   help='run the measuring client under SCHED_FIFO at priority N, as a '
                        "robot's real-time consumer of the library runs (default 0: the "
                        'normal scheduler); see the node parameter thread_priority')
    p.add_argument('--optima', metavar='FILE',
                   help="judge each fault's library as served: its trajectories, scored "
                        'by this client, against the best-known of an optima file '
                        '(config/robots/R_best_known.yaml, config/product_best_known.yaml); '
                        "the node's own scores where the file's robot is not a shipped one")
    add_private_node_arguments(p)
    p.add_argument('--json', action='store_true', help='print one JSON document')
    p.add_argument('-v', '--verbose', action='store_true', help='print every sample')
    add_connection_arguments(p, timeout=30.0)
    p.set_defaults(func=wrap(cmd_latency))
    return p


def _add_stream(bench_subparsers):
    """Add ``stream``: the deadline while /joint_states streams (benchmarks.stream)."""
    p = bench_subparsers.add_parser(
        'stream', help='deadline and fault -> library latency of recovery_node while '
                       '/joint_states streams (idle, 100 Hz, 500 Hz, 500 Hz + CPU burner)')
    p.add_argument('--start-node', action='store_true',
                   help='start a private recovery_node (fresh state directory) for the run')
    # SUPPRESS: given after the command it wins; absent, the global option stands.
    p.add_argument('--gesture-file', metavar='F', default=argparse.SUPPRESS,
                   help='with --start-node: the gesture library the node loads '
                        '(default: the global --gesture-file, else the packaged one)')
    p.add_argument('--robot-file', metavar='F', default=argparse.SUPPRESS,
                   help='with --start-node: the robot model the node loads (default: the '
                        'global --robot-file, else the packaged one)')
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
    p.add_argument('--domain-id', type=int, default=argparse.SUPPRESS, metavar='N',
                   help='ROS domain id (default: the global --domain-id, else '
                        '$ROS_DOMAIN_ID; a private one with --start-node)')
    p.add_argument('-v', '--verbose', action='store_true', help='print every run')
    p.set_defaults(func=cmd_stream)
    return p


def _add_product(bench_subparsers):
    """Add ``product``: the served problem, every part (benchmarks.product_node)."""
    from ..benchmarks.product import DEMO_OPTIMA_SEEDS, OPTIMA_SEEDS
    from ..benchmarks.product_node import PARTS
    p = bench_subparsers.add_parser(
        'product', help='the served problem: optima, deadline quality, table, node '
                        'latency, refinement, demo library')
    p.add_argument('--parts', default=','.join(PARTS), metavar='LIST',
                   help=f'comma-separated parts to run (default: {",".join(PARTS)})')
    p.add_argument('--seeds', type=int, default=10,
                   help='seeds per single fault for quality (default 10)')
    p.add_argument('--demo-seeds', type=int, default=3,
                   help='seeds per single fault for the demo library (default 3)')
    p.add_argument('--joints', nargs='+', default=None, metavar='JOINT',
                   help='single faults to run (default: all 14 joints)')
    p.add_argument('--jobs', type=int, default=2,
                   help='worker processes for the optima and the table (default 2)')
    p.add_argument('--no-burner', action='store_true', help='skip the CPU-burner passes')
    p.add_argument('--update-optima', action='store_true',
                   help='regenerate the best-known optima first (see --optima-file)')
    p.add_argument('--optima-seeds', type=int, default=OPTIMA_SEEDS,
                   help=f'seeds per fault set for --update-optima (default {OPTIMA_SEEDS})')
    p.add_argument('--demo-optima-seeds', type=int, default=DEMO_OPTIMA_SEEDS,
                   help=f'seeds per fault set of the demo library (default '
                        f'{DEMO_OPTIMA_SEEDS})')
    p.add_argument('--optima-libraries', default=None, metavar='LIST',
                   help='with --update-optima: regenerate only these libraries '
                        '(comma-separated: product, demo; the others are kept)')
    p.add_argument('--optima-file', default=None, metavar='FILE',
                   help='optima to read (and write) (default: the package config '
                        'product_best_known.yaml)')
    p.add_argument('--refine-window', type=float, default=12.0, metavar='SEC',
                   help='how long to collect refined versions after a fault (default 12)')
    p.add_argument('--refine-reps', type=int, default=3, metavar='N',
                   help='faults per refinement set (default 3)')
    p.add_argument('--table-timeout', type=float, default=600.0, metavar='SEC',
                   help="how long to wait for the node's table (default 600)")
    p.add_argument('--timeout', type=float, default=30.0, metavar='SEC',
                   help='how long to wait for the node per step (default 30)')
    p.add_argument('--out', default=None, metavar='DIR',
                   help='output directory (default: bench_out/product)')
    p.add_argument('--quiet', action='store_true', help='no progress lines on stderr')
    p.set_defaults(func=wrap(cmd_product))
    return p


def _add_callers(bench_subparsers):
    """Add ``callers``: crowds of default-QoS service callers (benchmarks.callers)."""
    p = bench_subparsers.add_parser(
        'callers', help='crowds of default-QoS /reconfigure_gestures callers: every call '
                        'answered?')
    p.add_argument('--clients', type=int, default=50, metavar='N',
                   help='clients calling once each, at once (default 50)')
    p.add_argument('--outstanding', type=int, default=20, metavar='N',
                   help='calls one client sends without waiting (default 20)')
    p.add_argument('--rounds', type=int, default=3, metavar='N',
                   help='rounds of both crowds (default 3)')
    p.add_argument('--single', type=int, default=20, metavar='N',
                   help="a lone caller's calls in a row, for its round trip (default 20)")
    add_private_node_arguments(p)
    p.add_argument('--json', action='store_true', help='also print one JSON document')
    add_connection_arguments(p, timeout=30.0)
    p.set_defaults(func=wrap(cmd_callers))
    return p


def register(bench_subparsers):
    """Add ``latency``, ``stream``, ``product``, ``callers`` and ``idle`` to ``bench``."""
    _add_latency(bench_subparsers)
    _add_stream(bench_subparsers)
    _add_product(bench_subparsers)
    _add_callers(bench_subparsers)
    _add_idle(bench_subparsers)
