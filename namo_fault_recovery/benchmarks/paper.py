"""
The paper's comparison (its Tables 3-6): GA, BFOA and ABC with the paper presets, and ours.

Every case (gesture, failed right-arm joint, locked at the library average) is solved
per gesture, as the paper did, ``reps`` times with seeds ``seed_base + rep``.  Each
finished (algorithm, gesture, joint) case is kept as one JSON file under
``OUT/cases/``; a rerun skips the seeds already there, so a long run can be stopped and
resumed.  The outputs are ``runs.csv`` (every run), ``summary.csv`` and
``summary.json`` (statistics, Kruskal-Wallis tests, the paper's numbers),
``tables.md`` (markdown tables beside the paper's) and box plots
``scores_<gesture>.png`` and ``times.png``.
"""

from concurrent.futures import as_completed, ProcessPoolExecutor
from dataclasses import dataclass
import math
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from . import common
from .paper_data import PAPER_COLUMN, paper_table6, TABLE4, TABLE5
from ..optimize import make_algorithm

QUICK_REPS = 5
QUICK_JOINTS = ('2',)
_SAVE_EVERY = 10   # runs between saves of a case file


def case_path(out_dir, key, gesture, joint):
    """Return the JSON file of one finished (algorithm, gesture, joint) case."""
    return Path(out_dir) / 'cases' / f'{key}__{gesture}__{joint}.json'


def _signature(spec, deadline):
    """Return what must match for stored runs to be reused: settings and deadline."""
    algo = make_algorithm(spec.algorithm, spec.preset, **spec.settings_dict())
    return {'algorithm': spec.algorithm, 'preset': spec.preset,
            'settings': common.plain(algo.options()), 'deadline': deadline}


def _load_case(path, signature):
    import json
    try:
        with open(path) as fh:
            doc = json.load(fh)
    except (OSError, ValueError):
        return None
    if doc.get('signature') != signature:
        return None
    return doc


def run_case(task):
    """
    Run the missing seeds of one case and save it; return ``(key, gesture, joint, n_run)``.

    ``task`` is a tuple ``(key, gesture, joint, seeds, deadline, files, path)`` (``files``:
    a :class:`~.common.ModelFiles`); a module-level function so that worker processes
    can run it.
    """
    key, gesture, joint, seeds, deadline, files, path = task
    robot, library = files.load()
    spec = common.lookup_spec(key)
    signature = _signature(spec, deadline)
    doc = _load_case(path, signature) or {
        'algorithm': key, 'gesture': gesture, 'joint': joint, 'signature': signature,
        'runs': []}
    have = {r['seed'] for r in doc['runs']}
    todo = [s for s in seeds if s not in have]
    for i, seed in enumerate(todo):
        doc['runs'].append(common.run_gesture(spec, robot, library, gesture, joint, seed,
                                              deadline))
        if (i + 1) % _SAVE_EVERY == 0:
            common.write_json(path, doc)
    if todo or not Path(path).exists():
        doc['machine'] = common.machine_info()
        common.write_json(path, doc)
    return key, gesture, joint, len(todo)


_COST = {'abc-paper': 4, 'bfoa-paper': 3, 'gd-paper-lr0.1': 2, 'gd-paper-lr0.05': 2}


@dataclass(frozen=True)
class PaperRun:
    """
    What the comparison runs: ``reps`` seeds from ``seed_base`` of the algorithms ``keys``.

    ``gestures`` / ``joints`` select the cases (None: all); ``jobs`` worker processes
    run them.  ``deadline`` (s) applies to each per-gesture run (None: the algorithms
    run their full iteration counts, as in the paper).
    """

    reps: int = 100
    jobs: int = 1
    keys: Sequence[str] = common.PAPER_LINEUP
    gestures: Optional[Sequence[str]] = None
    joints: Optional[Sequence[str]] = None
    seed_base: int = 0
    deadline: Optional[float] = None


