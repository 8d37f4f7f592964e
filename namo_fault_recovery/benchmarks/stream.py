"""
Deadline and latency of a running ``recovery_node`` while ``/joint_states`` streams.

The paper's 1 s deadline must hold on the robot, where the drivers stream joint states
at hundreds of Hz and other processes compete for the CPU.  For each condition (idle,
``/joint_states`` at each rate, the fastest rate plus a CPU burner on another core) and
each fault joint in turn (faults cleared between), the benchmark publishes the fault,
times the arrival of the new library on ``/gesture_library`` (client-observed latency),
calls ``/reconfigure_gestures`` and records the node's own figures for the library that
answer names (``wall_time_sec``, ``deadline_met``, ``success``, the summed
``<gesture>.score_after``) from ``/diagnostics``.

Everything goes over DDS to a real node process, through
:class:`~namo_fault_recovery.ros.client.RecoveryClient`: the stream comes from a
separate publisher process (:class:`~namo_fault_recovery.ros.joint_state_stream.
StreamProcess`, as a robot's drivers would), so it never shares the measuring client's
interpreter.  ROS is imported only when the benchmark runs.
"""

import contextlib
import json
import math
from pathlib import Path
import time

from .common import BenchError, machine_info
from .deadline import CpuBurner
from ..runtime.private_node import NodeTarget

DEFAULT_RATES = (0, 100, 500)
DEFAULT_FAULTS = tuple(f'right_arm_joint{i}' for i in range(1, 8))
SLACK_SEC = 0.020     # "within the deadline" allows this much over it (timer granularity)


def _percentile(values, q):
    if not values:
        return math.nan
    ordered = sorted(values)
    rank = (len(ordered) - 1) * q / 100.0
    lo, hi = math.floor(rank), math.ceil(rank)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (rank - lo)


def _call(call, *args):
    """
    Return ``call(*args)`` of the client; None when the node gave no answer in time.

    A node that is not there at all (no service, no subscriber) ends the benchmark.
    """
    from ..ros.client import ClientError, NodeUnreachable
    try:
        return call(*args)
    except NodeUnreachable as exc:
        raise BenchError(str(exc)) from None
    except ClientError:
        return None


def _diagnostics_of(client, stamp, timeout):
    """Return the 'reconfiguration' values of the /diagnostics of library ``stamp``."""
    from ..runtime import diagnostic_keys as keys
    text = keys.format_stamp(stamp)
    found = client.latest_diagnostics(
        lambda d: d.get(keys.RECONFIGURATION, keys.LIBRARY_STAMP) == text, timeout=timeout)
    return None if found is None else found.values[keys.RECONFIGURATION]


def _clear(client, record, timeout, last):
    """Clear the faults; return the reference library that follows (None: error noted)."""
    cleared = _call(client.clear_faults, timeout)
    if cleared is None or not cleared.success:
        record['error'] = (f'/clear_faults: {cleared.message}' if cleared else
                           f'/clear_faults: no answer within {timeout:g} s')
        return None
    base = client.next_library(last, timeout, diagnostics_timeout=0.0)
    if base is None:
        record['error'] = f'no reference library within {timeout:g} s of /clear_faults'
    return base


def _one_run(client, joint, timeout, last):
    """
    Clear, publish one fault, call /reconfigure_gestures; return the run's record.

    ``last`` is the stamp of the newest library version seen before: the clear's
    reference library is the first complete version after it, and the fault's library
    the first after that (so a late part of an earlier version is never taken for it).
    The record's ``last_stamp`` is the newest stamp seen at the end of the run.
    """
    record = {'joint': joint, 'last_stamp': last, 'answered': False, 'success': False,
              'deadline_met': False}
    base = _clear(client, record, timeout, last)
    if base is None:
        return record
    record['last_stamp'] = base.stamp
    t0 = time.monotonic()
    _call(client.publish_fault, [joint], None, timeout)
    got = client.next_library(base.stamp, timeout, diagnostics_timeout=0.0)
    record['latency_sec'] = got.received - t0 if got else None
    if got:
        record['last_stamp'] = got.stamp
    t1 = time.monotonic()
    answer = _call(client.reconfigure, timeout)
    record['service_sec'] = time.monotonic() - t1
    if answer is None:
        record['error'] = f'/reconfigure_gestures: no answer within {timeout:g} s'
        return record
    record.update(answered=True, success=bool(answer.success), message=answer.message)
    if answer.library_stamp is None:
        record['deadline_met'] = False
        return record
    record['library_version'] = answer.library_version
    record['last_stamp'] = max(record['last_stamp'], answer.library_stamp)
    values = _diagnostics_of(client, answer.library_stamp, timeout)
    if values is None:
        record['deadline_met'] = 'deadline' in answer.message and 'met' in answer.message
        return record
    _node_figures(record, values)
    if got is not None:
        fault_values = _diagnostics_of(client, got.stamp, 0.0)
        if fault_values is not None:
            record['fault_run_wall_time_sec'] = float(fault_values['wall_time_sec'])
    return record


