"""
``namo-recovery bench product``: one benchmark of the served problem, all its parts.

The packaged library under the node's settings.  Parts (``--parts``, default all):

- ``quality``: every single fault x ``--seeds`` through the engine's entry point at the
  1 s deadline, idle and with a CPU burner on the other core: each gesture's gap to the
  best-known optimum; target every gesture within 1% in >= 99% of the runs;
- ``table``: the contingency table as the node builds it; target every gesture of
  every entry within 0.5%;
- ``latency``: a real ``recovery_node`` (private domain, temporary ``state_dir``) over
  DDS, fault -> full library received: table hits once the table holds the entries
  timed (the single faults of ``--joints``; all 14, and the build's CPU, without it)
  (p95 <= 15 ms, idle and with the burner), and misses with
  ``contingency_table:=false`` (p95 <= 200 ms);
- ``refine``: double faults and a measured lock on the node without a table: the gap of
  each library version it publishes (scored from its positions) against time, over
  ``--refine-reps`` faults per set; target within 0.5% by 10 s;
- ``demo``: ``quality`` on the demo library (``config/demo_motions.yaml``, the circle).

The best-known optima come from ``config/product_best_known.yaml``;
``--update-optima`` regenerates them first (many seeds without a deadline).  Figures
on stdout, progress on stderr, ``summary.json`` in ``--out`` (default
``bench_out/product``).
"""

import contextlib
import json
import math
from pathlib import Path
import re
import time

import numpy as np

from . import common, product
from .common import BenchError
from .deadline import CpuBurner
from .latency import clear_faults, fault_library
from ..errors import EXIT_USAGE
from ..recovery.contingency import entry_key, fault_sets, table_locks
from ..runtime.private_node import NodeTarget

PARTS = ('quality', 'table', 'latency', 'refine', 'demo')
HIT_P95_MS = 15.0
MISS_P95_MS = 200.0
REFINE_WITHIN = 0.005
REFINE_BY_SEC = 10.0
OPTIMA_SEEDS = product.OPTIMA_SEEDS
DEMO_OPTIMA_SEEDS = product.DEMO_OPTIMA_SEEDS


def _pct(values):
    arr = np.asarray(values, dtype=float) * 1000.0
    if arr.size == 0:
        return {'n': 0, 'p50_ms': math.nan, 'p95_ms': math.nan, 'max_ms': math.nan}
    return {'n': int(arr.size), 'p50_ms': float(np.percentile(arr, 50)),
            'p95_ms': float(np.percentile(arr, 95)), 'max_ms': float(arr.max())}


def _origin(client, stamp, timeout=1.0):
    from ..runtime import diagnostic_keys as keys
    diag = client.latest_diagnostics(lambda d: d.describes(stamp), timeout=timeout)
    return None if diag is None else diag.get(keys.RECONFIGURATION, keys.LIBRARY_ORIGIN)


def _start(out, extra=()):
    return NodeTarget(start_node=True).start('/', out, extra)


def _table_keys(joints):
    """
    Return the table keys of the single faults of ``joints``: the entries a hit times.

    Computed as the node's keeper computes them (the node's default settings, no fault
    active), so that the bench waits for exactly the entries it will look up.
    """
    robot, lib = product.load_models()
    settings = product.node_settings()
    return [entry_key(table_locks(robot, lib, faults, settings))
            for faults in fault_sets(robot, lib, settings, joints=joints)]


def _wait_table(node, keys, timeout, out, t0, client=None):
    """
    Wait until the node's table file holds the entries ``keys``; return (seconds, RTTs).

    With ``client``, ``/reconfigure_gestures`` is called back to back meanwhile (no
    fault: the reference is republished at once), so the round trips say whether the
    background build slows the node's services.
    """
    path = Path(node.workdir) / 'contingency_table.json'
    wanted = set(keys)
    rtts = []
    while time.monotonic() - t0 < timeout:
        try:
            present = {e['key'] for e in json.loads(path.read_text())['entries']}
        except (OSError, ValueError, KeyError, TypeError):
            present = set()
        if wanted <= present:
            out.write(f'node table: holds the entries timed ({len(wanted)}; {len(present)} '
                      f'built) {time.monotonic() - t0:.1f} s after the node was started\n')
            return time.monotonic() - t0, rtts
        if node.proc.poll() is not None:
            raise BenchError('the node ended before its table was built')
        if client is None:
            time.sleep(0.25)
            continue
        began = time.monotonic()
        client.reconfigure(timeout=10.0)
        rtts.append(time.monotonic() - began)
        time.sleep(0.02)
    raise BenchError(f'the node table did not get the {len(wanted)} entries to time in '
                     f'{timeout:g} s')