def run_paper(out, out_dir, run: PaperRun = PaperRun(),
              files: common.ModelFiles = common.ModelFiles(), plots=True, progress=True):
    """
    Run (or resume) the comparison and write and print its tables; return the summary.

    ``run`` (:class:`PaperRun`) says what runs; ``files`` are the models.
    """
    robot, library = files.load()
    cases = common.select_cases(robot, library, run.gestures, run.joints)
    keys = [common.lookup_spec(k).key for k in run.keys]
    seeds = [run.seed_base + r for r in range(run.reps)]
    deadline, jobs = run.deadline, run.jobs
    out_dir = Path(out_dir)
    info = common.machine_info()
    tasks = [(k, g, j, seeds, deadline, files, case_path(out_dir, k, g, j))
             for k in keys for g, j in cases]
    tasks.sort(key=lambda t: -_COST.get(t[0], 1))
    prog = common.Progress(len(tasks), 'paper') if progress else None
    fresh = 0
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(run_case, t) for t in tasks]
            for fut in as_completed(futures):
                key, g, j, n = fut.result()
                fresh += n
                if prog:
                    prog.step(note=f'{key} {g} {j}: {n} new runs')
    else:
        for t in tasks:
            key, g, j, n = run_case(t)
            fresh += n
            if prog:
                prog.step(note=f'{key} {g} {j}: {n} new runs')

    runs = {}
    for k, g, j, _, _, _, path in tasks:
        doc = _load_case(path, _signature(common.lookup_spec(k), deadline))
        wanted = set(seeds)
        runs[(k, g, j)] = sorted((r for r in doc['runs'] if r['seed'] in wanted),
                                 key=lambda r: r['seed'])
    summary = summarise(robot, runs, keys, cases)
    summary['machine'] = info
    summary['machine_end'] = common.machine_info()
    summary['config'] = {'reps': run.reps, 'seeds': [seeds[0], seeds[-1]] if seeds else [],
                         'algorithms': {k: _signature(common.lookup_spec(k), deadline)
                                        for k in keys},
                         'jobs': jobs, 'new_runs': fresh, 'out_dir': str(out_dir)}
    _write_outputs(robot, out_dir, runs, summary, keys, cases, plots, out)
    _print(robot, out, summary, keys, cases, jobs, fresh, out_dir)
    return summary


def summarise(robot, runs, keys, cases):
    """Return statistics per (algorithm, case) and Kruskal-Wallis tests per case."""
    try:
        from .optimum import load_best_known
        best = load_best_known()
    except (OSError, ValueError):
        best = None
    stats = []
    for k in keys:
        for g, j in cases:
            rs = runs[(k, g, j)]
            jn = common.joint_number(robot, j)
            entry = {'algorithm': k, 'gesture': g, 'joint': j, 'joint_number': jn,
                     'score': common.describe([r['score'] for r in rs]),
                     'time': common.describe([r['time'] for r in rs]),
                     'statuses': _count([r['status'] for r in rs]),
                     'paper': paper_table6(g, jn, k),
                     'best_known': (best.cases[(g, j)]['score']
                                    if best is not None and (g, j) in best else None)}
            stats.append(entry)
    tests = []
    for g, j in cases:
        row = {'gesture': g, 'joint': j, 'joint_number': common.joint_number(robot, j)}
        for label, subset in (('paper3', [k for k in keys if k in PAPER_COLUMN]),
                              ('all', list(keys))):
            for what in ('score', 'time'):
                h, p, df = common.kruskal([[r[what] for r in runs[(k, g, j)]]
                                           for k in subset])
                row[f'{what}_{label}'] = {'H': h, 'p': p, 'df': df, 'algorithms': subset}
        tests.append(row)
    return {'stats': stats, 'kruskal': tests,
            'best_known_source': None if best is None else best.source}


def _count(items):
    out = {}
    for x in items:
        out[x] = out.get(x, 0) + 1
    return out


