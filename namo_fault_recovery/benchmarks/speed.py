"""
Whole-library speed and quality of our default ABC against the paper-preset ABC.

For every single right-arm joint failure (locked at the library average) and every
seed ``seed_base + rep``, the whole 4-gesture library is recovered (``recover()`` on the
paper's problem, :data:`~.common.PAPER_SETTINGS`) once by our
default (with the product deadline) and once by the paper-preset ABC (no deadline, as
in the paper), alternating which goes first.  The library wall time is measured around
the call.  Each gesture's score is compared with the best-known optimum
(``config/best_known_optima.yaml``): the share of runs within 0.5% per case, overall
and in the worst case, for both.

The paper ran each gesture on its own (about 0.55 s each, 2.2 s per library); the
engine batches the library into one problem, which already makes the paper preset
faster.  So, for the first ``sequential_reps`` seeds of each joint, the paper ABC is
also timed the paper's way: one call per gesture, the library time being their sum.
"""

import math
from pathlib import Path
import time

import numpy as np

from . import common
from ..recovery.result import CUT_SHORT

TARGET_MEDIAN_S = 0.100
TARGET_P95_S = 0.200
TARGET_SHARE = 0.99
TARGET_RATIO = 10.0
KEYS = ('abc-default', 'abc-paper')


def _run(spec, robot, library, joint, seed, deadline):
    t0 = time.perf_counter()
    report = common.run_recover(robot, library, {joint: None}, common.spec_settings(spec),
                                seed=seed, deadline=deadline, overrides=spec.settings_dict())
    outer = time.perf_counter() - t0
    return {'joint': joint, 'seed': int(seed), 'time': outer,
            'engine_time': float(report.wall_time),
            'statuses': [g.status for g in report.gestures],
            'scores': {g.name: float(g.score_after) for g in report.gestures}}


def _run_sequential(spec, robot, library, joint, seed):
    total = 0.0
    for g in library.names:
        t0 = time.perf_counter()
        common.run_recover(robot, library, {joint: None}, common.spec_settings(spec),
                           seed=seed, gestures=[g], overrides=spec.settings_dict())
        total += time.perf_counter() - t0
    return {'joint': joint, 'seed': int(seed), 'time': total}


def _best_known(best, robot, library):
    """Return the best-known optima (None: the packaged file, if any) and notes on them."""
    from .optimum import load_best_known
    notes = []
    if best is None:
        try:
            best = load_best_known()
        except (OSError, ValueError) as exc:
            notes.append(f'no best-known optima ({exc}); quality not assessed')
    if best is not None:
        warn = best.check_model(robot, library)
        if warn:
            notes.append(warn)
    return best, notes


def run_speed(out, out_dir, reps=100, joints=None, seed_base=0, deadline=1.0,
              files=common.ModelFiles(), progress=True, best=None, sequential_reps=10):
    """
    Run the speed benchmark, write ``runs.csv``/``summary.json`` and print the figures.

    ``deadline`` applies to our default only; the paper ABC runs unbounded.  ``best`` is
    a :class:`~.optimum.BestKnownOptima` (None: the packaged file); ``files`` a
    :class:`~.common.ModelFiles`.
    """
    robot, library = files.load()
    cases = common.select_cases(robot, library, None, joints)
    joint_list = list(dict.fromkeys(j for _, j in cases))
    specs = {k: common.lookup_spec(k) for k in KEYS}
    deadlines = {'abc-default': deadline, 'abc-paper': None}
    best, notes = _best_known(best, robot, library)
    info = common.machine_info()
    # Warm-up (imports, caches): one untimed library run of each.
    for k in KEYS:
        _run(specs[k], robot, library, joint_list[0], seed_base, deadlines[k])
    runs = {k: [] for k in KEYS}
    sequential = []
    prog = common.Progress(len(joint_list) * reps, 'speed') if progress else None
    for joint in joint_list:
        for rep in range(reps):
            order = KEYS if rep % 2 == 0 else KEYS[::-1]
            for k in order:
                runs[k].append(_run(specs[k], robot, library, joint, seed_base + rep,
                                    deadlines[k]))
            if rep < sequential_reps:
                sequential.append(_run_sequential(specs['abc-paper'], robot, library, joint,
                                                  seed_base + rep))
            if prog:
                prog.step(note=joint)
    summary = summarise(robot, library, runs, best, joint_list)
    summary['sequential'] = _sequential_summary(sequential, runs['abc-default'])
    summary.update({'machine': info, 'machine_end': common.machine_info(), 'notes': notes,
                    'config': {'reps': reps, 'seeds': [seed_base, seed_base + reps - 1],
                               'deadline_default': deadline, 'deadline_paper': None,
                               'joints': joint_list}})
    out_dir = Path(out_dir)
    rows = []
    for k, rs in runs.items():
        for r in rs:
            rows.append([k, r['joint'], r['seed'], r['time'], r['engine_time'],
                         ';'.join(sorted(set(r['statuses'])))]
                        + [r['scores'].get(g, math.nan) for g in library.names])
    common.write_csv(out_dir / 'runs.csv', ['algorithm', 'joint', 'seed', 'library_time_s',
                                            'engine_time_s', 'statuses']
                     + [f'score_{g}' for g in library.names], rows)
    common.write_json(out_dir / 'summary.json', summary)
    _print(out, summary, out_dir)
    return summary