def _build_cpu(node, timeout=10.0):
    """Return the table builder process's CPU seconds from the node's log (None if not)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            text = Path(node.workdir, 'node.log').read_text(errors='replace')
        except OSError:
            text = ''
        found = re.findall(r'entries built in [0-9.]+ s \(([0-9.]+) s of CPU', text)
        if found:
            return float(found[0])
        time.sleep(0.1)
    return None


def _latency_rounds(client, joints, timeout, burner):
    """Fault each joint in turn (clearing between); return the samples."""
    samples = []
    with (CpuBurner() if burner else contextlib.nullcontext()):
        for joint in joints:
            clear_faults(client, timeout)
            time.sleep(0.2)
            library, t0, _ = fault_library(client, [joint], None, timeout, 1.0)
            if library is None:
                samples.append({'joint': joint, 'latency_s': None, 'origin': None})
                continue
            samples.append({'joint': joint, 'latency_s': library.received - t0,
                            'origin': _origin(client, library.stamp),
                            'engine_wall_s': library.result.wall_time})
    return samples


def _latency_conditions(client, joints, timeout, conditions, target_ms, expect):
    """Run the latency rounds idle (and with the burner); return {condition: summary}."""
    out = {}
    for burner in conditions:
        samples = _latency_rounds(client, joints, timeout, burner)
        out['cpu burner' if burner else 'idle'] = dict(
            _latency_summary(samples, target_ms, expect), samples=samples)
    return out


def _latency_summary(samples, target_ms, expect):
    ok = [s['latency_s'] for s in samples if s['latency_s'] is not None]
    stats = _pct(ok)
    stats.update(failures=len(samples) - len(ok), target_p95_ms=target_ms,
                 expected_origin=expect,
                 origins={o: sum(str(s['origin']) == o for s in samples)
                          for o in sorted({str(s['origin']) for s in samples})},
                 met=bool(ok) and len(ok) == len(samples) and stats['p95_ms'] <= target_ms)
    return stats


def _refine_case(client, name, best, timeout, window):
    """Fault one refinement set; return the versions the node published in ``window``."""
    robot, lib = product.load_models()
    faults = product.refine_faults(name)
    joints = list(faults)
    angles = None
    if any(a is not None for a in faults.values()):
        if not all(a is not None for a in faults.values()):
            raise BenchError(f'{name}: give every angle or none')
        angles = [faults[j] for j in joints]
    clear_faults(client, timeout)
    time.sleep(0.2)
    library, t0, _ = fault_library(client, joints, angles, timeout, 1.0)
    versions = []
    while library is not None and library.received - t0 <= window:
        # Scored from the published positions: every version counts, described or not.
        scores = product.published_scores(robot, lib, library.joint_names,
                                          library.result.gestures)
        versions.append({'t_s': library.received - t0,
                         'origin': _origin(client, library.stamp, 0.5),
                         'described': library.described, 'scores': scores,
                         'worst_gap': product.worst_gap(scores, best)})
        left = max(t0 + window - time.monotonic(), 0.0)
        library = client.next_library(library.stamp, left, diagnostics_timeout=0.5)
    within = [v['t_s'] for v in versions if v['worst_gap'] <= REFINE_WITHIN]
    first = min(within) if within else None
    return {'set': name, 'faults_deg': product.REFINE_SETS[name], 'versions': versions,
            'first_within_s': first,
            'met': first is not None and first <= REFINE_BY_SEC,
            'final_gap': versions[-1]['worst_gap'] if versions else None}


def _refine_sets(cases):
    """Return per fault set: runs, share met, median and worst time to within 0.5%."""
    sets = {}
    for c in cases:
        sets.setdefault(c['set'], []).append(c)
    out = {}
    for name, cs in sets.items():
        firsts = [c['first_within_s'] for c in cs]
        reached = [f for f in firsts if f is not None]
        out[name] = {'runs': len(cs), 'share_met': float(np.mean([c['met'] for c in cs])),
                     'median_first_within_s': (float(np.median(reached)) if reached
                                               else None),
                     'final_gaps': [c['final_gap'] for c in cs],
                     'met': all(c['met'] for c in cs)}
    return out


def _hit_latency(args, out, joints, conditions):
    """Time table hits on a node with its table, once the table is built."""
    from ..ros.client import RecoveryClient
    started = time.monotonic()
    node, domain = _start(out)
    try:
        with RecoveryClient('/', domain) as client:
            client.current_library(args.timeout, diagnostics_timeout=0.0)
            keys = _table_keys(joints)
            whole = len(keys) == len(product.load_models()[0].joint_names)
            waited, rtts = _wait_table(node, keys, args.table_timeout, out, started, client)
            # The builder logs its CPU once the whole table is built: only then is it read.
            build = {'entries_waited': len(keys), 'wall_s': waited,
                     'cpu_s': _build_cpu(node) if whole else None, 'rtt': _pct(rtts)}
            rtt = build['rtt']
            cpu = (f'{build["cpu_s"]} s of CPU' if whole else
                   f'CPU not measured (waited for {len(keys)} of the entries only)')
            out.write(f'table build: {cpu}; service round trip '
                      f'during the build over {rtt["n"]} calls: p50 '
                      f'{rtt["p50_ms"]:.1f} / p95 {rtt["p95_ms"]:.1f} ms (targets: '
                      f'<= 60 s of CPU, p95 <= 50 ms)\n')
            hit = _latency_conditions(client, joints, args.timeout, conditions,
                                      HIT_P95_MS, 'table')
            return {'table_wait_s': waited, 'table_entries_waited': len(keys),
                    'build': build, 'conditions': hit}
    finally:
        node.stop()


def _refine(args, client, best_doc):
    """Run every refinement set ``args.refine_reps`` times; return the part's results."""
    robot, lib = product.load_models()
    settings = product.node_settings()
    cases = []
    for name in product.REFINE_SETS:
        locks = table_locks(robot, lib, product.refine_faults(name), settings)
        best = product.best_of(best_doc, 'product', entry_key(locks))
        if best is None:
            raise BenchError(f'no best-known stored for {name}; run with --update-optima')
        for rep in range(args.refine_reps):
            case = _refine_case(client, name, best, args.timeout, args.refine_window)
            cases.append(dict(case, rep=rep))
    return {'window_s': args.refine_window, 'reps': args.refine_reps, 'cases': cases,
            'sets': _refine_sets(cases)}


