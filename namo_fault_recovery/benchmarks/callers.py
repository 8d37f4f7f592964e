"""
Crowds of service callers against a running (or private) node (``bench callers``).

Every client keeps rclpy's default service QoS (depth 10, as ``ros2 service call``).
With rmw_fastrtps each of them receives every response of the service, so a crowd
answered at once may lose answers; the node paces them
(:mod:`namo_fault_recovery.runtime.answer_pacer`).  With one fault published, so that
each call is a run that the waiting callers join:

- ``rounds`` times: ``clients`` clients call ``/reconfigure_gestures`` once each, all at
  once; then one client, answered once before, sends ``outstanding`` calls without
  waiting for any; then a brand-new client does the same.  A brand-new client's calls
  wait in its request writer (depth 10) until the node has matched it, and only the
  last 10 are then delivered: those lost calls never reach the node (counted apart,
  ``unanswered_fresh``);
- ``single`` calls in a row from one client: the round trip of a lone caller, which the
  pacing must not delay.

Prints the calls answered within ``timeout`` and the time until the last answer.
Everything goes through :class:`~namo_fault_recovery.ros.client.RecoveryClient`.
"""

import time

from .latency import percentiles
from ..runtime.private_node import NodeTarget

FAULT = ('right_arm_joint2', 0.3)


def _crowd(client, clients, calls, timeout, answered_once=False):
    """Return the figures of one crowd: answered, calls, seconds to the last answer."""
    times = client.crowd_call(clients, calls, timeout, answered_once=answered_once)
    done = [t for t in times if t is not None]
    return {'answered': len(done), 'calls': len(times),
            'last_answer_sec': max(done) if len(done) == len(times) else None,
            'median_answer_sec': sorted(done)[len(done) // 2] if done else None}


def _measure(client, clients, outstanding, rounds, single, timeout):
    """Return the report of the crowds and the single caller."""
    client.current_library(timeout, diagnostics_timeout=0.0)
    client.publish_fault([FAULT[0]], [FAULT[1]], timeout)
    client.reconfigure(timeout)          # ordered after the fault: the fault is in
    report = {'fault': f'{FAULT[0]} at {FAULT[1]} rad', 'crowds': [], 'outstanding': [],
              'outstanding_fresh': []}
    for _ in range(rounds):
        report['crowds'].append(_crowd(client, clients, 1, timeout))
        report['outstanding'].append(_crowd(client, 1, outstanding, timeout, True))
        report['outstanding_fresh'].append(_crowd(client, 1, outstanding, timeout))
    trips = []
    for _ in range(single):
        start = time.monotonic()
        client.reconfigure(timeout)
        trips.append(time.monotonic() - start)
    if trips:
        report['single_caller'] = percentiles(trips)
    client.clear_faults(timeout)
    return report


def run_callers(out, clients=50, outstanding=20, rounds=3, single=20, timeout=30.0,
                namespace='/', target=NodeTarget()):
    """
    Measure crowds of default-QoS callers against a node; print and return the report.

    ``target`` is the node (:class:`~..runtime.private_node.NodeTarget`; with
    ``start_node`` a private one).  The report's ``unanswered`` counts every call of
    every crowd left without an answer within ``timeout`` s.
    """
    from ..ros.client import RecoveryClient
    node, domain_id = target.start(namespace, out)
    try:
        with RecoveryClient(namespace, domain_id) as client:
            report = _measure(client, clients, outstanding, rounds, single, timeout)
    finally:
        if node is not None:
            node.stop()
    report['unanswered'] = sum(c['calls'] - c['answered']
                               for c in report['crowds'] + report['outstanding'])
    report['unanswered_fresh'] = sum(c['calls'] - c['answered']
                                     for c in report['outstanding_fresh'])
    write_callers(out, report, timeout)
    return report


def _line(out, label, crowd, timeout):
    """Print one crowd: its answered calls, and when the last one was answered."""
    last = crowd['last_answer_sec']
    when = (f"all answered, last after {last:.3f} s (median {crowd['median_answer_sec']:.3f} s)"
            if last is not None else f'the rest unanswered after {timeout:g} s')
    out.write(f"{label:<34} {crowd['answered']:3d}/{crowd['calls']:<3d} {when}\n")


def write_callers(out, report, timeout):
    """Print a callers report: each crowd's answered calls and last answer, the lone caller."""
    out.write(f"default-QoS callers (depth 10), fault {report['fault']}\n")
    for i, crowd in enumerate(report['crowds']):
        _line(out, f"round {i + 1}: {crowd['calls']} clients, 1 call each", crowd, timeout)
        outstanding = report['outstanding'][i]
        _line(out, f"round {i + 1}: 1 client, {outstanding['calls']} calls", outstanding,
              timeout)
        fresh = report['outstanding_fresh'][i]
        _line(out, f'round {i + 1}: same, a brand-new client', fresh, timeout)
    single = report.get('single_caller')
    if single:
        out.write(f"lone caller, {single['n']} calls in a row: round trip p50 "
                  f"{single['p50_ms']:.1f} ms, p95 {single['p95_ms']:.1f} ms, max "
                  f"{single['max_ms']:.1f} ms\n")