def _stat_of(summary, key, gesture, joint):
    for s in summary['stats']:
        if s['algorithm'] == key and s['gesture'] == gesture and s['joint'] == joint:
            return s
    return None


def _test_of(summary, gesture, joint):
    for t in summary['kruskal']:
        if t['gesture'] == gesture and t['joint'] == joint:
            return t
    return None


_STAT_COLS = ('min', 'max', 'mean', 'sd', 'median', 'iqr')


def _descriptive_rows(robot, summary, keys, cases, what, joint, paper_table, prec):
    """Rows of a Table 4/5-like table for one failed joint (ours, then the paper's)."""
    rows = []
    for g in dict.fromkeys(c[0] for c in cases):
        if (g, joint) not in cases:
            continue
        test = _test_of(summary, g, joint)
        for n, k in enumerate(keys):
            d = _stat_of(summary, k, g, joint)[what]
            kw = ''
            if n == 0:
                t3, ta = test[f'{what}_paper3'], test[f'{what}_all']
                kw = (f'H({t3["df"]}) = {common.fmt(t3["H"], 3)}, p = {common.fmt_p(t3["p"])}; '
                      f'H({ta["df"]}) = {common.fmt(ta["H"], 3)}, p = {common.fmt_p(ta["p"])}')
            rows.append([g if n == 0 else '', common.lookup_spec(k).label]
                        + [common.fmt(d[c], prec) for c in _STAT_COLS] + [kw])
        if paper_table is not None and joint == 'right_arm_joint2' and g in paper_table:
            for n, (col, label) in enumerate((('ga', 'GA'), ('bfoa', 'BFOA'), ('abc', 'ABC'))):
                p = paper_table[g][col]
                kw = f'paper: H(2) = {paper_table[g]["kruskal_h"]:.3f}' if n == 0 else ''
                rows.append(['', f'{label} (paper)'] + [f'{p[c]:.4f}' for c in _STAT_COLS]
                            + [kw])
    return rows


def _table6_rows(robot, summary, keys, cases):
    rows = []
    for g, j in cases:
        row = [g, common.joint_number(robot, j)]
        for k in keys:
            s = _stat_of(summary, k, g, j)
            row += [common.fmt(s['score']['min']), common.fmt(s['time']['median']),
                    common.fmt(s['score']['median']), common.fmt(s['score']['iqr'])]
        rows.append(row)
    return rows


def _table6_header(keys):
    header = ['gesture', 'joint']
    for k in keys:
        label = common.lookup_spec(k).label
        header += [f'{label} min', 'time s', 'median', 'IQR']
    return header


def _comparison_rows(robot, summary, keys, cases):
    """Paper Table 6 ABC minimum beside ours, per case."""
    rows = []
    for g, j in cases:
        jn = common.joint_number(robot, j)
        paper = paper_table6(g, jn, 'abc-paper') or {}
        row = [g, jn, common.fmt(paper.get('min'))]
        ours = {}
        for k in ('abc-paper', 'abc-default'):
            if k in keys:
                ours[k] = _stat_of(summary, k, g, j)['score']['min']
                row.append(common.fmt(ours[k]))
        best = _stat_of(summary, keys[0], g, j)['best_known']
        row.append(common.fmt(best))
        ref = ours.get('abc-paper', ours.get('abc-default'))
        ratio = ref / paper['min'] if paper.get('min') and ref is not None else math.nan
        row.append(common.fmt(ratio, 3))
        row.append(common.fmt(paper.get('median')))
        if 'abc-paper' in keys:
            row.append(common.fmt(_stat_of(summary, 'abc-paper', g, j)['score']['median']))
        rows.append(row)
    return rows


def _comparison_header(keys):
    header = ['gesture', 'joint', 'paper ABC min']
    header += [f'{common.lookup_spec(k).label} min' for k in ('abc-paper', 'abc-default')
               if k in keys]
    header += ['best-known', 'ours/paper', 'paper ABC median']
    if 'abc-paper' in keys:
        header.append('ABC (paper) median')
    return header


