"""
Deadline overrun: how far past its deadline a whole-library reconfiguration returns.

Each algorithm runs with an iteration count it cannot finish (e.g. 10^9 ABC cycles), so
the deadline always binds.  The whole library is reconfigured for a single right-arm
joint failure (the joint cycles with the repetition) with deadlines of 0.05, 0.1, 0.25
and 1 s, once on the machine as it is and once more with a CPU-burning process pinned
to the other core.  The overrun is the wall time measured around the call minus the
deadline (the engine's own ``wall_time`` is reported too).
"""

import contextlib
import functools
import os
from pathlib import Path
import subprocess
import sys
import time

import numpy as np

from . import common

DEADLINES = (0.05, 0.1, 0.25, 1.0)
TARGET_OVERRUN_S = 0.020
_HUGE = 10 ** 9

# Algorithm key -> (optimiser, preset, overrides that make the deadline bind).
UNBOUNDED = {
    'abc-default': ('abc', 'default', {'max_cycles': _HUGE}),
    'abc-paper': ('abc', 'paper', {'max_cycles': _HUGE}),
    'ga-paper': ('ga', 'paper', {'generations': _HUGE}),
    'bfoa-paper': ('bfoa', 'paper', {'elimination_events': _HUGE}),
    'gd-paper': ('gd', 'paper', {'iterations': _HUGE}),
}
DEFAULT_KEYS = tuple(UNBOUNDED)


class CpuBurner:
    """A busy-looping child process, pinned to another core when there is one."""

    def __init__(self):
        self.proc = None
        self.cpu = None

    def __enter__(self):
        cpus = sorted(_affinity())
        self.cpu = cpus[-1] if len(cpus) > 1 else None
        preexec = None
        if self.cpu is not None and hasattr(os, 'sched_setaffinity'):
            preexec = functools.partial(os.sched_setaffinity, 0, {self.cpu})
        self.proc = subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                                     stdin=subprocess.DEVNULL, preexec_fn=preexec)
        time.sleep(0.3)   # let it get going
        return self

    def __exit__(self, *exc):
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
        return False


def _affinity():
    try:
        return os.sched_getaffinity(0)
    except AttributeError:
        return set(range(os.cpu_count() or 1))


def run_deadline(out, out_dir, deadlines=DEADLINES, reps=10, keys=DEFAULT_KEYS, burner=True,
                 robot_file=None, gesture_file=None, progress=True):
    """
    Run the deadline benchmark; write ``runs.csv``/``summary.json`` and print the figures.

    ``burner`` adds the second pass with the CPU burner.  Returns the summary dict.
    """
    robot, library = common.models(robot_file, gesture_file)
    joints = common.right_arm_joints(robot)
    for k in keys:
        if k not in UNBOUNDED:
            raise ValueError(f'unknown algorithm key {k!r}; expected one of '
                             f'{", ".join(UNBOUNDED)}')
    conditions = ['idle', 'cpu burner'] if burner else ['idle']
    info = {'start': common.machine_info()}
    # Warm-up (imports, caches).
    for k in keys:
        _run(robot, library, k, joints[0], 0, deadlines[0])
    prog = (common.Progress(len(conditions) * len(deadlines) * reps * len(keys), 'deadline')
            if progress else None)
    runs = []
    for cond in conditions:
        burning = cond == 'cpu burner'
        with (CpuBurner() if burning else contextlib.nullcontext()) as ctx:
            if burning:
                info['burner_cpu'] = ctx.cpu
            info[cond] = common.machine_info()
            for d in deadlines:
                for rep in range(reps):
                    for k in keys:
                        r = _run(robot, library, k, joints[rep % len(joints)], rep, d)
                        r['condition'] = cond
                        runs.append(r)
                        if prog:
                            prog.step(note=f'{cond} {d} s')
    info['end'] = common.machine_info()
    summary = summarise(runs, conditions, deadlines, keys)
    summary['machine'] = info
    summary['config'] = {'deadlines': list(deadlines), 'reps': reps, 'algorithms': {
        k: {'algorithm': UNBOUNDED[k][0], 'preset': UNBOUNDED[k][1],
            'settings': UNBOUNDED[k][2]} for k in keys}}
    out_dir = Path(out_dir)
    common.write_csv(out_dir / 'runs.csv',
                     ['condition', 'deadline_s', 'algorithm', 'joint', 'seed', 'wall_s',
                      'engine_wall_s', 'overrun_s', 'bound'],
                     [[r['condition'], r['deadline'], r['algorithm'], r['joint'], r['seed'],
                       r['wall'], r['engine_wall'], r['overrun'], r['bound']] for r in runs])
    common.write_json(out_dir / 'summary.json', summary)
    _print(out, summary, out_dir)
    return summary


