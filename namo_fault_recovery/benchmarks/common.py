"""
Shared pieces of the benchmarks: the cases, the algorithm line-up, statistics and files.

A *case* is one gesture with one failed right-arm joint locked at the library average
(the paper's 4 gestures x 7 joints = 28 cases).  An *algorithm key* names an optimiser,
its preset and any setting overrides, e.g. ``abc-paper`` or ``gd-paper-lr0.05``.
"""

from dataclasses import dataclass
import json
import math
import os
from pathlib import Path
import sys
import tempfile
import time
from typing import Optional

import numpy as np

from ..errors import ReportedError
from ..model.gestures import GestureLibrary, load_library
from ..model.kinematics import arm_joint_count
from ..model.robot import ARMS, load_robot
from ..objective.score import gesture_targets, SimilarityScore
from ..optimize.base import Clock
from ..recovery.engine import recover, RecoverySettings
from ..recovery.keyframes import finish_search, PoseProblem
from ..recovery.locks import resolve_locks
from ..resources import config_path, PAPER_GESTURE_FILE

DEFAULT_OUT_ROOT = 'bench_out'
WITHIN = 0.005   # "within 0.5% of the best-known optimum"
# The paper's problem: the faulted arm alone, no collision term (the gesture file is the
# paper's Table 2, see :func:`models`).  Everything else is the node's default.
PAPER_SETTINGS = RecoverySettings(collision_check=False, bimanual='off')


class BenchError(ReportedError):
    """A benchmark could not run, explained on one line; ``code`` is the exit code."""


@dataclass(frozen=True)
class AlgorithmSpec:
    """One entry of the line-up: optimiser name, preset, setting overrides and a label."""

    key: str
    algorithm: str
    preset: str
    settings: tuple = ()
    label: str = ''

    def settings_dict(self):
        """Return the setting overrides as a dict."""
        return dict(self.settings)


ALGORITHM_SPECS = {
    spec.key: spec for spec in (
        AlgorithmSpec('ga-paper', 'ga', 'paper', (), 'GA (paper)'),
        AlgorithmSpec('bfoa-paper', 'bfoa', 'paper', (), 'BFOA (paper)'),
        AlgorithmSpec('abc-paper', 'abc', 'paper', (), 'ABC (paper)'),
        AlgorithmSpec('abc-default', 'abc', 'default', (), 'ABC (ours)'),
        AlgorithmSpec('gd-paper-lr0.1', 'gd', 'paper', (('learning_rate', 0.1),),
                      'GD lr 0.1'),
        AlgorithmSpec('gd-paper-lr0.05', 'gd', 'paper', (('learning_rate', 0.05),),
                      'GD lr 0.05'),
    )
}
PAPER_LINEUP = ('ga-paper', 'bfoa-paper', 'abc-paper', 'abc-default')
PAPER_THREE = ('ga-paper', 'bfoa-paper', 'abc-paper')

_MODELS = {}


@dataclass(frozen=True)
class ModelFiles:
    """A benchmark's robot model and gesture library files (None: the packaged ones)."""

    robot_file: Optional[str] = None
    gesture_file: Optional[str] = None

    @classmethod
    def from_args(cls, args):
        """Return a command's ``--robot-file`` and ``--gesture-file``."""
        return cls(getattr(args, 'robot_file', None), getattr(args, 'gesture_file', None))

    def load(self):
        """Return ``(robot, library)`` (see :func:`models`)."""
        return models(self.robot_file, self.gesture_file)


def models(robot_file=None, gesture_file=None):
    """Return ``(robot, library)``, loaded once per process and file pair."""
    key = (None if robot_file is None else str(robot_file),
           None if gesture_file is None else str(gesture_file))
    if key not in _MODELS:
        robot = load_robot(robot_file)
        # The paper benchmarks run on the paper's Table 2 poses unless told otherwise.
        path = gesture_file if gesture_file is not None else config_path(PAPER_GESTURE_FILE)
        _MODELS[key] = (robot, load_library(robot, path))
    return _MODELS[key]


def right_arm_joints(robot):
    """Return the right arm's joint names (the failed joints of the paper's cases)."""
    return robot.arms['right'].joint_names