def _joints_in(cases):
    joints = list(dict.fromkeys(j for _, j in cases))
    if 'right_arm_joint2' in joints:   # the paper's Tables 3-5 case first
        joints.remove('right_arm_joint2')
        joints.insert(0, 'right_arm_joint2')
    return joints


def _write_outputs(robot, out_dir, runs, summary, keys, cases, plots, out):
    rows = []
    for (k, g, j), rs in runs.items():
        for r in rs:
            rows.append([k, g, j, r['seed'], r['score'], r.get('score_engine', ''),
                         r['score_before'], r['time'], r['engine_time'], r['status'],
                         r.get('nfev', '')])
    common.write_csv(out_dir / 'runs.csv', ['algorithm', 'gesture', 'joint', 'seed', 'score',
                                            'score_engine', 'score_before', 'time_s',
                                            'engine_time_s', 'status', 'nfev'], rows)
    header = ['algorithm', 'gesture', 'joint', 'n']
    header += [f'score_{c}' for c in _STAT_COLS] + [f'time_{c}' for c in _STAT_COLS]
    header += ['paper_min', 'paper_time', 'paper_median', 'paper_iqr', 'best_known']
    rows = []
    for s in summary['stats']:
        p = s['paper'] or {}
        rows.append([s['algorithm'], s['gesture'], s['joint'], s['score']['n']]
                    + [s['score'][c] for c in _STAT_COLS] + [s['time'][c] for c in _STAT_COLS]
                    + [p.get('min', ''), p.get('time', ''), p.get('median', ''),
                       p.get('iqr', ''), '' if s['best_known'] is None else s['best_known']])
    common.write_csv(out_dir / 'summary.csv', header, rows)
    common.write_json(out_dir / 'summary.json', summary)
    common.write_text(out_dir / 'tables.md', markdown(robot, summary, keys, cases))
    if not plots:
        return
    from . import plotting
    try:
        optima = {(s['gesture'], s['joint']): s['best_known'] for s in summary['stats']
                  if s['best_known'] is not None}
        written = plotting.boxplot_paper(runs, keys, cases, out_dir,
                                         {k: common.lookup_spec(k).label for k in keys},
                                         optima=optima)
    except plotting.MatplotlibMissing as exc:
        out.write(f'box plots skipped: {exc}\n')
        return
    summary['plots'] = [str(p) for p in written]


def markdown(robot, summary, keys, cases):
    """Return the markdown tables (Tables 4, 5 and 6 of the paper, reproduced)."""
    c = summary['config']
    m = summary['machine']
    parts = [f'# Paper comparison (Tables 3-6), {c["reps"]} repetitions per case\n',
             f'Seeds {c["seeds"][0]}..{c["seeds"][-1]}; per-gesture runs; {m["cpus"]} CPUs, '
             f'load average at start {m["loadavg"][0]:.2f}, {c["jobs"]} job(s); '
             f'{m["time"]}. Scores: lower is better; each is the best the optimiser found, as '
             f'the paper reports it (the engine returns the better of it and the locked '
             f'reference pose). Times: seconds of wall clock per gesture.\n']
    head = ['gesture', 'algorithm', 'MIN', 'MAX', 'MEAN', 'SD', 'Median', 'IQR',
            'Kruskal-Wallis (paper algorithms; all)']
    for j in _joints_in(cases):
        jn = common.joint_number(robot, j)
        parts.append(f'\n## Score, joint {jn} failed (cf. Table 4)\n\n')
        parts.append(common.markdown_table(
            head, _descriptive_rows(robot, summary, keys, cases, 'score', j, TABLE4, 4),
            ['l', 'l'] + ['r'] * 6 + ['l']))
        parts.append(f'\n## Time (s), joint {jn} failed (cf. Table 5)\n\n')
        parts.append(common.markdown_table(
            head, _descriptive_rows(robot, summary, keys, cases, 'time', j, TABLE5, 4),
            ['l', 'l'] + ['r'] * 6 + ['l']))
    parts.append('\n## All cases (cf. Table 6): min, median time, median and IQR of the '
                 'score\n\n')
    parts.append(common.markdown_table(_table6_header(keys),
                                       _table6_rows(robot, summary, keys, cases)))
    parts.append('\n## Paper Table 6 ABC minimum beside ours\n\n')
    parts.append(common.markdown_table(_comparison_header(keys),
                                       _comparison_rows(robot, summary, keys, cases)))
    parts.append("\nThe paper's absolute scores are not directly comparable: its joint "
                 'limits, d_offset and orientation units are not given.\n')
    return ''.join(parts)