def run_dds(args, out, best_doc, parts, joints):
    """Run the latency and refine parts against private nodes; return their results."""
    from ..ros.client import RecoveryClient
    results = {}
    conditions = [False] + ([] if args.no_burner else [True])
    if 'latency' in parts:
        results['latency_hit'] = _hit_latency(args, out, joints, conditions)
    if 'latency' in parts or 'refine' in parts:
        node, domain = _start(out, ('contingency_table:=false',))
        try:
            with RecoveryClient('/', domain) as client:
                client.current_library(args.timeout, diagnostics_timeout=0.0)
                if 'latency' in parts:
                    miss = _latency_conditions(client, joints, args.timeout, conditions,
                                               MISS_P95_MS, 'deadline')
                    results['latency_miss'] = {'conditions': miss}
                if 'refine' in parts:
                    results['refine'] = _refine(args, client, best_doc)
        finally:
            node.stop()
    return results


def print_dds(out, results):
    """Print the latency and refinement tables."""
    rows = []
    for label, key in (('table hit', 'latency_hit'), ('miss (no table)', 'latency_miss')):
        for cond, s in results.get(key, {}).get('conditions', {}).items():
            origins = ' '.join(f'{o}:{n}' for o, n in s['origins'].items())
            rows.append([label, cond, s['n'], s['failures'], origins,
                         f"{s['p50_ms']:.1f}", f"{s['p95_ms']:.1f}", f"{s['max_ms']:.1f}",
                         f"<= {s['target_p95_ms']:g}", 'met' if s['met'] else 'MISSED'])
    if rows:
        out.write('\n== node latency over DDS: fault published -> full library received '
                  '(ms) ==\n')
        if 'latency_hit' in results:
            hit = results['latency_hit']
            out.write(f"table with the entries timed ({hit['table_entries_waited']}) ready "
                      f"{hit['table_wait_s']:.1f} s after the node was started\n")
        out.write(common.text_table(['path', 'condition', 'n', 'failed', 'origins', 'p50',
                                     'p95', 'max', 'target p95', 'verdict'], rows))
    if 'refine' in results:
        out.write('\n== refinement curve (node without table; worst gesture gap to '
                  'best-known, % at t s after the fault; window '
                  f"{results['refine']['window_s']:g} s) ==\n")
        rows = []
        for c in results['refine']['cases']:
            curve = ' '.join(f"{v['t_s']:.2f}s:{v['origin'] or '?'}:"
                             f"{100 * v['worst_gap']:.2f}%" for v in c['versions'])
            first = c['first_within_s']
            rows.append([c['set'], c['rep'], len(c['versions']), curve,
                         '-' if first is None else f'{first:.2f}',
                         f'<= {REFINE_BY_SEC:g}', 'met' if c['met'] else 'MISSED'])
        out.write(common.text_table(['fault set', 'rep', 'versions', 't:origin:gap',
                                     'within 0.5% at s', 'target s', 'verdict'], rows))


