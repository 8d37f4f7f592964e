"""
Our explorer: the nominal model as a prior, Gauss-Newton steps on the measured error.

Round 0 measures every typical point at its designed pose (the change shows as the
measured error).  Each later round:

1. fits the structural correction the measurements of *all* points support
   (:func:`.corrections.select`): one structural error explains them all, and the
   fit averages the tracker's noise over every trial;
2. per point, keeps what the corrected model still misses: a bias (the mean residual
   of its trials, shrunk towards zero by a James-Stein factor so that noise is not
   chased) and a Broyden (secant) correction of the Jacobian from each pair of its
   successive trials, applied only where the secant mismatch is larger than noise;
3. solves every point's pose on that local model (damped least squares: a
   Gauss-Newton step on the measured error with the model's Jacobian, iterated to the
   corrected model's solution, kept out of the body by the safety check's clearance,
   :meth:`.trial.SafetyCheck.keep_clear`) and commands it, unless it moves less than
   ``tol_deg`` (the point has converged on its last measured pose).

When the designed DOF cannot reach (the corrected model leaves a point more than the
expansion threshold away), the next stage's joints are freed, as the paper does.
"""

from dataclasses import dataclass
import math

import numpy as np

from .corrections import select, solve_poses
from .task import ExploreTask, PointOutcome
from .trial import recording_end, TrialSession


@dataclass(frozen=True)
class SecantOptions:
    """Our explorer's knobs."""

    max_trials_per_point: int = 5
    tol_deg: float = 0.1            # a step smaller than this ends a point's exploration
    secant_gate: float = 3.0        # Broyden only beyond this many noise sigmas
    secant_move: float = 3.0        # ... and for moves this many times larger than that
    shrink: float = 3.0             # James-Stein factor of the per-point bias
    max_groups: int = 2
    halvings: int = 3               # a step the safety checks refuse is halved this often


class _State:
    """Per point: its measurements, bias and secant matrix."""

    def __init__(self, task):
        k, n = task.start.shape
        self.q = np.array(task.start, dtype=float)     # last commanded pose per point
        self.meas = np.zeros((k, 3))
        self.trials = np.zeros(k, dtype=int)
        self.log = []                                   # (point, q measured, tip)
        self.secant = np.zeros((k, 3, n))
        self.prev = [None] * k                           # previous (q, tip) at each point

    def record(self, k, trial):
        self.log.append((k, trial.q, trial.tip))
        self.trials[k] += 1
        self.meas[k] = trial.tip


def explore_secant(session: TrialSession, task: ExploreTask,
                   options: SecantOptions = SecantOptions()) -> PointOutcome:
    """Explore ``task``'s typical points with our explorer; return what was measured."""
    st = _State(task)
    out = PointOutcome(st.q, st.meas, st.trials)
    with recording_end(out):
        for k in range(len(task.start)):
            st.record(k, session.trial(st.q[k], task.point_ids[k] if task.point_ids else k))
            st.prev[k] = (st.q[k].copy(), st.meas[k].copy())
        for i, (stage, free) in enumerate(task.layouts):
            out.stage, out.free = stage, tuple(int(j) for j in free)
            later = len(task.layouts) - 1 - i
            predicted = _run_stage(session, task, st, np.asarray(free, int), options, out,
                                   later)
            if np.max(predicted) <= task.expansion_mm:
                break
    _keep_best(task, st)
    out.q, out.trials = st.q, st.trials
    out.measured = st.meas
    return out


def _keep_best(task, st):
    """
    End each point on its last pose, unless a trial of it measured clearly better.

    Clearly: by more than the noise of two measurements (3 sigma sqrt 2); then that
    trial's pose and measurement are the point's result (scored by what was measured).
    """
    margin = 3.0 * math.sqrt(2.0) * task.sigma_mm
    for p in range(len(st.q)):
        mine = [(float(np.linalg.norm(y - task.targets[p])), q, y)
                for k, q, y in st.log if k == p]
        if not mine:
            continue
        best = min(mine, key=lambda m: m[0])
        if float(np.linalg.norm(st.meas[p] - task.targets[p])) > best[0] + margin:
            st.q[p], st.meas[p] = best[1], best[2]


def _local_model(task, st, correction, options):
    """Return tip_fn(q, idx): the corrected model plus each point's bias and secant term."""
    q_all = np.array([q for _, q, _ in st.log])
    y_all = np.array([y for _, _, y in st.log])
    ids = np.array([k for k, _, _ in st.log])
    resid = y_all - correction.tip(q_all)
    k = len(task.start)
    bias = np.zeros((k, 3))
    sigma2 = task.sigma_mm ** 2
    for p in range(k):
        mine = resid[ids == p]
        if len(mine):
            b = mine.mean(axis=0)
            factor = max(0.0, 1.0 - options.shrink * sigma2 / (len(mine) * float(b @ b) + 1e-12))
            bias[p] = factor * b
    anchor_q = st.q.copy()

    def tip_fn(q, idx):
        lin = np.einsum('nij,nj->ni', st.secant[idx], q - anchor_q[idx])
        return correction.tip(q) + bias[idx] + lin
    return tip_fn