def select_cases(robot, library, gestures=None, joints=None):
    """
    Return the list of ``(gesture, joint)`` cases, in library then joint order.

    ``joints`` may hold joint names or 1-based right-arm joint numbers (as strings or
    ints); unknown names raise a ValueError naming the choices.
    """
    names = list(library.names) if not gestures else list(gestures)
    for g in names:
        library[g]   # raises KeyError naming the choices
    all_joints = right_arm_joints(robot)
    chosen = []
    for j in (joints or all_joints):
        if isinstance(j, (int, np.integer)) or (isinstance(j, str) and j.isdigit()):
            k = int(j)
            if not 1 <= k <= len(all_joints):
                raise ValueError(f'joint number {k}: expected 1..{len(all_joints)}')
            j = all_joints[k - 1]
        robot.locate_joint(j)   # raises KeyError naming the choices
        chosen.append(j)
    return [(g, j) for g in names for j in chosen]


def joint_number(robot, joint):
    """Return the 1-based index of a joint in its arm (``right_arm_joint2`` -> 2)."""
    return robot.locate_joint(joint)[1] + 1


def lookup_spec(key):
    """Return the AlgorithmSpec of a key, or raise a ValueError naming the choices."""
    try:
        return ALGORITHM_SPECS[key]
    except KeyError:
        raise ValueError(f'unknown algorithm key {key!r}; expected one of '
                         f'{", ".join(ALGORITHM_SPECS)}') from None


def recover_subset(robot, library, faults, settings, gestures=None, *, seed=None,
                   clock=None, overrides=None):
    """
    Return ``(LibraryResult, lock notes)`` of :func:`recover` on some of ``library``.

    ``gestures`` names a subset (None: the whole library): the library is cut down to
    it, with the lock angles the whole library would get (the ``average`` is over the
    whole library); the notes are those of resolving them.
    """
    notes = []
    if gestures is not None:
        if settings.lock_strategy != 'optimal':
            faults, notes = resolve_locks(robot, library, faults, settings.lock_strategy)
        library = GestureLibrary(tuple(library[g] for g in dict.fromkeys(gestures)),
                                 library.source)
    result = recover(robot, library, faults, settings, seed=seed, clock=clock,
                     optimizer_overrides=overrides)
    return result, notes


def run_recover(robot, library, faults, settings=PAPER_SETTINGS, *, seed, deadline=None,
                gestures=None, overrides=None):
    """
    Recover ``library`` with :func:`~namo_fault_recovery.recovery.engine.recover`.

    This is how every benchmark asks for a library: ``settings`` (the paper's problem
    unless told otherwise), ``deadline`` in s (None: no deadline; else it also becomes
    ``settings.deadline_sec``), ``overrides`` of the optimiser's preset.  ``gestures``
    names a subset (see :func:`recover_subset`).  Returns the
    :class:`~namo_fault_recovery.recovery.result.LibraryResult`.
    """
    if deadline is not None:
        settings = settings.with_changes(deadline_sec=float(deadline))
    return recover_subset(robot, library, faults, settings, gestures, seed=int(seed),
                          clock=Clock(None if deadline is None else float(deadline)),
                          overrides=overrides)[0]


def spec_settings(spec, settings=PAPER_SETTINGS):
    """Return ``settings`` with the optimiser and preset of an :class:`AlgorithmSpec`."""
    return settings.with_changes(optimizer=spec.algorithm, optimizer_preset=spec.preset)


def case_problems(robot, library, gesture, faults, weights=None):
    """
    Build the bounded problem(s) of one gesture under a fault set.

    Returns ``(problem, locks)`` where ``problem`` is the :class:`PoseProblem` over the
    gesture's keyframes (targets) with the faulted arms' remaining joints free, built as
    the engine's keyframe stage builds it.
    """
    locks, _ = resolve_locks(robot, library, faults)
    targets = gesture_targets(library[gesture])
    scorer = SimilarityScore(robot, targets, weights)
    base = {side: np.array([getattr(t, f'q_{side}') for t in targets]) for side in ARMS}
    locked = {side: [] for side in ARMS}
    for joint, angle in locks.items():
        side, j = robot.locate_joint(joint)
        base[side][:, j] = angle
        locked[side].append(j)
    moving = [s for s in ARMS if s in targets[0].arms and locked[s]]
    free = tuple((s, j) for s in moving for j in range(arm_joint_count(robot, s))
                 if j not in locked[s])
    problem = PoseProblem(robot, scorer, np.arange(len(targets)),
                          (base['right'], base['left']), free)
    return problem, locks


def describe(values):
    """Return min, max, mean, SD (n - 1), median and IQR of ``values`` as a dict."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {k: math.nan for k in ('n', 'min', 'max', 'mean', 'sd', 'median', 'iqr')}
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return {'n': int(v.size), 'min': float(v.min()), 'max': float(v.max()),
            'mean': float(v.mean()), 'sd': float(v.std(ddof=1)) if v.size > 1 else 0.0,
            'median': float(med), 'iqr': float(q3 - q1)}


def percentile(values, q):
    """Return the q-th percentile of the finite values (nan if none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.percentile(v, q)) if v.size else math.nan


