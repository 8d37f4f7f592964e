"""
``namo-recovery bench latency``: fault -> library latency of a running (or private) node.

For each of ``--count`` single-joint faults (cycling over the joints): clear the faults,
publish the fault, time the arrival of the complete new library, then time a
reconfigure_gestures round trip.  Prints p50/p95/max, and splits the latency into the
engine's wall time (from ``/diagnostics``; none for a contingency-table hit) and what the
node and DDS add, with the node's own figures of each library: ``publish_path_sec``
(result in hand -> last gesture published), ``fault_to_request_sec`` and
``fault_sync_sec``.  ``--joint-states-hz`` streams ``/joint_states`` from another process
meanwhile; ``--node-param`` sets a parameter of the private node (e.g.
``contingency_table:=false`` to time the engine path only).
"""

import json
import time

import numpy as np

from .private_node import private_domain, PrivateNode
from .ros_common import (add_connection_arguments, CommandError, domain_id, EXIT_FAILURE,
                         EXIT_USAGE, namespace, open_client, wrap)
from ..ros import diagnostic_keys as keys


def percentiles(values):
    """Return n, p50, p95, max and mean of durations in seconds, in milliseconds."""
    arr = np.asarray(values, dtype=float) * 1000.0
    return {'n': int(arr.size), 'p50_ms': float(np.percentile(arr, 50)),
            'p95_ms': float(np.percentile(arr, 95)), 'max_ms': float(arr.max()),
            'mean_ms': float(arr.mean())}


class _Samples:
    """The measurements of one benchmark run."""

    def __init__(self):
        self.latencies, self.round_trips, self.engine, self.overhead = [], [], [], []
        self.figures = {key: [] for key, _ in NODE_FIGURES}
        self.failures = []

    def report(self, count):
        if not self.latencies:
            raise CommandError('no measurement succeeded: ' + '; '.join(self.failures[:3]))
        report = {'faults': count, 'fault_to_library': percentiles(self.latencies),
                  'reconfigure_service': percentiles(self.round_trips),
                  'failures': self.failures}
        if self.engine:
            report['engine_wall_time'] = percentiles(self.engine)
            report['node_and_dds_overhead'] = percentiles(self.overhead)
        for key, values in self.figures.items():
            if values:
                report[key] = percentiles(values)
        return report


# The node's own figures of each library (from /diagnostics), as the report names them.
NODE_FIGURES = ((keys.FAULT_TO_REQUEST_SEC, '  node: fault received -> run requested'),
                (keys.FAULT_SYNC_SEC, '  node: fault set synced (overlaps engine)'),
                (keys.PUBLISH_PATH_SEC, '  node: result in hand -> published'))
NO_ENGINE = ('reference', 'table')       # origins published without an engine run


def _node_figures(client, library, samples, timeout=1.0):
    """Add the node's figures of ``library`` from the /diagnostics that describes it."""
    found = client.inbox.latest_diagnostics(lambda d: d.describes(library.stamp),
                                            timeout=timeout)
    values = found.values.get(keys.RECONFIGURATION, {}) if found is not None else {}
    for key in samples.figures:
        try:
            samples.figures[key].append(float(values[key]))
        except (KeyError, ValueError):
            pass
    return values.get(keys.LIBRARY_ORIGIN, '')


def _answered(client, answer, stamp, timeout, what):
    """Return the stamp of the version a Trigger answer names (else the next one)."""
    after = stamp if answer.library_stamp is None else answer.library_stamp - 1
    library = client.next_library(after, timeout, diagnostics_timeout=0.0)
    if library is None:
        raise CommandError(f'{what} did not arrive within {timeout:g} s')
    return library.stamp


def _faulted(client, joint, timeout):
    """Publish a fault of ``joint``; return (its library or None, publication time)."""
    stamp = client.inbox.newest_stamp()
    t0 = time.monotonic()
    client.publish_fault([joint], None, timeout)
    while True:
        library = client.next_library(stamp, max(t0 + timeout - time.monotonic(), 0.0))
        # A version already on its way when the fault went out is not the fault's.
        if library is None or not library.described or joint in library.result.locks:
            return library, t0
        stamp = library.stamp