def _node_figures(record, values):
    """Add the node's own figures of the answered library to a run's record."""
    record['wall_time_sec'] = float(values['wall_time_sec'])
    if values.get('request_to_publish_sec'):
        # The span the deadline covers: from the request to the publication.
        record['request_to_publish_sec'] = float(values['request_to_publish_sec'])
    record['deadline_sec'] = float(values['deadline_sec'])
    record['deadline_met'] = values['deadline_met'] == 'true'
    record['node_success'] = values['success'] == 'true'
    afters = {k[:-len('.score_after')]: float(v) for k, v in values.items()
              if k.endswith('.score_after')}
    befores = {k[:-len('.score_before')]: float(v) for k, v in values.items()
               if k.endswith('.score_before')}
    record['scores_after'] = afters
    record['total_score'] = sum(afters.values())
    record['total_score_before'] = sum(befores.get(g, math.nan) for g in afters)


def summarise(runs, idle_score=None):
    """Return the figures of one condition's runs (see the module docstring)."""
    walls = [r['wall_time_sec'] for r in runs if 'wall_time_sec' in r]
    spans = [r['request_to_publish_sec'] for r in runs if 'request_to_publish_sec' in r]

    def span(r):
        return r.get('request_to_publish_sec', r['wall_time_sec'])

    within = sum(1 for r in runs if 'wall_time_sec' in r
                 and span(r) <= r['deadline_sec'] + SLACK_SEC)
    latencies = [r['latency_sec'] for r in runs if r.get('latency_sec') is not None]
    scores = [r['total_score'] for r in runs if 'total_score' in r]
    mean_score = sum(scores) / len(scores) if scores else math.nan
    return {
        'runs': len(runs),
        'answered': sum(1 for r in runs if r.get('answered')),
        'errors': sum(1 for r in runs if 'error' in r),
        'success': sum(1 for r in runs if r.get('success')),
        'deadline_met': sum(1 for r in runs if r.get('deadline_met') is True),
        'within_deadline_plus_20ms': within,
        'wall_worst_sec': max(walls) if walls else math.nan,
        'wall_p95_sec': _percentile(walls, 95),
        'span_worst_sec': max(spans) if spans else math.nan,
        'span_p95_sec': _percentile(spans, 95),
        'latency_p50_sec': _percentile(latencies, 50),
        'latency_p95_sec': _percentile(latencies, 95),
        'latency_lost': len(runs) - len(latencies),
        'mean_total_score': mean_score,
        'score_vs_idle_pct': (100.0 * (mean_score - idle_score) / idle_score
                              if idle_score else math.nan),
    }


def _conditions(rates, burner):
    conditions = [(('idle' if rate == 0 else f'{rate:g} Hz'), rate, False) for rate in rates]
    if burner:
        fastest = max(rates)
        conditions.append((f'{fastest:g} Hz + burner' if fastest else 'idle + burner',
                           fastest, True))
    return conditions


def _table(name, summary, deadline, out):
    out.write(f'\n== {name} ==\n')
    s = summary
    out.write(f"  runs within deadline + 20 ms : {s['within_deadline_plus_20ms']}/{s['runs']}"
              f"  (node's deadline_met {s['deadline_met']}/{s['runs']}, success "
              f"{s['success']}/{s['runs']}, answered {s['answered']}/{s['runs']}"
              + (f", {s['errors']} with a service or library missing" if s['errors'] else '')
              + ')\n')
    out.write(f"  engine wall time             : worst {s['wall_worst_sec'] * 1000:7.1f} ms"
              f"   p95 {s['wall_p95_sec'] * 1000:7.1f} ms   (deadline "
              f'{deadline * 1000:.0f} ms)\n')
    out.write(f"  request -> publish (node)    : worst {s['span_worst_sec'] * 1000:7.1f} ms"
              f"   p95 {s['span_p95_sec'] * 1000:7.1f} ms\n")
    out.write(f"  fault -> library latency     : p50 {s['latency_p50_sec'] * 1000:7.1f} ms"
              f"   p95 {s['latency_p95_sec'] * 1000:7.1f} ms"
              + (f"   ({s['latency_lost']} never arrived)" if s['latency_lost'] else '')
              + '\n')
    out.write(f"  mean total score (sum after) : {s['mean_total_score']:.3f}"
              + (f"   ({s['score_vs_idle_pct']:+.1f} % vs idle)"
                 if not math.isnan(s['score_vs_idle_pct']) else '') + '\n')