def kruskal(groups):
    """
    Return ``(H, p, df)`` of the Kruskal-Wallis test over the groups (scipy.stats).

    Groups with no finite value are left out; with fewer than two groups left, or when
    every value is identical, H and p are nan.
    """
    from scipy import stats
    groups = [np.asarray(g, dtype=float) for g in groups]
    groups = [g[np.isfinite(g)] for g in groups]
    groups = [g for g in groups if g.size]
    if len(groups) < 2:
        return math.nan, math.nan, len(groups) - 1
    try:
        h, p = stats.kruskal(*groups)
    except ValueError:
        return math.nan, math.nan, len(groups) - 1
    return float(h), float(p), len(groups) - 1


def relative_gap(score, best):
    """Return ``(score - best) / best`` (0 when best is 0 and score is too)."""
    if best == 0:
        return 0.0 if score == 0 else math.inf
    return (score - best) / abs(best)


def keep_lower_scores(scores, before):
    """
    Lower each score of ``scores`` ({gesture: value}) to ``before``'s where that is lower.

    Return the names lowered, in ``before``'s order.  Best-known optima are the lowest
    scores ever found for a model, so a remade file keeps what an earlier one knew lower
    (``bench robots`` and ``bench product`` alike).
    """
    kept = [name for name, value in before.items()
            if name in scores and float(value) < scores[name]]
    for name in kept:
        scores[name] = float(before[name])
    return kept


def within(score, best, tol=WITHIN):
    """Return True if ``score`` is within ``tol`` (relative) of the optimum ``best``."""
    return score <= best + tol * abs(best) + 1e-12


def write_json(path, doc):
    """Write JSON atomically (temp file + rename), so a crash leaves no half file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix='.tmp', dir=path.parent)
    with os.fdopen(fd, 'w') as fh:
        json.dump(plain(doc), fh, indent=1, allow_nan=True)
        fh.write('\n')
    _publish(tmp, path)


def _publish(tmp, path):
    """Give a temp file the usual permissions (mkstemp makes it 0600) and move it."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(tmp, 0o666 & ~mask)
    os.replace(tmp, path)


def write_text(path, text):
    """Write a text file atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix='.tmp', dir=path.parent)
    with os.fdopen(fd, 'w') as fh:
        fh.write(text)
    _publish(tmp, path)


def write_csv(path, header, rows):
    """Write a CSV file (atomically) from a header and rows of plain values."""
    import csv
    import io
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator='\n')
    writer.writerow(header)
    for row in rows:
        writer.writerow([_csv_cell(v) for v in row])
    write_text(path, buf.getvalue())


def _csv_cell(v):
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    return v


def plain(obj):
    """Convert numpy scalars and arrays (recursively) to plain Python for JSON/YAML."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist())
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def machine_info():
    """Return the CPU count and load averages, to print beside any timing."""
    try:
        load = os.getloadavg()
    except OSError:
        load = (math.nan,) * 3
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:
        cpus = os.cpu_count()
    return {'cpus': cpus, 'loadavg': [round(x, 2) for x in load],
            'python': sys.version.split()[0], 'numpy': np.__version__,
            'time': time.strftime('%Y-%m-%d %H:%M:%S')}


def format_machine(info, label='machine'):
    """One line describing the machine and its load."""
    la = info['loadavg']
    return (f'{label}: {info["cpus"]} CPUs, load average {la[0]:.2f} / {la[1]:.2f} / '
            f'{la[2]:.2f} (1/5/15 min), Python {info["python"]}, numpy {info["numpy"]}, '
            f'{info["time"]}')


def markdown_table(header, rows, align=None):
    """Return a GitHub markdown table (right-aligned numbers unless told otherwise)."""
    align = align or ['l'] + ['r'] * (len(header) - 1)
    sep = ['---:' if a == 'r' else ':---' for a in align]
    lines = ['| ' + ' | '.join(str(h) for h in header) + ' |', '| ' + ' | '.join(sep) + ' |']
    for row in rows:
        lines.append('| ' + ' | '.join(str(c) for c in row) + ' |')
    return '\n'.join(lines) + '\n'


