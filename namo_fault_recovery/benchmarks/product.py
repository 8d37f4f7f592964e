"""
The served problem's benchmark, offline parts: best-known optima, deadline quality, table.

The served problem is the packaged library (``config/gestures.yaml``) under the node's
settings (:class:`~namo_fault_recovery.recovery.engine.RecoverySettings` defaults: 1 s
deadline, ``average`` locks, collision check, ...), every single joint fault.  Free of
ROS; ``namo-recovery bench product`` (:mod:`.product_node`) adds the parts that
need a real node over DDS (latency, refinement curve).

- :func:`generate_optima`: the best-known ``score_after`` per fault set and gesture, the
  minimum over many seeds of :func:`~..recovery.contingency.measure_entry` (no
  deadline), for the product library, the demo library (``config/demo_motions.yaml``)
  and the refinement part's fault sets; stored in ``config/product_best_known.yaml``;
- :func:`run_quality`: every single fault x seeds through :func:`recover` with the 1 s
  deadline and the cached typical points, as the node's engine child runs it, idle and
  with a CPU burner pinned to the other core; each gesture's gap to the best-known;
- :func:`run_table`: the table the node builds (``BUILD_SEEDS``, :func:`build_table`),
  each entry's gestures against the best-known.
"""

import contextlib
from datetime import datetime, timezone
import math
import multiprocessing
from pathlib import Path
import subprocess
import time

import numpy as np

from . import common
from .deadline import CpuBurner
from ..model.gestures import load_library
from ..model.kinematics import split_arms
from ..model.robot import load_robot
from ..objective.score import gesture_targets, SimilarityScore
from ..recovery.contingency import (build_table, entry_key, fault_sets, measure_entry,
                                    table_fingerprint, table_locks)
from ..recovery.engine import recover, RecoverySettings
from ..recovery.motion import typical_points
from ..resources import config_path, share_dir

PRODUCT_BEST_KNOWN_FILE = 'product_best_known.yaml'
LIBRARIES = {'product': 'gestures.yaml', 'demo': 'demo_motions.yaml'}
OPTIMA_SEEDS = 256           # seeds per fault set of the product library
DEMO_OPTIMA_SEEDS = 32       # of the demo library (the dense circle costs more)
QUALITY_WITHIN = 0.01        # part 2: every gesture within 1% ...
QUALITY_TARGET = 0.99        # ... in at least 99% of the runs
TABLE_WITHIN = 0.005         # part 3: every gesture of every entry within 0.5%
QUALITY_SEED_BASE = 1000     # quality seeds, away from the optima's 0..N-1
# Part 5: fault sets refined by the node (angles in deg; None = the lock strategy's).
REFINE_SETS = {
    'right2+right4': {'right_arm_joint2': None, 'right_arm_joint4': None},
    'right1+left3': {'right_arm_joint1': None, 'left_arm_joint3': None},
    'right2@-20deg': {'right_arm_joint2': -20.0},
}
ZERO = 1e-9                  # a best-known score this small counts as 0 (absolute gap)


def node_settings():
    """Return the node's default settings (``config/recovery_node.yaml``)."""
    return RecoverySettings()


def load_models(which='product'):
    """Return ``(robot, library)`` of the packaged robot and the ``which`` library."""
    robot = load_robot(None)
    return robot, load_library(robot, config_path(LIBRARIES[which]))


def refine_faults(name):
    """Return the fault set (joint -> rad or None) of a REFINE_SETS entry."""
    return {j: None if a is None else math.radians(a) for j, a in REFINE_SETS[name].items()}


def gap(score, best):
    """Return the relative gap of ``score`` to ``best`` (absolute when best is ~0)."""
    if abs(best) <= ZERO:
        return 0.0 if score <= ZERO else float(score)
    return (score - best) / abs(best)


