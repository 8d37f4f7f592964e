"""
Fault -> library latency of a running (or private) node (``namo-recovery bench latency``).

For each of ``--count`` single-joint faults (cycling over the joints): clear the faults,
publish the fault, time the arrival of the complete new library (as the client's
callback has it, and as its middleware received the last gesture:
``received_timestamp``, before the client's own executor took it), then time a
reconfigure_gestures round trip. Prints p50/p95/max, and splits the latency into the
engine's wall time (from ``/diagnostics``; none for a contingency-table hit) and what
the node and DDS add, with the node's own figures of each library: ``publish_path_sec``
(result in hand -> last gesture published), ``fault_to_request_sec``, ``fault_sync_sec``
and ``fault_to_publish_sec`` (fault received -> last gesture published: the node's whole
share; the rest is DDS and the client), and the libraries' origins (``table`` for a
contingency-table hit). The first fault waits until the node's contingency table is
loaded (its ``contingency_table`` status on ``/diagnostics``), as on a robot in
service. ``--settle`` waits between a clear and the next fault.
``--joint-states-hz`` streams ``/joint_states`` (the node's own joints) from another
process meanwhile;
``--node-param`` sets a parameter of the private node (e.g. ``contingency_table:=false``
to time the engine path only).  ``--optima`` judges the libraries as served: each
gesture's score against the best-known of its fault's locks in a ``bench robots`` /
``bench product`` optima file (the quality target's 1 %, measured through the node
rather than in process).  The client scores the published trajectories itself, on the
robot and library the file was made for (its ``robot``, or the product's libraries),
and reports how far the node's own scores on ``/diagnostics`` differ; with a file whose
robot it does not know, it takes the node's scores. Everything goes through
:class:`~namo_fault_recovery.ros.client.RecoveryClient`; ROS is imported only when the
benchmark runs.
"""

from dataclasses import dataclass
import math
import time

import numpy as np
import yaml

from .common import BenchError
from .product import best_of, gap, LIBRARIES, load_models, published_scores, QUALITY_WITHIN
from .robots import ROBOTS, shipped_robot
from ..errors import EXIT_USAGE
from ..recovery.contingency import entry_key
from ..runtime import diagnostic_keys as keys
from ..runtime.private_node import NodeTarget
from ..runtime.realtime import set_fifo_priority


def percentiles(values):
    """Return n, p50, p95, max and mean of durations in seconds, in milliseconds."""
    arr = np.asarray(values, dtype=float) * 1000.0
    return {'n': int(arr.size), 'p50_ms': float(np.percentile(arr, 50)),
            'p95_ms': float(np.percentile(arr, 95)), 'max_ms': float(arr.max()),
            'mean_ms': float(arr.mean())}