def _measure(args, client, samples, out):
    current = client.current_library(args.timeout, diagnostics_timeout=0.0)
    joints = list(current.joint_names)
    if args.joints:
        unknown = [j for j in args.joints if j not in joints]
        if unknown:
            raise CommandError(f'--joints: unknown joint {unknown[0]!r}', EXIT_USAGE)
        joints = list(args.joints)
    stamp = current.stamp
    for i in range(args.count):
        joint = joints[i % len(joints)]
        answer = client.clear_faults(args.timeout)
        if not answer.success:
            raise CommandError(f'clear_faults failed: {answer.message}')
        stamp = _answered(client, answer, stamp, args.timeout,
                          'the reference library after a clear')
        library, t0 = _faulted(client, joint, args.timeout)
        if library is None:
            samples.failures.append(f'{joint}: no library within {args.timeout:g} s')
            continue
        stamp = library.stamp
        samples.latencies.append(library.received - t0)
        origin = _node_figures(client, library, samples)
        if library.described:
            engine = 0.0 if origin in NO_ENGINE else library.result.wall_time
            samples.engine.append(engine)
            samples.overhead.append(samples.latencies[-1] - engine)
        t1 = time.monotonic()
        answer = client.reconfigure(args.timeout)
        samples.round_trips.append(time.monotonic() - t1)
        if not answer.success:
            samples.failures.append(f'{joint}: {answer.message}')
        else:
            stamp = _answered(client, answer, stamp, args.timeout,
                              'the library of /reconfigure_gestures')
        if args.verbose:
            out.write(f'{i + 1:3d} {joint:<18} fault->library '
                      f'{samples.latencies[-1] * 1000:8.1f} ms   service '
                      f'{samples.round_trips[-1] * 1000:8.1f} ms\n')
    client.clear_faults(args.timeout)


def bench_latency(args, out):
    """Measure fault-publish -> full-library-received latency against a node."""
    domain = domain_id(args)
    node = None
    if args.start_node:
        domain = private_domain() if domain is None else domain
        node = PrivateNode(args, domain, namespace(args), out)
    samples = _Samples()
    stream = None
    try:
        if args.joint_states_hz > 0:
            from ..ros.stream_bench import StreamProcess
            stream = StreamProcess(args.joint_states_hz, domain)
        with open_client(args, domain) as client:
            _measure(args, client, samples, out)
    finally:
        if stream is not None:
            stream.close()
        if node is not None:
            node.stop()
    report = samples.report(args.count)
    code = 0 if not samples.failures else EXIT_FAILURE
    if args.json:
        out.write(json.dumps(report, indent=2) + '\n')
        return code
    for label, key in (('fault publish -> full library received', 'fault_to_library'),
                       ('reconfigure_gestures round trip', 'reconfigure_service'),
                       ('  of which optimisation (engine wall time)', 'engine_wall_time'),
                       ('  of which node + DDS (latency - engine)', 'node_and_dds_overhead'),
                       *((label, key) for key, label in NODE_FIGURES)):
        if key in report:
            s = report[key]
            out.write(f"{label:<42} n={s['n']:<3} p50 {s['p50_ms']:7.1f} ms  "
                      f"p95 {s['p95_ms']:7.1f} ms  max {s['max_ms']:7.1f} ms\n")
    for failure in samples.failures:
        out.write(f'failure: {failure}\n')
    return code


def add_latency_arguments(parser):
    """Add the options of ``bench latency`` to ``parser``."""
    parser.add_argument('-n', '--count', type=int, default=50, metavar='N',
                        help='number of single-joint faults (default 50)')
    parser.add_argument('--joints', nargs='+', metavar='JOINT',
                        help='joints to fault in turn (default: all 14)')
    parser.add_argument('--start-node', action='store_true',
                        help='start a private recovery_node for the benchmark')
    parser.add_argument('--joint-states-hz', type=float, default=0.0, metavar='HZ',
                        help='stream /joint_states at HZ from another process meanwhile')
    parser.add_argument('--node-param', dest='node_params', action='append', default=[],
                        metavar='NAME:=VALUE',
                        help='a parameter of the private node (--start-node; repeatable)')
    parser.add_argument('--json', action='store_true', help='print one JSON document')
    parser.add_argument('-v', '--verbose', action='store_true', help='print every sample')
    add_connection_arguments(parser, timeout=30.0)
    parser.set_defaults(func=wrap(bench_latency))


def register_bench(bench_subparsers):
    """Add ``latency`` to the subparsers of a ``bench`` command."""
    p = bench_subparsers.add_parser(
        'latency', help='fault -> library latency against a running recovery_node')
    add_latency_arguments(p)
    return p