def published_scores(robot, lib, joint_names, gestures, settings=None):
    """
    Return ``{gesture: score_after}`` recomputed from published positions.

    ``gestures`` are :class:`GestureResult` s whose ``positions`` columns are
    ``joint_names`` (as a client rebuilds them from ``/gesture_library``); the score is
    the engine's (the worst keyframe of :class:`SimilarityScore` with the settings'
    weights), so that a version whose ``/diagnostics`` never arrived is scored too.
    """
    settings = settings or node_settings()
    order = [list(joint_names).index(j) for j in robot.joint_names]
    out = {}
    for g in gestures:
        q = np.asarray(g.positions, dtype=float)[:, order]
        scorer = SimilarityScore(robot, gesture_targets(lib[g.name]), settings.weights,
                                 reference_robot=robot)
        total = scorer.evaluate(*split_arms(robot, q), np.arange(len(q)))
        out[g.name] = float(np.max(total))
    return out


def worst_gap(scores, best):
    """Return the largest gap over gestures: ``scores`` and ``best`` map name -> score."""
    return max(gap(scores[g], best[g]) for g in best)


# --- part 1: best-known optima -------------------------------------------------------

def best_known_path():
    """Return where the product optima are stored (the package config)."""
    return share_dir('config') / PRODUCT_BEST_KNOWN_FILE


def load_product_best_known(path=None):
    """Load the product optima YAML; raise FileNotFoundError if there is none."""
    import yaml
    path = Path(path) if path else best_known_path()
    with open(path) as fh:
        doc = yaml.safe_load(fh)
    if not isinstance(doc, dict) or 'libraries' not in doc:
        raise ValueError(f'{path}: expected a mapping with a "libraries" key')
    doc['source'] = str(path)
    return doc


def best_of(doc, library, key):
    """Return ``{gesture: best score}`` of one fault set, or None if not stored."""
    entry = doc['libraries'].get(library, {}).get('fault_sets', {}).get(key)
    return None if entry is None else {g: float(s) for g, s in entry['best'].items()}


def fingerprint_warning(doc, library, robot, lib, settings):
    """Return a line if the stored optima were made for another model, else ''."""
    stored = doc['libraries'].get(library, {}).get('fingerprint')
    now = table_fingerprint(robot, lib, settings)
    if stored != now:
        return (f'warning: {PRODUCT_BEST_KNOWN_FILE} [{library}] was made for fingerprint '
                f'{str(stored)[:12]}, not {now[:12]} (the model, library or settings '
                f'changed): regenerate it with --update-optima')
    return ''


_WORKER = {}


def _init_worker(settings):
    robot = load_robot(None)
    _WORKER['settings'] = settings
    for which, name in LIBRARIES.items():
        lib = load_library(robot, config_path(name))
        _WORKER[which] = (robot, lib, typical_points(robot, lib, settings.vq_distortion_mm))


def playable(robot, gesture):
    """
    Return True if a GestureResult's keyframes respect the joints' velocity limits.

    Between successive keyframes no joint may need more than its limit
    (``robot.joint_velocity_limits``); the approach to the first keyframe is
    the player's to plan.  A gesture that breaks it is not played as designed (the
    player stretches it), so it cannot be a best-known optimum.
    """
    limits = np.asarray(robot.joint_velocity_limits, dtype=float)
    q = np.asarray(gesture.positions, dtype=float)
    t = np.asarray(gesture.times, dtype=float)
    if len(t) < 2:
        return True
    speed = np.abs(np.diff(q, axis=0)) / np.maximum(np.diff(t), 1e-9)[:, None]
    return bool(np.all(speed <= limits * (1 + 1e-9)))


def _optimum_task(task):
    which, key, faults, seed = task
    robot, lib, quant = _WORKER[which]
    built = measure_entry(robot, lib, faults, _WORKER['settings'], seeds=(seed,),
                          quantisations=quant)
    return which, key, seed, {g.name: (g.score_after, playable(robot, g))
                              for g in built.result.gestures}