def _run(robot, library, key, joint, seed, deadline):
    algorithm, preset, settings = UNBOUNDED[key]
    t0 = time.perf_counter()
    report = common.run_recover(robot, library, {joint: None},
                                common.PAPER_SETTINGS.with_changes(
                                    optimizer=algorithm, optimizer_preset=preset),
                                seed=seed, deadline=deadline, overrides=settings)
    wall = time.perf_counter() - t0
    return {'algorithm': key, 'joint': joint, 'seed': seed, 'deadline': deadline,
            'wall': wall, 'engine_wall': float(report.wall_time), 'overrun': wall - deadline,
            'bound': not report.deadline_met}


def summarise(runs, conditions, deadlines, keys):
    """Return the overrun figures per condition and deadline (and per algorithm)."""
    rows = []
    for cond in conditions:
        for d in deadlines:
            rs = [r for r in runs if r['condition'] == cond and r['deadline'] == d]
            worst = max(rs, key=lambda r: r['overrun'])
            rows.append({
                'condition': cond, 'deadline': d, 'n': len(rs),
                'bound_share': float(np.mean([r['bound'] for r in rs])),
                'median_overrun': common.percentile([r['overrun'] for r in rs], 50),
                'p95_overrun': common.percentile([r['overrun'] for r in rs], 95),
                'worst_overrun': worst['overrun'], 'worst_algorithm': worst['algorithm'],
                'worst_engine_overrun': max(r['engine_wall'] - d for r in rs),
                'per_algorithm': {k: max(r['overrun'] for r in rs if r['algorithm'] == k)
                                  for k in keys},
            })
    worst = max(rows, key=lambda r: r['worst_overrun'])
    return {'rows': rows, 'worst': {'overrun': worst['worst_overrun'],
                                    'condition': worst['condition'],
                                    'deadline': worst['deadline'],
                                    'algorithm': worst['worst_algorithm']}}


def _print(out, s, out_dir):
    m = s['machine']
    out.write(common.format_machine(m['start'], 'machine at start') + '\n')
    if 'cpu burner' in m:
        out.write(common.format_machine(m['cpu burner'], 'with the burner') +
                  f' (burner pinned to CPU {m.get("burner_cpu")})\n')
    c = s['config']
    out.write(f'deadline: whole library, single right-arm joint failures, {c["reps"]} run(s) '
              f'per deadline and algorithm ({", ".join(c["algorithms"])}), iteration counts '
              f'that cannot finish\n')
    keys = list(c['algorithms'])
    rows = []
    for r in s['rows']:
        rows.append([r['condition'], f'{r["deadline"]:g}', r['n'],
                     f'{100 * r["bound_share"]:.0f}%', common.fmt(1000 * r['median_overrun'], 2),
                     common.fmt(1000 * r['p95_overrun'], 2),
                     common.fmt(1000 * r['worst_overrun'], 2), r['worst_algorithm'],
                     common.fmt(1000 * r['worst_engine_overrun'], 2)]
                    + [common.fmt(1000 * r['per_algorithm'][k], 1) for k in keys])
    out.write(common.text_table(['condition', 'deadline s', 'runs', 'bound', 'median ms',
                                 'p95 ms', 'worst ms', 'worst by', 'engine worst ms']
                                + [f'{k} ms' for k in keys], rows))
    w = s['worst']
    verdict = 'met' if w['overrun'] <= TARGET_OVERRUN_S else 'MISSED'
    out.write(f'worst overrun {1000 * w["overrun"]:.2f} ms ({w["algorithm"]}, deadline '
              f'{w["deadline"]:g} s, {w["condition"]}); target <= '
              f'{1000 * TARGET_OVERRUN_S:.0f} ms: {verdict}\n')
    out.write(f'written: {out_dir / "runs.csv"}, {out_dir / "summary.json"}\n')