class LatencySamples:
    """The measurements of one benchmark run."""

    def __init__(self, best=None, models=None):
        self.best = best                   # [{locks key: {gesture: best-known score}}]
        self.models = models or [None] * len(best or ())   # per library: (robot, lib)
        self.gaps = []                     # per judged library: its largest gesture gap
        self.unmatched = 0                 # described libraries without a best-known
        self.beyond = []                   # 'locks: gesture gap %' of each beyond 1 %
        self.rescored = 0                  # judged on the client's own scores
        self.node_diff = 0.0               # their largest difference to the node's
        self.latencies, self.round_trips, self.engine, self.overhead = [], [], [], []
        self.delivered = []           # fault published -> last gesture at the client's rmw
        self.figures = {key: [] for key, _ in NODE_FIGURES}
        self.failures = []
        self.origins = {}                  # library_origin -> count ('' if not described)
        self.table = None                  # the contingency table at the first fault

    @classmethod
    def from_optima(cls, path):
        """Return the samples of a run judged against an optima file (read once)."""
        libraries = _optima_libraries(path)
        return cls([best for best, _ in libraries],
                   [_library_models(name) for _, name in libraries])

    def add_library(self, client, library, t0, t0_ns=None):
        """Add the latency of a fault's ``library`` (published at ``t0``) and its split."""
        self.latencies.append(library.received - t0)
        if library.delivered_ns and t0_ns:
            self.delivered.append((library.delivered_ns - t0_ns) * 1e-9)
        origin = _node_figures(client, library, self)
        self.origins[origin] = self.origins.get(origin, 0) + 1
        if library.described:
            engine = 0.0 if origin in NO_ENGINE else library.result.wall_time
            self.engine.append(engine)
            self.overhead.append(self.latencies[-1] - engine)
            if self.best is not None:
                self.judge(library.result, library.joint_names)

    def judge(self, result, joint_names=None):
        """
        Add the largest gap of ``result``'s gestures to their best-known (``best``).

        Scored by the client from the published positions (columns ``joint_names``)
        where the library's models are known, else the node's own ``score_after``.
        """
        key, names = entry_key(result.locks), {g.name for g in result.gestures}
        found = next((i for i, sets in enumerate(self.best)
                      if result.locks and set(sets.get(key) or ()) == names), None)
        if found is None:
            self.unmatched += 1
            return
        best = self.best[found][key]
        scores = {g.name: g.score_after for g in result.gestures}
        client = self.client_scores(found, result, joint_names)
        if client is not None:
            self.rescored += 1
            self.node_diff = max([self.node_diff] + [
                abs(gap(scores[name], score)) if math.isfinite(scores[name]) else math.inf
                for name, score in client.items()])
            scores = client
        gaps = {name: gap(score, float(best[name])) for name, score in scores.items()}
        self.gaps.append(max((x if math.isfinite(x) else math.inf) for x in gaps.values()))
        if self.gaps[-1] > QUALITY_WITHIN:
            self.beyond.append(f'{key}: ' + ', '.join(
                f'{name} {100 * x:.2f} %' for name, x in gaps.items() if x > QUALITY_WITHIN))

    def client_scores(self, found, result, joint_names):
        """
        Return ``{gesture: score}`` of ``result`` as published, or None (the node's count).

        None without the library's models or columns, for a library that leans the
        torso or carries a tool (the published angles alone do not say the pose), or
        whose trajectories are not the models' (another robot's joints, another count
        of keyframes: the client cannot score them).
        """
        models = self.models[found]
        if models is None or not joint_names or result.tool_mm or any(
                g.shared for g in result.gestures):
            return None
        try:
            return published_scores(*models, joint_names, result.gestures)
        except (ValueError, IndexError):
            return None

    def report(self, count):
        """Return the report dict; raise BenchError when nothing was measured."""
        if not self.latencies:
            raise BenchError('no measurement succeeded: ' + '; '.join(self.failures[:3]))
        report = {'faults': count, 'fault_to_library': percentiles(self.latencies),
                  'reconfigure_service': percentiles(self.round_trips),
                  'origins': dict(self.origins), 'failures': self.failures}
        if self.table is not None:
            report['table_at_start'] = {'state': self.table[0], 'entries': self.table[1]}
        if self.best is not None:
            report['served_quality'] = {
                'judged': len(self.gaps), 'without_best_known': self.unmatched,
                'within_1pct': sum(g <= QUALITY_WITHIN for g in self.gaps),
                'max_gap_pct': 100 * max(self.gaps) if self.gaps else None,
                'beyond_1pct': list(self.beyond), 'rescored_by_client': self.rescored,
                'node_score_diff_pct': 100 * self.node_diff if self.rescored else None}
        if self.delivered:
            report['fault_to_delivery'] = percentiles(self.delivered)
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
                (keys.PUBLISH_PATH_SEC, '  node: result in hand -> published'),
                (keys.FAULT_TO_PUBLISH_SEC, '  node: fault received -> last published'))
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


def answered(client, answer, stamp, timeout, what):
    """Return the stamp of the version a Trigger answer names (else the next one)."""
    after = stamp if answer.library_stamp is None else answer.library_stamp - 1
    library = client.next_library(after, timeout, diagnostics_timeout=0.0)
    if library is None:
        raise BenchError(f'{what} did not arrive within {timeout:g} s')
    return library.stamp


def clear_faults(client, timeout, stamp=None):
    """Clear the faults; return the stamp of the library of the answer, once it arrived."""
    stamp = client.inbox.newest_stamp() if stamp is None else stamp
    answer = client.clear_faults(timeout)
    if not answer.success:
        raise BenchError(f'clear_faults failed: {answer.message}')
    return answered(client, answer, stamp, timeout, 'the reference library after a clear')


def fault_library(client, joints, angles, timeout, diagnostics_timeout=3.0):
    """
    Publish a fault; return (its first library or None, publication time, the same in ns).

    The publication time is ``time.monotonic()`` (the library's ``received``) and
    ``time.time_ns()`` (the middleware's reception time, ``delivered_ns``).

    Called after the library of a clear arrived: the next version is the fault's.  A
    version whose ``/diagnostics`` never came (superseded at once by a refined one) is
    accepted; a described one must lock the joints (a version already on its way when
    the fault went out is not the fault's).
    """
    stamp = client.inbox.newest_stamp()
    t0, t0_ns = time.monotonic(), time.time_ns()
    client.publish_fault(joints, angles, timeout)
    while True:
        library = client.next_library(stamp, max(t0 + timeout - time.monotonic(), 0.0),
                                      diagnostics_timeout=diagnostics_timeout)
        if library is None or not library.described or set(joints) <= set(
                library.result.locks):
            return library, t0, t0_ns
        stamp = library.stamp


