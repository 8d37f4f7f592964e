"""
The best-known optimum of every case, by dense multistart local search.

For each (gesture, failed right-arm joint) case the problem is the one the engine
solves (the failed joint at the library average, the arm's other joints free within
their limits).  The search polishes the reference start (the gesture's own angles of
the free joints) and ``starts`` uniform random starts with the batched BFGS of
:func:`namo_fault_recovery.optimize.polish.polish` (analytic gradients of a slightly
smoothed score; exact values reported), then refines the best point of each case with
a long polish and a bounded Nelder-Mead on the exact, unsmoothed score.  Of equivalent
optima (the spherical wrist can flip), the one closest to the reference pose is kept.
The results are stored in ``config/best_known_optima.yaml`` and read by
:func:`load_best_known`.
"""

from dataclasses import dataclass, field
import math
from pathlib import Path

import numpy as np

from . import common
from ..optimize.base import Clock
from ..optimize.polish import polish
from ..resources import config_path, share_dir

BEST_KNOWN_FILE = 'best_known_optima.yaml'
_CHUNK = 512   # starts polished per batched call (bounds the memory)


@dataclass
class BestKnownOptima:
    """The stored optima: ``cases[(gesture, joint)]`` is a dict, ``meta`` the provenance."""

    cases: dict
    meta: dict = field(default_factory=dict)
    source: str = '<memory>'

    def score(self, gesture, joint):
        """Return the best-known score of a case, or raise KeyError naming the case."""
        try:
            return self.cases[(gesture, joint)]['score']
        except KeyError:
            raise KeyError(f'no best-known optimum for gesture {gesture!r} with '
                           f'{joint} failed in {self.source}') from None

    def __contains__(self, case):
        return case in self.cases

    def check_model(self, robot, library):
        """Return None if the optima fit this model, else a one-line warning."""
        stored = self.meta.get('model_fingerprint')
        now = common.model_fingerprint(robot, library)
        if stored != now:
            return (f'warning: {self.source} was computed for model fingerprint {stored}, '
                    f'the loaded model is {now}; rerun `namo-recovery bench optimum --write`')
        return None


def best_known_path():
    """Return where ``bench optimum --write`` stores the optima (the package config)."""
    return share_dir('config') / BEST_KNOWN_FILE


def load_best_known(path=None):
    """
    Load the stored best-known optima (``config/best_known_optima.yaml`` by default).

    Returns a :class:`BestKnownOptima`; raises FileNotFoundError if there is no file.
    """
    import yaml
    path = Path(path) if path is not None else config_path(BEST_KNOWN_FILE)
    with open(path) as fh:
        data = yaml.safe_load(fh)
    if not isinstance(data, dict) or not isinstance(data.get('cases'), dict):
        raise ValueError(f'{path}: expected a mapping with a "cases" key')
    cases = {}
    for gesture, per_joint in data['cases'].items():
        for joint, entry in per_joint.items():
            entry = dict(entry)
            entry['score'] = float(entry['score'])
            cases[(gesture, joint)] = entry
    meta = {k: v for k, v in data.items() if k != 'cases'}
    return BestKnownOptima(cases, meta, str(path))


def _polish_starts(problem, x_start, clock, maxiter):
    """Polish every start, ``_CHUNK`` at a time; return (x, f) of all of them."""
    xs, fs = [], []
    for lo in range(0, x_start.shape[1], _CHUNK):
        x, f = polish(problem, x_start[:, lo:lo + _CHUNK], clock, maxiter=maxiter,
                      ftol=1e-12)
        xs.append(x)
        fs.append(f)
    return np.concatenate(xs, axis=1), np.concatenate(fs, axis=1)