def text_table(header, rows):
    """Return a plain fixed-width table for the terminal."""
    cells = [[str(h) for h in header]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = []
    for n, row in enumerate(cells):
        lines.append('  '.join(c.ljust(w) if i == 0 else c.rjust(w)
                               for i, (c, w) in enumerate(zip(row, widths))).rstrip())
        if n == 0:
            lines.append('  '.join('-' * w for w in widths))
    return '\n'.join(lines) + '\n'


def fmt(x, prec=4):
    """Format a number for a table: fixed precision, nan as '-'."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return '-'
    return f'{x:.{prec}f}'


def fmt_p(p):
    """Format a p-value the way the paper does (p = 0.000 below 0.0005)."""
    if p is None or not math.isfinite(p):
        return '-'
    return f'{p:.3f}' if p >= 0.0005 else f'{p:.1e}'


class Progress:
    """Throttled progress lines on stderr (stdout carries only the figures)."""

    def __init__(self, total, label, stream=None, every=2.0):
        self.total = total
        self.done = 0
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.every = every
        self.start = time.monotonic()
        self.last = -math.inf

    def step(self, n=1, note=''):
        """Count ``n`` finished units and print a line at most every ``every`` s."""
        self.done += n
        now = time.monotonic()
        if now - self.last >= self.every or self.done >= self.total:
            self.last = now
            elapsed = now - self.start
            eta = elapsed / self.done * (self.total - self.done) if self.done else math.nan
            self.stream.write(f'[{self.label}] {self.done}/{self.total} '
                              f'({elapsed:.0f} s, ~{eta:.0f} s left) {note}\n')
            self.stream.flush()


def model_fingerprint(robot, library, weights=None):
    """
    Return a short hash of everything the optimum of a case depends on.

    That is the DH table, the joint limits, the gesture angles and arms, and the score
    weights; stored optima are only valid for the model they were computed on.
    """
    import hashlib
    from ..objective.score import ScoreWeights
    weights = weights if weights is not None else ScoreWeights()
    h = hashlib.sha256()
    profile_robot = getattr(robot, 'chains', None) is not None
    if profile_robot:                   # a robot from a URDF profile: its compiled chains
        h.update(robot.geometry_key())
    else:
        for arr in (robot.theta_offset, robot.d, robot.a_prev, robot.alpha_prev,
                    robot.end_effector):
            h.update(np.round(np.asarray(arr, dtype=float), 9).tobytes())
    for side in ARMS:
        h.update(np.round(robot.arms[side].lower, 9).tobytes())
        h.update(np.round(robot.arms[side].upper, 9).tobytes())
    if not profile_robot:
        h.update(repr((robot.elbow_frame, robot.wrist_frame)).encode())
    for g in library:
        h.update(repr((g.name, g.arms, g.two_handed)).encode())
        for kf in g.keyframes:
            h.update(np.round(kf.positions(), 9).tobytes())
    h.update(np.round(weights.vector(True), 12).tobytes())
    h.update(np.round(weights.vector(False), 12).tobytes())
    return h.hexdigest()[:16]


def run_gesture(spec, robot, library, gesture, joint, seed, deadline=None):
    """
    Run one algorithm on one case (one gesture, one failed joint) with one seed.

    The run is the one the engine's keyframe stage makes for that gesture alone (same
    problem, same derived seed, the same local steps after the algorithm's search:
    :func:`~..recovery.keyframes.finish_search`), but it keeps the optimiser's own best
    (``score``), as the paper reports it; the engine returns the better of that and the
    locked reference pose (``score_engine``, never above ``score_before``).  The wall
    time is measured around problem construction and search.
    """
    from ..optimize import make_algorithm, minimize
    t0 = time.perf_counter()
    algo = make_algorithm(spec.algorithm, spec.preset, **spec.settings_dict())
    problem, _ = case_problems(robot, library, gesture, {joint: None})
    before = problem.evaluate(problem.x0[:, None, :])[:, 0]
    rng = np.random.default_rng(int(seed))
    budget = None if deadline is None else max(deadline - (time.perf_counter() - t0), 0.0)
    clock = Clock(budget)
    res = minimize(problem, algo, clock=clock, seed=int(rng.integers(2 ** 63)))
    rows = len(problem.target_ids)
    _, raw, _ = finish_search(problem, algo, np.atleast_2d(res.x), np.atleast_1d(res.fun),
                              np.zeros(rows, dtype=int), problem.x0, clock,
                              local=(res.xl, res.funl))
    outer = time.perf_counter() - t0
    engine = np.minimum(raw, before)
    status = {0: 'converged', 1: 'deadline', 2: 'cancelled'}[res.status]
    return {'seed': int(seed), 'score': float(raw.max()), 'score_engine': float(engine.max()),
            'score_before': float(before.max()), 'time': float(outer),
            'engine_time': float(res.wall_time), 'status': status, 'nfev': int(res.nfev)}