def _sequential_summary(sequential, ours):
    """Paper ABC run gesture by gesture (as the paper did) against ours, same seeds."""
    if not sequential:
        return None
    keys = {(r['joint'], r['seed']) for r in sequential}
    t_seq = [r['time'] for r in sequential]
    t_ours = [r['time'] for r in ours if (r['joint'], r['seed']) in keys]
    med_seq, med_ours = common.percentile(t_seq, 50), common.percentile(t_ours, 50)
    return {'n': len(t_seq), 'median': med_seq, 'p95': common.percentile(t_seq, 95),
            'ours_median_same_seeds': med_ours, 'ratio_median': med_seq / med_ours}


def summarise(robot, library, runs, best, joints):
    """Return timing and quality figures from the runs."""
    timing = {}
    for k, rs in runs.items():
        t = [r['time'] for r in rs]
        timing[k] = {'n': len(t), 'median': common.percentile(t, 50),
                     'p95': common.percentile(t, 95), 'max': float(np.max(t)) if t else math.nan,
                     'mean': float(np.mean(t)) if t else math.nan,
                     'deadline_hits': sum(any(s in CUT_SHORT
                                              for s in r['statuses']) for r in rs)}
    ratio = {'median': timing['abc-paper']['median'] / timing['abc-default']['median'],
             'p95': timing['abc-paper']['p95'] / timing['abc-default']['p95']}
    quality = None
    if best is not None:
        quality = {}
        for k, rs in runs.items():
            per_case = []
            for g in library.names:
                for j in joints:
                    if (g, j) not in best:
                        continue
                    opt = best.score(g, j)
                    scores = [r['scores'][g] for r in rs if r['joint'] == j]
                    gaps = [common.relative_gap(s, opt) for s in scores]
                    per_case.append({
                        'gesture': g, 'joint': j, 'optimum': opt, 'n': len(scores),
                        'share_within': float(np.mean([common.within(s, opt)
                                                       for s in scores])),
                        'median_score': float(np.median(scores)),
                        'median_gap': float(np.median(gaps)), 'max_gap': float(np.max(gaps)),
                        'below_optimum': int(sum(gp < -1e-6 for gp in gaps))})
            n_all = sum(c['n'] for c in per_case)
            quality[k] = {
                'cases': per_case,
                'share_within_overall': (sum(c['share_within'] * c['n'] for c in per_case)
                                         / n_all if n_all else math.nan),
                'worst_case': min(per_case, key=lambda c: (c['share_within'],
                                                           -c['max_gap'])),
            }
        quality['equal_or_better'] = _compare(quality['abc-default']['cases'],
                                              quality['abc-paper']['cases'])
    return {'timing': timing, 'ratio': ratio, 'quality': quality}


def _compare(ours, paper):
    """Check per case that our default's quality equals or beats the paper ABC's."""
    worse = []
    for a, b in zip(ours, paper):
        share_ok = a['share_within'] >= b['share_within'] - 1e-12
        median_ok = a['median_score'] <= b['median_score'] * (1 + 1e-9) + 1e-12
        if not (share_ok and median_ok):
            worse.append({'gesture': a['gesture'], 'joint': a['joint'],
                          'share_ours': a['share_within'], 'share_paper': b['share_within'],
                          'median_ours': a['median_score'], 'median_paper': b['median_score']})
    return {'cases': len(ours), 'equal_or_better': len(ours) - len(worse), 'worse': worse}


def _ms(x):
    return common.fmt(1000 * x, 1)