def optima_plan(settings, seeds=OPTIMA_SEEDS, demo_seeds=DEMO_OPTIMA_SEEDS, joints=None,
                libraries=tuple(LIBRARIES)):
    """Return ``{library: {key: faults}}``: the fault sets the optima are computed for."""
    plan = {}
    for which in libraries:
        robot, lib = load_models(which)
        sets = fault_sets(robot, lib, settings, joints=joints)
        if which == 'product':
            sets += [table_locks(robot, lib, refine_faults(n), settings) for n in REFINE_SETS]
        plan[which] = {entry_key(table_locks(robot, lib, f, settings)): f for f in sets}
    return plan


def _best_of_runs(runs, names):
    """
    Return one fault set's stored optimum from its ``(seed, scores)`` runs.

    Per gesture the lowest score_after over the seeds whose keyframes are playable
    (all seeds if none is), the seed that gave it and the unplayable seeds.
    """
    best, best_seed, unplayable = {}, {}, {}
    for g in names:
        ok = [(sc[g][0], seed) for seed, sc in runs if sc[g][1]] or \
            [(sc[g][0], seed) for seed, sc in runs]
        best[g], best_seed[g] = min(ok)
        unplayable[g] = sum(1 for _, sc in runs if not sc[g][1])
    scores = [{g: v[0] for g, v in sc.items()} for _, sc in runs]
    return {'best': {g: float(v) for g, v in best.items()},
            'best_seed': {g: int(v) for g, v in best_seed.items()},
            'unplayable_seeds': {g: n for g, n in unplayable.items() if n},
            'seeds_within_1pct': round(float(np.mean(
                [worst_gap(sc, best) <= QUALITY_WITHIN for sc in scores])), 4)}