def wait_table(client, timeout):
    """
    Return the node's contingency table status once it is not loading any more, or None.

    A fault while the node still loads its table (just after its start) is searched
    live: the first fault of a run would time the start-up, not what a robot in service
    does.  ``(state, entries)`` from /diagnostics; None when the node does not say
    (a node without that status) within ``timeout`` s.
    """
    def ready(diag):
        return diag.get(keys.CONTINGENCY_TABLE, keys.TABLE_STATE) not in (
            None, keys.TABLE_LOADING)
    found = client.latest_diagnostics(ready, timeout=timeout)
    if found is None:
        return None
    return (found.get(keys.CONTINGENCY_TABLE, keys.TABLE_STATE),
            int(found.get(keys.CONTINGENCY_TABLE, keys.TABLE_ENTRIES, 0)))


def _measure(client, samples, rounds, timeout, out, verbose=False):
    """Run the clear -> fault -> reconfigure ``rounds``; add them to ``samples``."""
    current = client.current_library(timeout, diagnostics_timeout=0.0)
    joints = _checked_joints(rounds.joints, current.joint_names)
    samples.table = wait_table(client, timeout)
    stamp = current.stamp
    for i in range(rounds.count):
        joint = joints[i % len(joints)]
        stamp = clear_faults(client, timeout, stamp)
        time.sleep(rounds.settle)   # the node at rest (its work after the clear done)
        library, t0, t0_ns = fault_library(client, [joint], None, timeout)
        if library is None:
            samples.failures.append(f'{joint}: no library within {timeout:g} s')
            continue
        stamp = library.stamp
        samples.add_library(client, library, t0, t0_ns)
        t1 = time.monotonic()
        answer = client.reconfigure(timeout)
        samples.round_trips.append(time.monotonic() - t1)
        if not answer.success:
            samples.failures.append(f'{joint}: {answer.message}')
        else:
            stamp = answered(client, answer, stamp, timeout,
                             'the library of /reconfigure_gestures')
        if verbose:
            out.write(f'{i + 1:3d} {joint:<18} fault->library '
                      f'{samples.latencies[-1] * 1000:8.1f} ms   service '
                      f'{samples.round_trips[-1] * 1000:8.1f} ms\n')
    client.clear_faults(timeout)


def _checked_joints(joints, known):
    if not joints:
        return list(known)
    unknown = [j for j in joints if j not in known]
    if unknown:
        raise BenchError(f'--joints: unknown joint {unknown[0]!r}', EXIT_USAGE)
    return list(joints)


def _start_stream(client, rate, timeout):
    """
    Start ``/joint_states`` at ``rate`` Hz: the node's own joints, at its first gesture's start.

    The joints come from the library the node publishes, so that a stream for any robot
    carries that robot's names, as its drivers would (the node parses and keeps them).
    Returns once the stream publishes to a matched subscriber (the node): its process
    start-up is over and its readings reach the node.
    """
    from ..ros.joint_state_stream import library_stream
    stream, started = library_stream(client, rate, timeout)
    if not started:
        stream.close()
        raise BenchError(f'--joint-states-hz: the stream did not start within {timeout:g} s')
    return stream


def served_optima(path):
    """
    Return ``[{locks key: {gesture: score}}]``: an optima file's libraries (BenchError if not).

    ``bench robots`` files hold one (``fault_sets``), ``bench product``'s one per library
    (``libraries.NAME.fault_sets.KEY.best``); a library is told by its gesture names.
    """
    return [best for best, _ in _optima_libraries(path)]


def served_models(path):
    """
    Return, per library of :func:`served_optima`, its ``(robot, library)``, or None.

    A ``bench robots`` file names its shipped robot (``robot``); the product file's
    libraries are the packaged robot's.  Another robot's file gives None: the client
    cannot score its trajectories, and takes the node's scores.
    """
    return [_library_models(name) for _, name in _optima_libraries(path)]


def _library_models(name):
    """Return ``(robot, library)`` of a shipped robot's or a packaged library's name, or None."""
    if not isinstance(name, str):
        return None
    if name in ROBOTS:
        return shipped_robot(name).models()
    return load_models(name) if name in LIBRARIES else None


def _optima_libraries(path):
    """Return ``[(best-known fault sets, robot or library name)]`` of an optima file."""
    try:
        with open(path, encoding='utf-8') as handle:
            doc = yaml.safe_load(handle)
        if 'libraries' in doc:
            found = [({key: best_of(doc, name, key) for key in lib['fault_sets']}, name)
                     for name, lib in doc['libraries'].items()]
        else:
            found = [(dict(doc['fault_sets']), doc.get('robot'))]
    except OSError as exc:
        raise BenchError(f'--optima {path}: cannot read it ({exc.strerror})',
                         EXIT_USAGE) from None
    except (yaml.YAMLError, KeyError, TypeError, AttributeError) as exc:
        why = ' '.join(f'{type(exc).__name__}: {exc}'.split())
        raise BenchError(f'--optima {path}: expected fault_sets (bench robots) or '
                         f'libraries.NAME.fault_sets (bench product); {why}'[:300],
                         EXIT_USAGE) from None
    return found