def _print_quality(out, q):
    """Print the quality half of ``bench speed``: the share within 0.5%, per case."""
    out.write('\nshare of runs within 0.5% of the best-known optimum, per case '
              '(ours | paper ABC)\n')
    rows = []
    for a, b in zip(q['abc-default']['cases'], q['abc-paper']['cases']):
        rows.append([a['gesture'], a['joint'].replace('right_arm_', ''),
                     common.fmt(a['optimum']), f'{100 * a["share_within"]:.0f}%',
                     common.fmt(100 * a['max_gap'], 3), f'{100 * b["share_within"]:.0f}%',
                     common.fmt(100 * b['median_gap'], 2), common.fmt(100 * b['max_gap'], 2)])
    out.write(common.text_table(['gesture', 'joint', 'optimum', 'ours within',
                                 'ours max gap %', 'paper within', 'paper median gap %',
                                 'paper max gap %'], rows))
    for k in ('abc-default', 'abc-paper'):
        qq = q[k]
        w = qq['worst_case']
        out.write(f'{common.lookup_spec(k).label}: {100 * qq["share_within_overall"]:.2f}% of '
                  f'runs within 0.5% overall; worst case {w["gesture"]} {w["joint"]}: '
                  f'{100 * w["share_within"]:.0f}% (max gap {100 * w["max_gap"]:.3f}%)\n')
        below = [cc for cc in qq['cases'] if cc['below_optimum']]
        for cc in below:
            out.write(f'  note: {cc["below_optimum"]} run(s) beat the stored optimum of '
                      f'{cc["gesture"]} {cc["joint"]}; rerun `bench optimum --write`\n')
    worst = min(c['share_within'] for c in q['abc-default']['cases'])
    out.write(f'target >= {100 * TARGET_SHARE:.0f}% within 0.5% in every case: '
              f'{_verdict(worst >= TARGET_SHARE)} (worst {100 * worst:.0f}%)\n')
    e = q['equal_or_better']
    out.write(f'quality equal or better than the paper ABC (share within 0.5% and median '
              f'score): {e["equal_or_better"]}/{e["cases"]} cases\n')
    for w in e['worse']:
        out.write(f'  worse: {w["gesture"]} {w["joint"]}: within {100 * w["share_ours"]:.0f}% '
                  f'vs {100 * w["share_paper"]:.0f}%, median {w["median_ours"]:.4f} vs '
                  f'{w["median_paper"]:.4f}\n')


def _print(out, s, out_dir):
    c = s['config']
    out.write(common.format_machine(s['machine'], 'machine at start') + '\n')
    out.write(common.format_machine(s['machine_end'], 'machine at end') + '\n')
    for note in s['notes']:
        out.write(note + '\n')
    out.write(f'speed: whole library ({len(c["joints"])} single right-arm joint failures x '
              f'{c["reps"]} seeds {c["seeds"][0]}..{c["seeds"][1]}), our default with '
              f'deadline {c["deadline_default"]} s, the paper ABC without one\n')
    t = s['timing']
    rows = [[common.lookup_spec(k).label, v['n'], _ms(v['median']), _ms(v['p95']),
             _ms(v['max']), _ms(v['mean']), v['deadline_hits']] for k, v in t.items()]
    out.write(common.text_table(['algorithm', 'runs', 'median ms', 'p95 ms', 'max ms',
                                 'mean ms', 'deadline hits'], rows))
    r = s['ratio']
    out.write(f'ratio paper ABC / ours: median {r["median"]:.1f}x, p95 {r["p95"]:.1f}x\n')
    seq = s.get('sequential')
    if seq:
        out.write(f'paper ABC one gesture at a time, as the paper ran it ({seq["n"]} library '
                  f'runs, the first seeds of each joint): median {_ms(seq["median"])} ms, p95 '
                  f'{_ms(seq["p95"])} ms; ratio to ours on the same seeds: median '
                  f'{seq["ratio_median"]:.1f}x\n')
    d = t['abc-default']
    out.write(f'target median <= {1000 * TARGET_MEDIAN_S:.0f} ms: '
              f'{_verdict(d["median"] <= TARGET_MEDIAN_S)} ({_ms(d["median"])} ms); '
              f'p95 <= {1000 * TARGET_P95_S:.0f} ms: {_verdict(d["p95"] <= TARGET_P95_S)} '
              f'({_ms(d["p95"])} ms); >= {TARGET_RATIO:.0f}x faster: '
              f'{_verdict(r["median"] >= TARGET_RATIO)} ({r["median"]:.1f}x)\n')
    q = s['quality']
    if q is None:
        out.write(f'written: {out_dir / "runs.csv"}, {out_dir / "summary.json"}\n')
        return
    _print_quality(out, q)
    out.write(f'written: {out_dir / "runs.csv"}, {out_dir / "summary.json"}\n')


def _verdict(ok):
    return 'met' if ok else 'MISSED'