def _best_known(out, args, joints):
    """Return the best-known optima document (regenerated first with --update-optima)."""
    optima_file = Path(args.optima_file) if args.optima_file else product.best_known_path()
    if args.update_optima:
        libraries = tuple(args.optima_libraries.split(',')) if args.optima_libraries \
            else tuple(product.LIBRARIES)
        try:
            doc = product.generate_optima(out, args.optima_seeds, args.demo_optima_seeds,
                                          args.jobs, joints=joints, progress=not args.quiet,
                                          libraries=libraries)
        except KeyError as exc:
            raise BenchError(f'--optima-libraries: {exc.args[0]}', EXIT_USAGE) from None
        try:
            old = product.load_product_best_known(optima_file)
        except FileNotFoundError:
            old = None
        product.write_product_optima(optima_file, product.merge_optima(doc, old))
        out.write(f'written: {optima_file}\n')
    try:
        best_doc = product.load_product_best_known(optima_file)
    except FileNotFoundError:
        raise BenchError(f'{optima_file}: no best-known optima; run with --update-optima',
                         EXIT_USAGE) from None
    made = best_doc.get('made', {})
    out.write(f"best-known optima: {best_doc['source']} (made {made.get('date')}, commit "
              f"{made.get('commit')}, {best_doc['libraries']['product']['seeds']} seeds per "
              f'fault set)\n')
    return best_doc


def _run_parts(out, args, summary, best_doc, parts, joints):
    """Run the parts in order; add their results to ``summary``."""
    seeds_given = args.joints or None
    try:
        if 'quality' in parts:
            summary['quality'] = product.run_quality(
                out, best_doc, 'product', args.seeds, not args.no_burner, seeds_given,
                progress=not args.quiet)
        if 'table' in parts:
            summary['table'] = product.run_table(out, best_doc, args.jobs, seeds_given)
        if 'latency' in parts or 'refine' in parts:
            dds = run_dds(args, out, best_doc, parts, joints)
            summary.update(dds)
            print_dds(out, dds)
        if 'demo' in parts:
            summary['demo'] = product.run_quality(
                out, best_doc, 'demo', args.demo_seeds, not args.no_burner, seeds_given,
                progress=not args.quiet)
    except KeyError as exc:
        raise BenchError(str(exc.args[0]), EXIT_USAGE) from None


def run_product(out, args, parts):
    """
    Run the served problem's benchmark (see the module docstring); return the summary.

    ``args`` holds the options of ``bench product`` (checked by the command line);
    ``parts`` are some of :data:`PARTS`.  Writes ``summary.json`` in ``args.out``.
    """
    robot = product.load_models()[0]
    joints = list(args.joints) if args.joints else list(robot.joint_names)
    unknown = [j for j in joints if j not in robot.joint_names]
    if unknown:
        raise BenchError(f'--joints: unknown joint {unknown[0]!r}', EXIT_USAGE)
    out_dir = Path(args.out) if args.out else Path(common.DEFAULT_OUT_ROOT) / 'product'
    summary = {'machine': common.machine_info(), 'parts': parts, 'joints': joints}
    out.write(common.format_machine(summary['machine']) + '\n')
    best_doc = _best_known(out, args, args.joints)
    summary['optima'] = {'file': best_doc['source'], 'made': best_doc.get('made', {})}
    _run_parts(out, args, summary, best_doc, parts, joints)
    common.write_json(out_dir / 'summary.json', summary)
    out.write(f"\n{_verdicts(summary)}written: {out_dir / 'summary.json'}\n")
    return summary


def _verdicts(s):
    """Return the one-line verdicts of every part run."""
    lines = []
    for key, label in (('quality', 'quality at the deadline'), ('demo', 'demo library')):
        for cond, c in s.get(key, {}).get('conditions', {}).items():
            lines.append(f"{label} ({cond}): {100 * c['share_all_within']:.1f}% of runs all "
                         f"within 1% (target 99%): {'met' if c['met'] else 'MISSED'}")
    if 'table' in s:
        lines.append(f"table: {100 * s['table']['share_within']:.1f}% of entries within "
                     f"0.5% (target 100%): {'met' if s['table']['met'] else 'MISSED'}")
    for key, label in (('latency_hit', 'table hit'), ('latency_miss', 'miss')):
        for cond, c in s.get(key, {}).get('conditions', {}).items():
            lines.append(f"latency {label} ({cond}): p95 {c['p95_ms']:.1f} ms (target "
                         f"<= {c['target_p95_ms']:g}): {'met' if c['met'] else 'MISSED'}")
    for name, c in s.get('refine', {}).get('sets', {}).items():
        gaps = ' '.join(f'{100 * g:.2f}%' for g in c['final_gaps'] if g is not None)
        lines.append(f"refine {name}: within 0.5% by 10 s in {100 * c['share_met']:.0f}% of "
                     f"{c['runs']} runs (final gaps {gaps}; target 100%): "
                     f"{'met' if c['met'] else 'MISSED'}")
    return ''.join(line + '\n' for line in lines)