def _print(robot, out, summary, keys, cases, jobs, fresh, out_dir):
    c = summary['config']
    out.write(common.format_machine(summary['machine'], 'machine at start') + '\n')
    out.write(common.format_machine(summary['machine_end'], 'machine at end') + '\n')
    out.write(f'paper comparison: {len(cases)} case(s) x {len(keys)} algorithm(s) x '
              f'{c["reps"]} rep(s), seeds {c["seeds"][0]}..{c["seeds"][-1]}, per-gesture runs, '
              f'{jobs} job(s){"" if jobs == 1 else " (times include contention)"}; '
              f'{fresh} new run(s), the rest reused from {out_dir / "cases"}\n')
    j = _joints_in(cases)[0]
    jn = common.joint_number(robot, j)
    head = ['gesture', 'algorithm', 'MIN', 'MAX', 'MEAN', 'SD', 'Median', 'IQR',
            'Kruskal-Wallis (paper algorithms; all)']
    out.write(f'\nscore, joint {jn} failed (cf. Table 4)\n')
    out.write(common.text_table(head, _descriptive_rows(robot, summary, keys, cases, 'score',
                                                        j, TABLE4, 4)))
    out.write(f'\ntime (s), joint {jn} failed (cf. Table 5)\n')
    out.write(common.text_table(head, _descriptive_rows(robot, summary, keys, cases, 'time',
                                                        j, TABLE5, 4)))
    out.write('\nall cases (cf. Table 6): min score, median time (s), median score, IQR\n')
    out.write(common.text_table(_table6_header(keys), _table6_rows(robot, summary, keys,
                                                                   cases)))
    out.write('\npaper Table 6 ABC minimum beside ours\n')
    out.write(common.text_table(_comparison_header(keys),
                                _comparison_rows(robot, summary, keys, cases)))
    out.write('\nKruskal-Wallis per case (scores; times)\n')
    rows = []
    for t in summary['kruskal']:
        rows.append([t['gesture'], t['joint_number']]
                    + [f'H({t[f"{w}_{s}"]["df"]}) = {common.fmt(t[f"{w}_{s}"]["H"], 2)}, '
                       f'p = {common.fmt_p(t[f"{w}_{s}"]["p"])}'
                       for w in ('score', 'time') for s in ('paper3', 'all')])
    out.write(common.text_table(['gesture', 'joint', 'score (paper algs)', 'score (all)',
                                 'time (paper algs)', 'time (all)'], rows))
    out.write(f'\nwritten: {out_dir / "runs.csv"}, {out_dir / "summary.csv"}, '
              f'{out_dir / "summary.json"}, {out_dir / "tables.md"}\n')
    if summary.get('plots'):
        out.write('box plots: ' + ', '.join(summary['plots']) + '\n')
    if summary.get('best_known_source') is None:
        out.write('note: no best-known optima file; run `namo-recovery bench optimum '
                  '--write`\n')
    means = {k: float(np.mean([_stat_of(summary, k, g, jj)['time']['median']
                               for g, jj in cases])) for k in keys}
    out.write('mean of the per-case median times (s): ' + ', '.join(
        f'{common.lookup_spec(k).label} {v:.4f}' for k, v in means.items()) + '\n')