def _keyframe_entry(best_f, q_right, q_left, f_starts, polished_f):
    """Return one keyframe's optimum and how the starts (``f_starts``) reached it."""
    hits = float(np.mean(f_starts <= best_f + common.WITHIN * abs(best_f) + 1e-12))
    # Starts that reached the best basin floor (to the polish's 1e-4 accuracy).
    same = float(np.mean(f_starts <= polished_f + 1e-4 * abs(polished_f) + 1e-9))
    return {
        'score': float(best_f),
        'right_deg': [round(float(v), 6) for v in np.degrees(q_right)],
        'left_deg': [round(float(v), 6) for v in np.degrees(q_left)],
        'reference_start_score': float(f_starts[0]),
        'reference_start_in_best_basin': bool(
            f_starts[0] <= polished_f + 1e-4 * abs(polished_f) + 1e-9),
        'share_of_starts_within_0.5pct': round(hits, 4),
        'share_of_starts_in_best_basin': round(same, 4),
    }


def dense_optimum(robot, library, gesture, joint, starts=1000, seed=0, maxiter=300):
    """
    Return the best-known optimum of one case as a dict (see the module docstring).

    The random starts are drawn from ``numpy.random.default_rng([seed, k])`` where k
    numbers the case, so every case gets its own reproducible stream.
    """
    problem, locks = common.case_problems(robot, library, gesture, {joint: None})
    k_case = (list(library.names).index(gesture) * 100
              + common.joint_number(robot, joint))
    rng = np.random.default_rng([seed, k_case])
    clock = Clock(None)
    x_start = np.concatenate((problem.x0[:, None, :], problem.random(rng, starts)), axis=1)
    x_all, f_all = _polish_starts(problem, x_start, clock, maxiter)
    n_targets = problem.batch
    polished_f = f_all.min(axis=1)
    # Equivalent optima exist (e.g. the spherical wrist flipped): among the starts that
    # reached the best basin floor, keep the pose closest to the reference one.
    floor = f_all <= polished_f[:, None] + 1e-4 * np.abs(polished_f[:, None]) + 1e-9
    wrapped = (x_all - problem.x0[:, None, :] + np.pi) % (2 * np.pi) - np.pi
    distance = np.where(floor, np.linalg.norm(wrapped, axis=-1), np.inf)
    best_i = np.argmin(distance, axis=1)
    best_x = x_all[np.arange(n_targets), best_i].copy()
    best_f = f_all[np.arange(n_targets), best_i].copy()
    # Long polish of the winners, then Nelder-Mead on the exact (unsmoothed) score.
    x2, f2 = polish(problem, best_x[:, None, :], clock, maxiter=3000, ftol=0.0)
    gain = f2[:, 0] < best_f
    best_x[gain], best_f[gain] = x2[gain, 0], f2[gain, 0]
    refined = _nelder_mead(problem, best_x, best_f)
    keyframes = []
    q_right, q_left = problem.assemble(best_x)
    for t in range(n_targets):
        keyframes.append(_keyframe_entry(best_f[t], q_right[t], q_left[t], f_all[t],
                                         polished_f[t]))
    worst = max(range(n_targets), key=lambda t: keyframes[t]['score'])
    return {
        'score': keyframes[worst]['score'],
        'lock_deg': round(math.degrees(locks[joint]), 6),
        'free_joints': [robot.arms[s].joint_names[j] for s, j in problem.free],
        'right_deg': keyframes[worst]['right_deg'],
        'left_deg': keyframes[worst]['left_deg'],
        'starts': int(x_start.shape[1]),
        'nelder_mead_gain': float(refined),
        'keyframes': keyframes,
    }


def _nelder_mead(problem, best_x, best_f):
    """Refine each target's best point in place on the exact score; return the gain."""
    from scipy.optimize import minimize as sp_minimize
    total_gain = 0.0
    bounds = list(zip(problem.lower, problem.upper))
    for t in range(problem.batch):
        def f_t(x, t=t):
            pts = best_x[:, None, :].copy()
            pts[t, 0] = np.clip(x, problem.lower, problem.upper)
            return float(problem.evaluate(pts)[t, 0])
        res = sp_minimize(f_t, best_x[t], method='Nelder-Mead', bounds=bounds,
                          options={'xatol': 1e-10, 'fatol': 1e-12, 'maxiter': 20000,
                                   'maxfev': 40000, 'adaptive': True})
        if res.fun < best_f[t]:
            total_gain += best_f[t] - res.fun
            best_x[t] = np.clip(res.x, problem.lower, problem.upper)
            best_f[t] = res.fun
    return total_gain