@dataclass(frozen=True)
class Rounds:
    """What ``bench latency`` measures: which faults, how paced, under which load."""

    count: int = 50                 # single-joint faults, cycling over ``joints``
    joints: tuple = ()              # () = every joint of the served library
    # s between the library of each clear and the next fault (0: at once, while the
    # node still draws the clear's markers and restarts its table builder)
    settle: float = 0.0
    joint_states_hz: float = 0.0    # /joint_states from another process meanwhile
    client_priority: int = 0        # > 0: the measuring client under SCHED_FIFO


def run_latency(out, rounds: Rounds = Rounds(), timeout=30.0, namespace='/',
                target=NodeTarget(), verbose=False, optima=None):
    """
    Measure fault-publish -> full-library-received latency against a node.

    ``target`` (:class:`~..runtime.private_node.NodeTarget`) is the node: with
    ``start_node`` a private one is started (its ``robot_file``, ``gesture_file`` and
    ``node_params``) in ``domain_id`` (default a private one).  ``rounds.client_priority``
    > 0 runs the client (not the node or the stream, started before it) under
    ``SCHED_FIFO`` at that priority (:func:`~..runtime.realtime.set_fifo_priority`;
    BenchError if refused).  ``optima`` (a file) judges the libraries as served.  Returns
    ``(report, failures)``: the report dict (raises BenchError when no measurement
    succeeded) and the list of failed rounds.
    """
    from ..ros.client import RecoveryClient
    stream = None
    samples = LatencySamples() if optima is None else LatencySamples.from_optima(optima)
    node, domain_id = target.start(namespace, out)
    try:
        # The client's middleware and executor threads inherit the policy.
        refused = set_fifo_priority(rounds.client_priority)
        if refused:
            raise BenchError(f'--client-priority: {refused}')
        with RecoveryClient(namespace, domain_id) as client:
            if rounds.joint_states_hz > 0:
                stream = _start_stream(client, rounds.joint_states_hz, timeout)
            _measure(client, samples, rounds, timeout, out, verbose)
    finally:
        if stream is not None:
            stream.close()
        if node is not None:
            node.stop()
    return samples.report(rounds.count), samples.failures


def write_latency(out, report, failures):
    """Print a latency report: p50 / p95 / max of every figure, then the failures."""
    for label, key in (('fault publish -> full library received', 'fault_to_library'),
                       ("  the last gesture at the client's rmw", 'fault_to_delivery'),
                       ('reconfigure_gestures round trip', 'reconfigure_service'),
                       ('  of which optimisation (engine wall time)', 'engine_wall_time'),
                       ('  of which node + DDS (latency - engine)', 'node_and_dds_overhead'),
                       *((label, key) for key, label in NODE_FIGURES)):
        if key in report:
            s = report[key]
            out.write(f"{label:<42} n={s['n']:<3} p50 {s['p50_ms']:7.1f} ms  "
                      f"p95 {s['p95_ms']:7.1f} ms  max {s['max_ms']:7.1f} ms\n")
    table = report.get('table_at_start')
    if table:
        out.write(f"contingency table at the first fault: {table['state']}, "
                  f"{table['entries']} entries\n")
    quality = report.get('served_quality')
    if quality:
        worst = quality['max_gap_pct']
        largest = '' if worst is None else f', largest gap {worst:.2f} %'
        scored, diff = "the node's scores", ''
        if quality.get('rescored_by_client'):
            scored = "the client's scores of the published trajectories" + (
                '' if quality['rescored_by_client'] == quality['judged'] else
                f" ({quality['rescored_by_client']} of them, the node's the others)")
            diff = f"; the node's own scores within {quality['node_score_diff_pct']:.2g} %"
        out.write(f'quality as served ({scored} against the best-known{diff}): '
                  f"{quality['within_1pct']} of {quality['judged']} libraries with every "
                  f'gesture within 1 %{largest}; {quality["without_best_known"]} without a '
                  'best-known for their locks\n')
        for line in quality.get('beyond_1pct', ()):
            out.write(f'  beyond 1 %: {line}\n')
    origins = report.get('origins') or {}
    if origins:
        out.write('libraries by origin: ' + ', '.join(
            f'{name or "not described"} {n}' for name, n in sorted(origins.items())) + '\n')
    for failure in failures:
        out.write(f'failure: {failure}\n')