def _broyden(task, st, k, trial, tip_fn, options):
    """Update point ``k``'s secant matrix from its previous trial to this one."""
    q0, y0 = st.prev[k]
    dq = trial.q - q0
    nrm = float(dq @ dq)
    if nrm < math.radians(0.01) ** 2:
        return
    predicted = tip_fn(trial.q[None], np.array([k]))[0] - tip_fn(q0[None], np.array([k]))[0]
    miss = (trial.tip - y0) - predicted
    noise = options.secant_gate * math.sqrt(2.0) * task.sigma_mm
    # A secant is information only where the move is large against the noise: a tiny
    # step with a noisy difference would make a huge, wrong Jacobian correction.
    if np.linalg.norm(miss) > noise and np.linalg.norm(predicted) > options.secant_move * noise:
        st.secant[k] += np.outer(miss, dq) / nrm


def _waiting(task, st, tip_fn, predicted, options, later):
    """
    Return which points wait for the next layout instead of a trial at this one (K,).

    Only while a later layout remains: a point the corrected model leaves beyond the
    expansion threshold even at its new pose will need the expanded DOF, so it keeps
    its trials for them.  It takes a trial here only if the model predicts the move
    gains more than the noise of two measurements (3 sigma sqrt 2) and one trial per
    later layout stays in its budget; otherwise noise-sized steps at a layout that
    cannot reach would spend the trials the expansion needs.
    """
    if not later:
        return np.zeros(len(st.q), dtype=bool)
    idx = np.arange(len(st.q))
    now = np.linalg.norm(tip_fn(st.q, idx) - task.targets, axis=1)
    gain = now - predicted
    margin = 3.0 * math.sqrt(2.0) * task.sigma_mm
    reserve = st.trials >= options.max_trials_per_point - later
    return (predicted > task.expansion_mm) & ((gain <= margin) | reserve)


def _run_stage(session, task, st, free, options, out, later=0):
    """
    Run rounds at one layout until every point converges; return predicted errors (K,).

    ``later`` is the number of layouts after this one (see :func:`_waiting`).
    """
    k = len(task.start)
    done = np.zeros(k, dtype=bool)
    predicted = np.full(k, np.inf)
    while True:
        q_all = np.array([q for _, q, _ in st.log])
        y_all = np.array([y for _, _, y in st.log])
        correction = select(task.chain, q_all, y_all, task.sigma_mm, options.max_groups)
        out.correction, out.model = correction.describe(), correction
        tip_fn = _local_model(task, st, correction, options)
        q_new, predicted = solve_poses(tip_fn, st.q, task.targets, free, task.lower,
                                       task.upper, task.start,
                                       keep_clear=session.safety.keep_clear())
        moves = np.degrees(np.abs(q_new - st.q).max(axis=1))
        done |= (moves < options.tol_deg) | (st.trials >= options.max_trials_per_point)
        done |= _waiting(task, st, tip_fn, predicted, options, later)
        todo = np.flatnonzero(~done)
        if not todo.size:
            out.status = ('budget' if np.any(st.trials >= options.max_trials_per_point)
                          and np.any(moves >= options.tol_deg) else 'converged')
            return predicted
        for p in todo:
            goal = _safe_step(session, st.q[p], q_new[p], options.halvings)
            name = task.point_ids[p] if task.point_ids else p
            if goal is None:
                done[p] = True
                out.notes.append(f'point {name}: every step towards the solved pose would be '
                                 f'refused ({session.problem(q_new[p])}); it waits')
                continue
            trial = session.trial(goal, name)
            _broyden(task, st, p, trial, tip_fn, options)
            st.prev[p] = (trial.q.copy(), trial.tip.copy())
            st.q[p] = goal
            st.record(p, trial)


def _safe_step(session, q_from, q_to, halvings):
    """
    Return the longest safe part of the step ``q_from`` -> ``q_to`` (all, 1/2, 1/4, ...).

    The corrected model's solution knows nothing of self-collision: where the whole
    step would be refused (the pose or the move from where the robot is now), a
    shorter one in the same direction still learns, and the next round plans again
    from it.  None when even ``1 / 2 ** halvings`` of it would be refused.
    """
    for i in range(halvings + 1):
        goal = q_from + 0.5 ** i * (q_to - q_from)
        if not session.problem(goal):
            return goal
    return None