def compute_optima(robot, library, cases, starts=1000, seed=0, maxiter=300, progress=True):
    """Return ``{(gesture, joint): entry}`` for the cases, by :func:`dense_optimum`."""
    prog = common.Progress(len(cases), 'optimum') if progress else None
    out = {}
    for gesture, joint in cases:
        out[(gesture, joint)] = dense_optimum(robot, library, gesture, joint, starts, seed,
                                              maxiter)
        if prog:
            prog.step(note=f'{gesture} {joint}: {out[(gesture, joint)]["score"]:.6f}')
    return out


def optima_document(robot, library, optima, starts, seed, maxiter):
    """Return the YAML document (a dict) for computed optima."""
    doc = {
        'version': 1,
        'description': 'Best-known optimum of every (gesture, failed right-arm joint) case '
                       'of the gesture-similarity score; lower is better.',
        'generated_by': f'namo-recovery bench optimum --starts {starts} --seed {seed} --write',
        'method': (f'dense multistart local search: the reference start (the gesture angles '
                   f'of the free joints) plus {starts} uniform random starts within the joint '
                   f'limits, each polished by the batched BFGS of optimize.polish (analytic '
                   f'gradients of the score smoothed by 0.01, exact values kept, maxiter '
                   f'{maxiter}, ftol 1e-12); the best point then polished for up to 3000 '
                   f'iterations and refined by bounded Nelder-Mead on the exact score; of '
                   f'equivalent optima (within 1e-4) the one closest to the reference pose'),
        'lock': 'library average (the paper lock strategy)',
        'angles': 'degrees; right_deg has the failed joint at its lock angle',
        'model_fingerprint': common.model_fingerprint(robot, library),
        'robot': Path(robot.source).name,
        'gestures': Path(library.source).name,
        'cases': {},
    }
    for (gesture, joint), entry in optima.items():
        doc['cases'].setdefault(gesture, {})[joint] = entry
    return doc


PAPER_OPTIMA_TITLE = ('Best-known optima of the 28 paper cases (generated data; do not edit '
                      'by hand).')


def write_optima(path, doc, title=PAPER_OPTIMA_TITLE):
    """Write an optima YAML under a header comment: ``title``, then how to regenerate it."""
    import yaml
    text = (f'# {title}\n'
            f'# Regenerate: {doc["generated_by"]}\n'
            + yaml.safe_dump(common.plain(doc), sort_keys=False, default_flow_style=None,
                             width=99))
    common.write_text(path, text)


def algorithm_gaps(robot, library, cases, best, keys, seeds, deadline=None, progress=True):
    """
    Run each algorithm on each case with ``seeds`` seeds; return rows of gaps.

    Each row: ``{'gesture', 'joint', 'algorithm', 'scores', 'gaps'}`` where the gaps
    are relative to the best-known optimum.
    """
    rows = []
    prog = common.Progress(len(cases) * len(keys), 'gaps') if progress else None
    for gesture, joint in cases:
        opt = best[(gesture, joint)]['score']
        for key in keys:
            spec = common.lookup_spec(key)
            scores = [common.run_gesture(spec, robot, library, gesture, joint, s,
                                         deadline)['score'] for s in range(seeds)]
            rows.append({'gesture': gesture, 'joint': joint, 'algorithm': key,
                         'optimum': opt, 'scores': scores,
                         'gaps': [common.relative_gap(s, opt) for s in scores]})
            if prog:
                prog.step()
    return rows