def generate_optima(out, seeds=OPTIMA_SEEDS, demo_seeds=DEMO_OPTIMA_SEEDS, jobs=2,
                    joints=None, settings=None, progress=True, libraries=tuple(LIBRARIES)):
    """
    Compute the best-known optima (min over seeds per gesture); return the YAML doc.

    Each (fault set, seed) is one :func:`measure_entry` run without a deadline;
    ``jobs`` spawned workers share them.  ``libraries`` (keys of :data:`LIBRARIES`)
    are computed; :func:`merge_optima` keeps the others of a stored document.
    """
    settings = settings or node_settings()
    unknown = [w for w in libraries if w not in LIBRARIES]
    if unknown:
        raise KeyError(f'unknown library {unknown[0]!r}; expected one of '
                       f'{", ".join(LIBRARIES)}')
    plan = optima_plan(settings, seeds, demo_seeds, joints, libraries)
    tasks = [(which, key, faults, s) for which, sets in plan.items()
             for key, faults in sets.items()
             for s in range(seeds if which == 'product' else demo_seeds)]
    began = time.monotonic()
    prog = common.Progress(len(tasks), 'optima') if progress else None
    found = {}
    ctx = multiprocessing.get_context('spawn')
    with ctx.Pool(max(1, int(jobs)), initializer=_init_worker, initargs=(settings,)) as pool:
        for which, key, seed, scores in pool.imap_unordered(_optimum_task, tasks, chunksize=4):
            found.setdefault((which, key), []).append((seed, scores))
            if prog:
                prog.step()
    wall = time.monotonic() - began
    doc = {
        'version': 1,
        'description': ('Best-known score_after (worst keyframe, lower is better) of each '
                        'gesture of the served problem: the packaged library under the '
                        'node settings, every single joint fault (lock: the strategy of the '
                        'settings, average), plus the refinement fault sets of bench '
                        'product.'),
        'generated_by': f'namo-recovery bench product --update-optima --optima-seeds {seeds} '
                        f'--demo-optima-seeds {demo_seeds} --jobs {jobs}'
                        + ('' if set(libraries) == set(LIBRARIES) else
                           f' --optima-libraries {",".join(libraries)}'),
        'method': 'per fault set, recover() without a deadline (measure_entry, one seed '
                  'each, seeds 0..N-1, the node settings and preset); per gesture the '
                  'lowest score_after over the seeds whose keyframes respect the joint '
                  'velocity limits (a wave that flips the wrist faster than the joint '
                  'can move is not an optimum a robot can play)',
        'made': {'date': datetime.now(timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ'),
                 'commit': git_commit(), 'wall_sec': round(wall, 1), 'jobs': int(jobs),
                 'machine': common.machine_info()},
        'settings': common.plain(settings.public()),
        'libraries': {},
    }
    for which, sets in plan.items():
        robot, lib = load_models(which)
        n = seeds if which == 'product' else demo_seeds
        entry = {'file': LIBRARIES[which], 'seeds': n,
                 'fingerprint': table_fingerprint(robot, lib, settings), 'fault_sets': {}}
        for key in sets:
            entry['fault_sets'][key] = _best_of_runs(sorted(found[(which, key)]), lib.names)
        doc['libraries'][which] = entry
    out.write(f'optima: {len(tasks)} runs in {wall:.0f} s ({jobs} jobs)\n')
    return doc


def merge_optima(new, old):
    """
    Return ``new`` with the libraries it did not compute taken from ``old`` (or None).

    Each library entry keeps its own ``made`` (date, commit, seeds), so a document
    regenerated for one library still says when and how the others were made.  A
    library computed again for the same model and settings (its ``fingerprint``) keeps
    every best the old entry knew lower (:func:`keep_lower_bests`).
    """
    for which, entry in new['libraries'].items():
        entry.setdefault('made', new['made'])
    if old is None:
        return new
    for which, entry in old.get('libraries', {}).items():
        if which not in new['libraries']:
            entry.setdefault('made', old.get('made', {}))
            new['libraries'][which] = entry
        else:
            keep_lower_bests(new['libraries'][which], entry)
    new['libraries'] = {w: new['libraries'][w] for w in LIBRARIES if w in new['libraries']}
    return new


def keep_lower_bests(entry, before):
    """
    Keep in a library ``entry`` each gesture best that ``before`` (same fingerprint) had lower.

    A best-known optimum is the lowest score ever found for that model: a search change
    that stops finding a basin must not raise the bar it is measured against (the robots'
    optima do the same, :func:`~.robots.keep_lower`).  A kept best keeps its seed, listed
    under ``kept_from_earlier`` (that seed was an earlier code's); ``seeds_within_1pct``
    stays this run's own share.  Fault sets this run did not solve are carried over.
    """
    if before.get('fingerprint') != entry.get('fingerprint'):
        return
    for key, old_set in before.get('fault_sets', {}).items():
        new_set = entry['fault_sets'].setdefault(key, old_set)
        if new_set is old_set:
            continue
        kept = common.keep_lower_scores(new_set['best'], old_set.get('best', {}))
        for name in kept:
            new_set['best_seed'][name] = old_set.get('best_seed', {}).get(name)
        if kept:
            new_set['kept_from_earlier'] = kept


def git_commit():
    """Return the package's git commit (with ``-dirty``), or 'unknown'."""
    root = Path(__file__).resolve().parent.parent.parent
    try:
        head = subprocess.run(['git', 'rev-parse', '--short=12', 'HEAD'], cwd=root,
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(['git', 'status', '--porcelain', '--untracked-files=no'],
                               cwd=root, capture_output=True, text=True,
                               timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return 'unknown'
    return (head + ('-dirty' if dirty else '')) if head else 'unknown'


def write_product_optima(path, doc):
    """Write the served problem's optima YAML with its header comment."""
    from .optimum import write_optima
    write_optima(path, doc, 'Best-known optima of the served problem (generated data; do not '
                            'edit).')


# --- parts 2 and 6: quality at the deadline ----------------------------------------

def _quality_runs(robot, lib, settings, quant, best_doc, which, faults_of, cond, seeds,
                  prog):
    """Run every fault set once per seed of ``seeds`` under one condition; return the runs."""
    runs = []
    for key, faults in faults_of.items():
        best = best_of(best_doc, which, key)
        if best is None:
            raise KeyError(f'{PRODUCT_BEST_KNOWN_FILE}: no optimum stored for '
                           f'[{which}] {key}; regenerate with --update-optima')
        for seed in seeds:
            t0 = time.monotonic()
            res = recover(robot, lib, faults, settings, seed=seed, quantisations=quant)
            wall = time.monotonic() - t0
            scores = {g.name: g.score_after for g in res.gestures}
            gaps = {g: gap(scores[g], best[g]) for g in best}
            runs.append({'condition': cond, 'fault': key, 'seed': seed,
                         'wall_s': wall, 'deadline_met': res.deadline_met,
                         'scores': scores, 'gaps': gaps,
                         'worst_gap': max(gaps.values())})
            if prog:
                prog.step(note=cond)
    return runs


def _quality_condition(rs, names):
    """Return the summary of one condition's runs ``rs`` (gestures ``names``)."""
    share = float(np.mean([r['worst_gap'] <= QUALITY_WITHIN for r in rs]))
    per_gesture = {g: {'median_pct': 100 * common.percentile(
                       [r['gaps'][g] for r in rs], 50),
                       'p95_pct': 100 * common.percentile([r['gaps'][g] for r in rs], 95),
                       'max_pct': 100 * max(r['gaps'][g] for r in rs),
                       'share_within': float(np.mean([r['gaps'][g] <= QUALITY_WITHIN
                                                      for r in rs]))}
                   for g in names}
    lowest = [min(r['gaps'].values()) for r in rs]      # each run's lowest gap
    misses = {}
    for r in rs:
        if r['worst_gap'] > QUALITY_WITHIN:
            misses[r['fault']] = misses.get(r['fault'], 0) + 1
    return {'runs': len(rs), 'share_all_within': share, 'met': share >= QUALITY_TARGET,
            'deadline_met_share': float(np.mean([r['deadline_met'] for r in rs])),
            'wall_p95_ms': 1000 * common.percentile([r['wall_s'] for r in rs], 95),
            'wall_max_ms': 1000 * max(r['wall_s'] for r in rs),
            'below_best_known': sum(low < -1e-6 for low in lowest),
            'below_best_known_max_pct': -100 * min(0.0, *lowest),
            'per_gesture': per_gesture, 'misses_by_fault': misses}


def run_quality(out, best_doc, which='product', seeds=10, burner=True, joints=None,
                seed_base=QUALITY_SEED_BASE, deadline=None, progress=True):
    """
    Run every single fault x ``seeds`` at the node's deadline; return the summary dict.

    Conditions: ``idle`` and, with ``burner``, ``cpu burner`` (a busy process pinned to
    the other core).  ``deadline`` (s) overrides the node's 1 s.
    """
    settings = node_settings()
    if deadline is not None:
        settings = settings.with_changes(deadline_sec=float(deadline))
    robot, lib = load_models(which)
    warn = fingerprint_warning(best_doc, which, robot, lib, node_settings())
    if warn:
        out.write(warn + '\n')
    quant = typical_points(robot, lib, settings.vq_distortion_mm)
    sets = fault_sets(robot, lib, node_settings(), joints=joints)
    faults_of = {entry_key(f): dict.fromkeys(f) for f in sets}
    recover(robot, lib, next(iter(faults_of.values())), settings, seed=0,
            quantisations=quant)                        # warm-up, as the engine child
    conditions = ['idle'] + (['cpu burner'] if burner else [])
    prog = (common.Progress(len(conditions) * len(sets) * seeds, f'quality {which}')
            if progress else None)
    runs = []
    burner_cpu = None
    for cond in conditions:
        with (CpuBurner() if cond == 'cpu burner' else contextlib.nullcontext()) as ctx:
            if ctx is not None:
                burner_cpu = ctx.cpu
            runs += _quality_runs(robot, lib, settings, quant, best_doc, which, faults_of,
                                  cond, range(seed_base, seed_base + seeds), prog)
    summary = {'library': which, 'file': LIBRARIES[which], 'seeds': seeds,
               'seed_base': seed_base, 'deadline_sec': settings.deadline_sec,
               'burner_cpu': burner_cpu, 'target_within': QUALITY_WITHIN,
               'target_share': QUALITY_TARGET, 'conditions': {}, 'runs': runs}
    for cond in conditions:
        summary['conditions'][cond] = _quality_condition(
            [r for r in runs if r['condition'] == cond], lib.names)
    print_quality(out, summary)
    return summary


def print_quality(out, s):
    """Print the quality table of :func:`run_quality`'s summary."""
    out.write(f"\n== quality at the deadline [{s['library']}: {s['file']}] "
              f"({s['seeds']} seeds per single fault, deadline {s['deadline_sec']:g} s; "
              f'gap to best-known, %) ==\n')
    names = list(next(iter(s['conditions'].values()))['per_gesture'])
    rows = []
    for cond, c in s['conditions'].items():
        rows.append([cond, c['runs']]
                    + [f"{common.fmt(p['median_pct'], 2)}/{common.fmt(p['max_pct'], 2)}"
                       for p in (c['per_gesture'][g] for g in names)]
                    + [f"{100 * c['share_all_within']:.1f}%",
                       f"{100 * s['target_share']:.0f}%", 'met' if c['met'] else 'MISSED',
                       common.fmt(c['wall_p95_ms'], 1), f"{100 * c['deadline_met_share']:.0f}%"])
    out.write(common.text_table(
        ['condition', 'runs'] + [f'{g} med/max' for g in names]
        + ['all within 1%', 'target', 'verdict', 'wall p95 ms', 'deadline met'], rows))
    for cond, c in s['conditions'].items():
        if c['misses_by_fault']:
            worst = ', '.join(f'{k.split("=")[0]}: {n}' for k, n in
                              sorted(c['misses_by_fault'].items(), key=lambda kv: -kv[1]))
            out.write(f'  {cond}: runs with a gesture beyond 1%, by fault: {worst}\n')
        if c['below_best_known']:
            out.write(f"  {cond}: {c['below_best_known']} run(s) beat the best-known, by at "
                      f"most {c['below_best_known_max_pct']:.4f} % (regenerate with more "
                      f'seeds)\n')


# --- part 3: the table ---------------------------------------------------------------

def run_table(out, best_doc, jobs=2, joints=None, seeds=None):
    """Build the table as the node does and check every entry; return the summary."""
    from ..runtime.contingency_keeper import BUILD_SEEDS
    seeds = tuple(BUILD_SEEDS if seeds is None else seeds)
    settings = node_settings()
    robot, lib = load_models('product')
    sets = fault_sets(robot, lib, settings, joints=joints)
    t0 = time.monotonic()
    table = build_table(robot, lib, settings, sets, jobs=jobs, seeds=seeds)
    wall = time.monotonic() - t0
    entries = []
    for key, (_, result) in sorted(table.entries.items()):
        best = best_of(best_doc, 'product', key)
        scores = {g.name: g.score_after for g in result.gestures}
        gaps = {g: gap(scores[g], best[g]) for g in best}
        entries.append({'fault': key, 'seed': result.seed, 'scores': scores, 'gaps': gaps,
                        'worst_gap': max(gaps.values())})
    share = float(np.mean([e['worst_gap'] <= TABLE_WITHIN for e in entries]))
    summary = {'seeds': list(seeds), 'build_wall_sec': wall, 'jobs': jobs,
               'entries': entries, 'share_within': share, 'target_within': TABLE_WITHIN,
               'met': share >= 1.0}
    out.write(f'\n== contingency table (node builder: seeds {list(seeds)}, build_table, '
              f'{wall:.1f} s on {jobs} jobs; gap to best-known, %) ==\n')
    names = list(lib.names)
    rows = [[e['fault'].split('=')[0], e['seed']]
            + [common.fmt(100 * e['gaps'][g], 2) for g in names]
            + ['yes' if e['worst_gap'] <= TABLE_WITHIN else 'NO'] for e in entries]
    out.write(common.text_table(['fault', 'seed'] + names + ['within 0.5%'], rows))
    out.write(f'entries with every gesture within 0.5%: {100 * share:.1f}% (target 100%): '
              f"{'met' if summary['met'] else 'MISSED'}\n")
    return summary