def _run_condition(client, condition, faults, reps, timeout, last, out, verbose=False):
    """Run every fault ``reps`` times under one condition; return (runs, CPU, stream, last)."""
    from ..ros.joint_state_stream import library_stream
    name, rate, burning = condition
    # The node's own joints (any robot), at its first gesture's start.
    stream = library_stream(client, rate, timeout)[0] if rate > 0 else None
    runs = []
    try:
        with (CpuBurner() if burning else contextlib.nullcontext()) as ctx:
            time.sleep(1.0 if stream else 0.0)   # let the stream get matched
            for _ in range(reps):
                for joint in faults:
                    record = _one_run(client, joint, timeout, last)
                    last = record.pop('last_stamp')
                    runs.append(record)
                    _print_run(out, name, joint, record, verbose)
            burner_cpu = ctx.cpu if burning else None
    finally:
        stream_report = stream.close() if stream else {}
    _call(client.clear_faults, timeout)
    cleared = client.next_library(last, timeout, diagnostics_timeout=0.0)
    last = cleared.stamp if cleared else client.inbox.newest_stamp()
    return runs, burner_cpu, stream_report, last


def _print_run(out, name, joint, record, verbose):
    if 'error' in record:
        out.write(f"  {name}: {joint}: {record['error']}\n")
    elif verbose:
        wall = record.get('wall_time_sec', math.nan)
        latency = record.get('latency_sec') or math.nan
        out.write(f'  {name:<18} {joint:<18} wall {wall:.3f} s  latency {latency:.3f} s  met '
                  f"{record.get('deadline_met')}\n")


def _measure(client, report, conditions, faults, reps, timeout, out, verbose):
    """Run every condition against the node behind ``client``; fill ``report``."""
    from ..ros.client import NodeUnreachable
    try:
        client.current_library(timeout, diagnostics_timeout=0.0)
    except NodeUnreachable:
        raise BenchError(f'no recovery_node found: nothing on /gesture_library within '
                         f'{timeout:g} s') from None
    last = client.inbox.newest_stamp()
    idle_score = None
    for condition in conditions:
        name, rate, burning = condition
        runs, burner_cpu, stream_report, last = _run_condition(
            client, condition, faults, reps, timeout, last, out, verbose)
        summary = summarise(runs, idle_score)
        if name == 'idle':
            idle_score = summary['mean_total_score']
        deadline = next((r['deadline_sec'] for r in runs if 'deadline_sec' in r), 1.0)
        report['conditions'][name] = {'rate_hz': rate, 'burner': burning,
                                      'burner_cpu': burner_cpu, 'stream': stream_report,
                                      'summary': summary, 'runs': runs}
        _table(name + (f" (stream sent {stream_report.get('sent', '?')} msgs, "
                       f"{stream_report.get('rate_hz', '?')} Hz achieved)"
                       if rate > 0 else ''), summary, deadline, out)


def run_stream_bench(out, rates=DEFAULT_RATES, burner=True, faults=DEFAULT_FAULTS, reps=1,
                     target=NodeTarget(), out_dir=None, timeout=60.0, verbose=False):
    """
    Run every condition against the node; print one table each; return the report dict.

    ``target`` (:class:`~..runtime.private_node.NodeTarget`) is the node: with
    ``start_node`` a private one (fresh state directory, ``gesture_file``) is started for
    the run and stopped at the end; otherwise the node already running in ``domain_id``
    (default ``$ROS_DOMAIN_ID``) is measured.  ``out_dir`` receives ``stream_bench.json``.
    """
    from ..ros.client import RecoveryClient
    rates = [float(r) for r in rates]
    if any(r < 0 for r in rates) or not rates:
        raise BenchError('--rates: expected one or more rates >= 0 (Hz)')
    node, domain_id = target.start(out=out)
    report = {'machine': machine_info(),
              'gesture_file': target.gesture_file or '(node default)',
              'faults': list(faults), 'reps': reps, 'slack_sec': SLACK_SEC,
              'conditions': {}}
    info = report['machine']
    out.write(f"machine: {info['cpus']} CPUs, load average {info['loadavg']}; gesture file "
              f"{report['gesture_file']}; faults {', '.join(faults)} x {reps}\n")
    try:
        with RecoveryClient('/', domain_id) as client:
            _measure(client, report, _conditions(rates, burner), faults, reps, timeout, out,
                     verbose)
    finally:
        if node is not None:
            report['node_exit_code'] = node.stop()
        if out_dir:   # also what was measured before an error
            _write_report(out, out_dir, report)
    return report


def _write_report(out, out_dir, report):
    path = Path(out_dir)
    path.mkdir(parents=True, exist_ok=True)
    target = path / 'stream_bench.json'
    target.write_text(json.dumps(report, indent=2, default=str))
    out.write(f'\nwrote {target}\n')


def missed_runs(report):
    """Return how many runs of a report were not answered or missed the deadline."""
    return sum(c['summary']['runs'] - c['summary']['deadline_met']
               for c in report['conditions'].values())