def _print_optima(out, robot, optima):
    """Print the table of the optima beside the paper ABC's best."""
    from .paper_data import TABLE6
    header = ['gesture', 'joint', 'lock deg', 'optimum', 'ref start', 'ref in best basin',
              'starts within 0.5%', 'paper ABC min']
    rows = []
    for (gesture, joint), e in optima.items():
        kf = e.get('keyframes', [{}])[0]
        jn = common.joint_number(robot, joint)
        paper = TABLE6.get((gesture, jn), {}).get('abc', {}).get('min')
        rows.append([gesture, jn, common.fmt(e['lock_deg'], 2), common.fmt(e['score']),
                     common.fmt(kf.get('reference_start_score', math.nan)),
                     {True: 'yes', False: 'no'}.get(kf.get('reference_start_in_best_basin'),
                                                    '-'),
                     common.fmt(100 * kf.get('share_of_starts_within_0.5pct', math.nan), 1)
                     + '%', common.fmt(paper)])
    out.write(common.text_table(header, rows))


def _print_gaps(out, robot, gaps, keys, seeds):
    """Print every algorithm's median gap per case, and the share of runs within 0.5%."""
    out.write(f'\ngap to the best-known optimum, % (median over seeds 0..{seeds - 1}; '
              f'per-gesture runs, no deadline)\n')
    by_case = {}
    for r in gaps:
        by_case.setdefault((r['gesture'], r['joint']), {})[r['algorithm']] = r
    header = ['gesture', 'joint'] + [common.lookup_spec(k).label for k in keys]
    rows = []
    for (gesture, joint), per in by_case.items():
        rows.append([gesture, common.joint_number(robot, joint)]
                    + [common.fmt(100 * float(np.median(per[k]['gaps'])), 2) for k in keys])
    out.write(common.text_table(header, rows))
    shares = []
    for k in keys:
        hits = [g <= common.WITHIN for r in gaps if r['algorithm'] == k for g in r['gaps']]
        shares.append(f'{common.lookup_spec(k).label} {100 * np.mean(hits):.1f}%')
    out.write('share of runs within 0.5%: ' + ', '.join(shares) + '\n')
    below = [r for r in gaps if min(r['gaps']) < -1e-6]
    for r in below:
        out.write(f'note: {r["algorithm"]} beat the stored optimum of {r["gesture"]} '
                  f'{r["joint"]} ({min(r["scores"]):.6f} < {r["optimum"]:.6f}); rerun '
                  f'with more starts\n')


@dataclass(frozen=True)
class Multistart:
    """The dense multistart local search: ``starts`` random starts, ``seed``, ``maxiter``."""

    starts: int = 1000
    seed: int = 0
    maxiter: int = 300


def run_optimum(robot, library, out, cases, search=Multistart(), write=None,
                keys=common.PAPER_LINEUP, seeds=3, use_stored=False, progress=True):
    """
    Compute (or, with ``use_stored``, load) the optima and print them with the gaps.

    ``search`` (:class:`Multistart`) finds the optima; ``write`` is a path to store the
    YAML (None: do not store).  Returns a dict with the
    optima and the gap rows.
    """
    info = common.machine_info()
    out.write(common.format_machine(info) + '\n')
    if use_stored:
        stored = load_best_known()
        warn = stored.check_model(robot, library)
        if warn:
            out.write(warn + '\n')
        optima = {c: stored.cases[c] for c in cases if c in stored}
        out.write(f'best-known optima loaded from {stored.source}\n')
    else:
        optima = compute_optima(robot, library, cases, search.starts, search.seed,
                                search.maxiter, progress)
        out.write(f'best-known optima by dense multistart local search: reference start + '
                  f'{search.starts} random starts per case (seed {search.seed})\n')
    _print_optima(out, robot, optima)
    if write is not None and not use_stored:
        doc = optima_document(robot, library, optima, search.starts, search.seed,
                              search.maxiter)
        write_optima(write, doc)
        out.write(f'written: {write}\n')
    gaps = []
    if seeds > 0 and keys:
        gaps = algorithm_gaps(robot, library, list(optima), optima, keys, seeds,
                              progress=progress)
        _print_gaps(out, robot, gaps, keys, seeds)
    return {'machine': info, 'optima': {f'{g}/{j}': e for (g, j), e in optima.items()},
            'gaps': gaps}
