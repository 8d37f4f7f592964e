"""
Reconfigure gestures for a fault set: build the bounded problems and solve them.

For every keyframe of every gesture the failed joints are set to their lock angles and
the remaining joints of the faulted arms that take part in the gesture become the free
variables.  Keyframes with the same free-variable layout are solved together as one
batched problem (one objective call per optimiser phase for all of them), within one
wall-clock budget for the whole library (the caller's clock; see :mod:`.budget`).  On
top of the paper's method:

- lock strategies (``average``, ``measured``, ``optimal``; see :mod:`.locks`); the
  ``optimal`` candidates are solved on the very problem of the final result, the
  starting lock among them, so that ``optimal`` is never worse than its start;
- stage 2 of a staged DOF expansion (the second source paper): when a two-handed
  gesture still scores above a threshold, the healthy arm moves too;
- capsule self-collision (:mod:`..objective.collision`) as a penalty inside the optimisation, with
  a final check reported per gesture;
- the keyframes of one motion share their branches: each is polished again from its
  neighbours' solutions (:func:`_share_branches`), so that a motion's keyframes do not
  end in different basins of the arm's redundancy by the luck of the colony;
- each gesture's keyframes then take the kinematic twins whose path from rest presses
  the body least, then those nearest its design (:mod:`.twins`: the same score, but the
  far twin swings the arm half a turn to reach the pose, maybe through the body).
"""

import copy
from dataclasses import dataclass, replace
import time
from typing import NamedTuple, Optional, Union

import numpy as np

from . import pacing
from .budget import ENGINE_RESERVE, STAGE1_SHARE
from .constrained import constrained_pose
from .figures import COLLIDES_WARNING, largest_jump
from .least_squares import refine_basins
from .locks import clamp_lock, resolve_locks
from .result import CUT_SHORT, GestureResult, LibraryResult
from .seeding import kinematic_starts
from .twins import best_twins, pose_twins
from ..model.kinematics import (angle_bytes, arm_columns, arm_joint_count, ArmLandmarks,
                                batch_forward, batch_forward_jacobian, split_arms,
                                take_landmarks)
from ..model.robot import ARMS
from ..objective.collision import CollisionModel
from ..objective.score import gesture_targets, SimilarityScore
from ..optimize import make_algorithm, minimize, Problem, STATUS_CANCELLED, STATUS_DEADLINE
from ..optimize.base import Clock
from ..optimize.polish import polish

_STATUS_NAMES = {0: 'converged', STATUS_DEADLINE: 'deadline', STATUS_CANCELLED: 'cancelled'}
BIMANUAL_MODES = ('auto', 'off', 'on')
DEFAULT_BIMANUAL_THRESHOLD = 10.0
LOCK_CANDIDATES = 12       # coarse lock angles per optimal joint (plus the start)
_DEG2 = (180.0 / np.pi) ** 2
DEFAULT_EXPANSION_THRESHOLD = 5.0   # mm of fingertip error
SHARE_NEIGHBOURS = 5       # a keyframe is restarted from this many keyframes of its motion
SHARE_SWEEPS = 3           # restart sweeps at most (each spreads a branch a little further)
IDLE_STAY_CLOSE = 0.01      # per deg^2: an idle faulted arm moved clear stays near its pose
SHARE_POLISHED = 1         # of those restarts, the best-scoring ones are polished
RESTART_MAXITER = 20       # polish iterations of a repair's branch restarts
RESTART_MAXITER_POLISHED = 5   # ... after a search that polished its keyframes
RESTART_KEEP = (1, 3, 5, 10)   # the iterations whose points are offered to the repair too
TWIN_PATH_SAMPLES = 8      # poses per leg of a twin's path from rest, judged
REACH_MAXITER = 20         # polish iterations of a repair's searches within reach
STIFF_PENALTY = 10.0       # a stuck repair's penalty, times the capsules' own weight
# Colliding rows are solved with the capsules as hard constraints first (recovery.
# constrained), when there are at most CONSTRAINED_ROWS of them (the solve takes 20-70 ms a
# row; the penalised colony is batched); a row whose constrained pose scores within
# CONSTRAINED_GAP of its plain result (the search without the contacts, as low as a clear
# pose normally gets) is settled.
CONSTRAINED_ROWS = 2
CONSTRAINED_GAP = 0.01
PUSH_MAXITER = 15          # polish iterations that push an idle arm out of the body
PACED_NOTE = ('its keyframes were searched into branches too far apart for the joints '
              'to travel in time; repaired within the velocity limits')


@dataclass(frozen=True)
class SearchOptions:
    """
    How the motion adaptation asks the keyframe search to run (the paper's run: defaults).

    ``stay_close`` (per deg^2) penalises moving away from the reference pose, so that
    neighbouring keyframes stay on one redundant branch; ``pulled`` (True or gesture
    names) says which gestures it applies to: a single pose has no neighbour, and the
    pull only costs it score (Talos's side_invite with arm_right_2_joint locked ended
    3.3-4.6 % above its best in 7 seeds of 10 with it).  ``share_branches`` (True,
    False, or gesture names) restarts each keyframe of a motion from its other
    keyframes' solutions (:func:`_share_branches`).  ``lock_start`` maps joints to the
    start of ``lock_strategy='optimal'`` (None: the library average).  ``pace`` (True
    or gesture names) says which motions are kept within the velocity limits
    (:func:`_pace`): the motion adaptation names those it publishes as searched, not
    the typical points of a dense motion, whose whole motion it paces itself.
    ``leans`` maps gesture names to the angles (S,) of the robot's shared joints (a
    torso, :class:`~..model.shared_joints.SharedJoints`) held through that gesture: its
    references are moved back by that lean, so that the upright arms searched here are
    scored as the leaned arms will be (:mod:`.lean`).
    """

    stay_close: float = 0.0
    pulled: Union[bool, tuple] = True
    share_branches: Union[bool, tuple] = True
    lock_start: Optional[dict] = None
    pace: Union[bool, tuple] = True
    leans: Optional[dict] = None


class PoseProblem(Problem):
    """
    The free joints of some arms, for a batch of targets, scored against each target.

    ``base`` is the pair (right, left) of (B, n) starting poses (reference angles with
    failed joints at their locks); ``free`` is a tuple of ``(arm, joint index)`` giving
    the variables.  With a ``collision`` model the capsule penalty is added to the score.
    ``smooth`` (mm or deg) rounds the kinks of the score for the gradient-based polish.
    With ``anchor`` (B, D) the problem adds ``continuity * |x - anchor|^2`` (x in
    degrees): a penalty on joint-space jumps away from where a motion's previous
    point leads, so that successive keyframes stay on one branch of the redundancy.
    ``continuity`` is one weight for every row or one per row (B,): 0 for a row whose
    pose has no neighbour to stay with (its ``anchor`` still says where the design is,
    for the kinematic starts).
    """

    def __init__(self, robot, scorer, target_ids, base, free, collision=None, smooth=0.01,
                 x0=None, anchor=None, continuity=0.0):
        if not free:
            raise ValueError('PoseProblem: no free joint to optimise')
        self.robot = robot
        self.scorer = scorer
        self.collision = collision
        self.smooth = float(smooth)
        self.target_ids = np.asarray(target_ids, dtype=int)
        self.base = {side: np.array(pose, dtype=float) for side, pose in zip(ARMS, base)}
        self.free = tuple(free)
        self.columns = {side: [(k, j) for k, (s, j) in enumerate(self.free) if s == side]
                        for side in ARMS}
        lower = [robot.arms[s].lower[j] for s, j in self.free]
        upper = [robot.arms[s].upper[j] for s, j in self.free]
        # An arm without free joints does not move: its landmarks are computed once.
        self.fixed = {side: batch_forward(robot, self.base[side], side)
                      for side in ARMS if not self.columns[side]}
        if x0 is None:   # the starting poses' free joints: a known-good start
            x0 = [[self.base[s][b, j] for s, j in self.free] for b in range(len(target_ids))]
        self.anchor = None if anchor is None else np.asarray(anchor, dtype=float)
        # Per row (B,), per rad^2: a motion's keyframes are pulled, a single pose is not.
        self.continuity = np.broadcast_to(
            np.asarray(continuity if anchor is not None else 0.0, dtype=float) * _DEG2,
            (len(self.target_ids),)).copy()
        self.pulled = bool(np.any(self.continuity))
        super().__init__(lower, upper, self._objective, n_batch=len(self.target_ids), x0=x0,
                         value_and_grad=self._value_and_grad)
        # The colony starts from kinematic starts (see starts) where a moving arm is scored
        # (an idle arm moved clear of the body is not: its draws would only be pulled home).
        self.seeded = any(side in scorer.targets[t].arms for t in self.target_ids
                          for side in ARMS if self.columns[side])

    def starts(self, rng, n):
        """
        Return ``n`` starts per keyframe: from the kinematics (:mod:`.seeding`) if seeded.

        A problem restricted to boxes (:meth:`restrict`: a paced motion's reach) draws
        uniformly in them: in a box that small a draw starts near already.
        """
        if self.seeded and self.row_bounds is None:
            return kinematic_starts(self, rng, n)
        return self.random(rng, n)

    def subset(self, rows):
        """Return the same problem for some of its rows only (``rows``: indices)."""
        rows = np.asarray(rows, dtype=int)
        sub = PoseProblem(self.robot, self.scorer, self.target_ids[rows],
                          (self.base['right'][rows], self.base['left'][rows]), self.free,
                          self.collision, self.smooth, self.x0[rows],
                          None if self.anchor is None else self.anchor[rows],
                          self.continuity[rows] / _DEG2)
        if self.row_bounds is not None:
            sub.restrict(self.row_bounds[0][rows], self.row_bounds[1][rows])
        return sub

    def assemble(self, x):
        """Return full (right, left) angles of shape (..., n) for variables x (B, ..., D)."""
        x = np.asarray(x, dtype=float)
        extra = x.ndim - 2
        out = {}
        for side in ARMS:
            n = self.base[side].shape[-1]
            base = self.base[side].reshape((-1,) + (1,) * extra + (n,))
            q = np.broadcast_to(base, x.shape[:-1] + (n,)).copy()
            for k, j in self.columns[side]:
                q[..., j] = x[..., k]
            out[side] = q
        return out['right'], out['left']

    def arms(self, x: np.ndarray, jacobian: bool = False) -> tuple:
        """
        Return ``({side: landmarks}, target ids)`` of x (B, N, D), one row per pose.

        A moving arm with ``jacobian`` gives ``(landmarks, jacobian)``; an arm without
        free joints gives its fixed landmarks.
        """
        batch, n, _ = x.shape
        q = dict(zip(ARMS, self.assemble(x)))
        rows = np.repeat(np.arange(batch), n)
        arms = {}
        for side in ARMS:
            if side in self.fixed:
                arms[side] = take_landmarks(self.fixed[side], rows)
            elif jacobian:
                arms[side] = batch_forward_jacobian(self.robot,
                                                    q[side].reshape(-1, q[side].shape[-1]),
                                                    side)
            else:
                arms[side] = batch_forward(self.robot, q[side].reshape(-1, q[side].shape[-1]),
                                           side)
        return arms, np.repeat(self.target_ids, n)

    def _objective(self, x):
        arms, target = self.arms(x, jacobian=False)
        f = self.scorer.evaluate(arms['right'], arms['left'], target)
        if self.collision is not None:
            f = f + self.collision.penalty(arms['right'], arms['left'], target)[0]
        f = f.reshape(x.shape[:2])
        if self.pulled:
            f = f + self.continuity[:, None] * np.sum((x - self.anchor[:, None]) ** 2, axis=-1)
        return f

    def _value_and_grad(self, x):
        arms, target = self.arms(x, jacobian=True)
        return self.value_and_grad_at(x, arms, target)

    @staticmethod
    def split_jacobians(arms: dict) -> tuple[dict, dict]:
        """Return ``({side: landmarks}, {side: jacobian or None})`` of :meth:`arms` with them."""
        moving = {s: not isinstance(a, ArmLandmarks) for s, a in arms.items()}
        return ({s: a[0] if moving[s] else a for s, a in arms.items()},
                {s: a[1] if moving[s] else None for s, a in arms.items()})

    def value_and_grad_at(self, x: np.ndarray, arms: dict, target: np.ndarray) -> tuple:
        """Return the objective and its gradient at x (B, N, D) from its :meth:`arms`."""
        batch, n, dim = x.shape
        f, g_right, g_left = self.scorer.value_and_grad(arms['right'], arms['left'], target,
                                                        self.smooth)
        grads = {'right': g_right, 'left': g_left}
        if self.collision is not None:
            lm, jac = self.split_jacobians(arms)
            pen, pen_grad = self.collision.penalty(lm['right'], lm['left'], target,
                                                   jac['right'], jac['left'])
            f = f + pen
            for side, g in pen_grad.items():
                grads[side] = grads[side] + g
        grad = np.empty((batch * n, dim))
        for side in ARMS:
            for k, j in self.columns[side]:
                grad[:, k] = grads[side][:, j]
        f, grad = f.reshape(batch, n), grad.reshape(batch, n, dim)
        if self.pulled:
            step = x - self.anchor[:, None]
            f = f + self.continuity[:, None] * np.sum(step ** 2, axis=-1)
            grad = grad + 2.0 * self.continuity[:, None, None] * step
        return f, grad


class _Batch:
    """Rows to solve: starting poses, target ids and free-variable layouts."""

    def __init__(self, base_right, base_left, target_ids, layouts, x0=None, stay_close=0.0,
                 motions=None):
        self.right = np.array(base_right, dtype=float)
        self.left = np.array(base_left, dtype=float)
        self.target_ids = np.asarray(target_ids, dtype=int)
        self.layouts = list(layouts)
        self.x0 = x0   # optional {row: start vector in the row's layout}
        # Per row, the penalty per deg^2 away from the reference pose (0: none).
        self.stay_close = np.broadcast_to(np.asarray(stay_close, dtype=float),
                                          (len(self.target_ids),)).copy()
        # Per row, the motion (gesture) it belongs to: rows of one motion share branches.
        self.motions = (np.full(len(self.target_ids), -1) if motions is None
                        else np.asarray(motions, dtype=int))


def _solve(robot, scorer, checker, batch, algo, clock, rng, stats=None):
    """
    Solve every row of ``batch`` within ``clock``; with a collision ``checker``, keep apart.

    The collision constraint is lazy: the plain score is optimised first (fast, and
    most results do not collide), the results are checked, and only the rows that
    collide are solved again: with the capsules as hard constraints from their
    starting pose (:func:`_settle_constrained`), and, unless that came within
    ``CONSTRAINED_GAP`` of the plain result, with the capsule penalty from their
    collision-free starting pose and from the plain optimum (:func:`_repair`).
    Return (best right, best left, status names).
    """
    best_r, best_l, status = _solve_once(robot, scorer, None, batch, algo, clock, rng, stats)
    if checker is None:
        return best_r, best_l, status
    ids = batch.target_ids
    lm_r, lm_l = batch_forward(robot, best_r, 'right'), batch_forward(robot, best_l, 'left')
    collides, shape_hits = checker.verdicts(lm_r, lm_l, ids)
    rows = np.nonzero(collides)[0]
    if rows.size == 0:
        return best_r, best_l, status
    # The torso's shape in the repair's penalty only where it is what the rows touch.
    if np.any(shape_hits[rows]):
        checker = checker.shaped()
    rows, extra = _settle_constrained(robot, scorer, checker, batch, rows,
                                      (best_r, best_l, status), algo, clock)
    if rows.size == 0:
        return best_r, best_l, status
    r2, l2, r3, l3, st2 = _repair(robot, scorer, checker, batch, rows,
                                  (best_r, best_l), _repair_algorithm(algo), clock, rng, stats)
    # Candidates per row: the plain result, the penalised ones (from the starting pose
    # and from the plain result), and the starting pose (collision-free unless the locks
    # themselves force a contact).  The best score among those that do not collide
    # wins; where all collide, the penalised ones are pushed out with a stiffer penalty
    # (_push_clear) and join them, and if all still collide, the least penetration.  The
    # rows' constrained poses (_settle_constrained) are candidates too.
    candidates = [(best_r[rows], best_l[rows]), (r2, l2), (r3, l3),
                  (batch.right[rows], batch.left[rows])] + extra
    scores, pens, hits = _judge(robot, scorer, checker, ids[rows], candidates)
    stuck = np.nonzero(hits.all(axis=0))[0]
    if stuck.size:
        def solve(stiff, sub):
            return _solve_once(robot, scorer, stiff, sub, _repair_algorithm(algo), clock,
                               rng, stats)[:2]
        for qr, ql in _push_clear(checker, batch, rows[stuck],
                                  [(r[stuck], l[stuck]) for r, l in candidates[1:3]], solve):
            full_r, full_l = r3.copy(), l3.copy()
            full_r[stuck], full_l[stuck] = qr, ql
            candidates.append((full_r, full_l))
        scores, pens, hits = _judge(robot, scorer, checker, ids[rows], candidates)
    for i, k in enumerate(rows):
        free = ~hits[:, i]
        pick = (int(np.argmin(np.where(free, scores[:, i], np.inf))) if free.any()
                else int(np.argmin(pens[:, i])))
        best_r[k], best_l[k] = candidates[pick][0][i], candidates[pick][1][i]
        if st2[i] in CUT_SHORT:
            status[k] = st2[i]
    return best_r, best_l, status


def _repair(robot, scorer, checker, batch, rows, plain, algo, clock, rng, stats):
    """
    Solve the colliding ``rows`` again with the capsule penalty, from two starts at once.

    One start is the row's starting pose (collision-free unless the locks force a
    contact), the other the plain optimum that collided: the penalty pushes it out into
    the nearest clear pose, which is usually far better than the clear basin around the
    start (measured on Talos's Wai with arm_right_6_joint locked: 21.2-21.6 from the
    plain optimum against 24-36 from the start).  Both starts are rows of one batched
    problem.  Return (right, left) from the start, (right, left) from the plain optimum,
    and the statuses of the first.
    """
    layouts = [batch.layouts[k] for k in rows]
    start = {i: [(batch.right if s == 'right' else batch.left)[k, j] for s, j in lay]
             for i, (k, lay) in enumerate(zip(rows, layouts))}
    m = len(rows)
    from_plain = {m + i: [(plain[0] if s == 'right' else plain[1])[k, j] for s, j in lay]
                  for i, (k, lay) in enumerate(zip(rows, layouts))}
    both = np.concatenate([rows, rows])
    sub = _Batch(batch.right[both], batch.left[both], batch.target_ids[both],
                 layouts + layouts, {**start, **from_plain},
                 stay_close=batch.stay_close[both], motions=batch.motions[both])
    r2, l2, st2 = _solve_once(robot, scorer, checker, sub, algo, clock, rng, stats)
    return r2[:m], l2[:m], r2[m:], l2[m:], st2[:m]


def _settle_constrained(robot, scorer, checker, batch, rows, plain, algo, clock):
    """
    Solve colliding ``rows`` with hard constraints first; return (rows left, candidates).

    ``plain`` is (right, left, status) of the plain search, updated in place: a row
    whose constrained pose (:func:`_constrained`) is clear and within
    :data:`CONSTRAINED_GAP` of its plain result (which searched without the contacts,
    so a clear pose rarely scores lower) takes that pose and is settled, unless the
    plain search was cut short.  The rows left go to the penalised search, with their
    constrained poses as one more candidate (the list returned).  Only with a polishing
    algorithm (the node's preset; the paper's runs as it ran) and up to
    :data:`CONSTRAINED_ROWS` rows (the solve is per row; the colony is batched).

    A converged solve alone is not settled: it can end in a far worse basin than the
    penalised search's (Namo's Wai with right joint 3 stuck at 15 deg: 83.67 against
    48.27, every seed), though on the rows measured first (Talos's right joint 4,
    TIAGo++'s and Namo's colliding Wai at their average locks) the penalised search
    gained only 0.0-0.3 % after it.
    """
    best_r, best_l, status = plain
    if not getattr(algo, 'polish', 0) or len(rows) > CONSTRAINED_ROWS:
        return rows, []
    found = _constrained(robot, scorer, checker, batch, rows, clock)
    scores, _, hits = _judge(robot, scorer, checker, batch.target_ids[rows],
                             [(best_r[rows], best_l[rows]), found])
    settled = ~hits[1] & (scores[1] <= scores[0] * (1.0 + CONSTRAINED_GAP)) & np.array(
        [status[k] not in CUT_SHORT for k in rows], dtype=bool)
    for i in np.nonzero(settled)[0]:
        best_r[rows[i]], best_l[rows[i]] = found[0][i], found[1][i]
        if clock.expired():
            status[rows[i]] = _STATUS_NAMES[clock.reason]
    return rows[~settled], [(found[0][~settled], found[1][~settled])]


def _constrained(robot, scorer, checker, batch, rows, clock):
    """
    Return (right, left) of ``rows``, each solved from its start with hard constraints.

    The capsules' clearances as SLSQP's constraints (:mod:`.constrained`), with the
    torso's shape where ``checker`` has it (as the penalised repair: only where the
    rows touch it; it costs a third more per evaluation, and the judge checks it
    anyway), from the row's starting pose, each row within a share of the clock that
    leaves the penalised search one too; a row without free joints, or for which no
    clear pose was found, keeps its starting pose.
    """
    right, left = batch.right[rows].copy(), batch.left[rows].copy()
    for i, k in enumerate(rows):
        if not batch.layouts[k]:
            continue
        problem = _rows_problem(robot, scorer, None, batch, batch.layouts[k], [k])[0]
        res = constrained_pose(problem, checker, clock.child(share=1.0 / (len(rows) - i + 1)))
        if res.x is not None:
            qr, ql = problem.assemble(res.x[None])
            right[i], left[i] = qr[0], ql[0]
    return right, left


def _judge(robot, scorer, checker, ids, candidates):
    """Return (scores, penetration sums, collides) of (right, left) candidates, (C, rows)."""
    scores, pens, hits = [], [], []
    for qr, ql in candidates:
        lm_r, lm_l = batch_forward(robot, qr, 'right'), batch_forward(robot, ql, 'left')
        scores.append(scorer.evaluate(lm_r, lm_l, ids))
        pens.append(checker.penetration(lm_r, lm_l, ids).sum(axis=1))
        hits.append(checker.collides(lm_r, lm_l, ids))
    return np.array(scores), np.array(pens), np.array(hits)


def _push_clear(checker, batch, rows, penalised, solve):
    """
    Return the penalised candidates of ``rows`` searched again with a stiffer penalty.

    The capsule penalty is soft: where the score pulls into a contact, its optimum rests
    at a small penetration (weight 1 per mm^2: about a millimetre against a steep score),
    and when every candidate of a row ended beyond the tolerance the least-penetrating
    one was published, colliding (the paper's Wai with right joint 2 locked at 20 deg:
    1.05 mm into the torso).  From each penalised candidate ``(right, left)`` of the
    rows, ``solve(checker, batch)`` (the caller's search) runs with the penalty
    ``STIFF_PENALTY`` times stronger and settles at a clear pose next to it.
    """
    stiff = copy.copy(checker)
    stiff.capsules = replace(checker.capsules, weight=checker.capsules.weight * STIFF_PENALTY)
    layouts = [batch.layouts[k] for k in rows]
    m = len(rows)
    starts = {c * m + i: [(qr if s == 'right' else ql)[i, j] for s, j in lay]
              for c, (qr, ql) in enumerate(penalised) for i, lay in enumerate(layouts)}
    many = np.tile(rows, len(penalised))
    sub = _Batch(batch.right[many], batch.left[many], batch.target_ids[many],
                 layouts * len(penalised), starts, stay_close=batch.stay_close[many],
                 motions=batch.motions[many])
    right, left = solve(stiff, sub)
    return [(right[c * m:(c + 1) * m], left[c * m:(c + 1) * m]) for c in range(len(penalised))]


def _repair_algorithm(algo):
    """
    Return the algorithm for the penalised repair pass: the same, with a shorter polish.

    The repair only has to find a good collision-free pose near the start; half the
    polish iterations keep the node's latency down (see README, "Self-collision").
    """
    if getattr(algo, 'polish', 0):
        algo = copy.copy(algo)
        algo.polish_maxiter = max(1, algo.polish_maxiter // 2)
    return algo


def _unpolished(algo):
    """Return ``algo`` without its own polish: its caller polishes the result with more."""
    if not getattr(algo, 'polish', 0):
        return algo
    algo = copy.copy(algo)
    algo.polish = 0
    return algo


def _solve_once(robot, scorer, collision, batch, algo, clock, rng, stats=None):
    """
    Solve every row of ``batch`` (rows sharing a layout in one batched problem).

    Return (best right, best left, status names); a row never ends worse than its
    starting pose (by the objective, which includes the penalty when ``collision``).
    ``stats['nfev']``, if given, counts the objective evaluations over all rows.
    """
    m = len(batch.target_ids)
    best_r, best_l = batch.right.copy(), batch.left.copy()
    status = ['unchanged'] * m
    groups = {}
    for k, free in enumerate(batch.layouts):
        if free:
            groups.setdefault(free, []).append(k)
    # A batched solve costs about the same for one row as for twenty (the per-call
    # overhead dominates), so each group gets an equal share of what is left, smallest
    # groups first: the time they do not use rolls over to the bigger ones.
    order = sorted(groups.items(), key=lambda item: len(item[1]))
    for n_left, (free, members) in zip(range(len(order), 0, -1), order):
        x0 = None
        if batch.x0 is not None:
            x0 = np.array([batch.x0[k] for k in members])
        problem, designed = _rows_problem(robot, scorer, collision, batch, free, members, x0)
        start = problem.evaluate(problem.x0[:, None, :])[:, 0]
        group_clock = clock.child(share=1.0 / n_left)
        res = minimize(problem, algo, clock=group_clock, seed=int(rng.integers(2 ** 63)))
        nfev = res.nfev * len(members)
        x = np.atleast_2d(res.x)
        f = np.atleast_1d(res.fun)
        x, f, used = finish_search(problem, algo, x, f, batch.motions[members], designed,
                                   group_clock, local=(res.xl, res.funl))
        nfev += used
        if stats is not None:
            stats['nfev'] = stats.get('nfev', 0) + nfev
        keep = f <= start
        x = np.where(keep[:, None], x, problem.x0)
        qr, ql = problem.assemble(x)
        for i, k in enumerate(members):
            best_r[k], best_l[k] = qr[i], ql[i]
            status[k] = _STATUS_NAMES[res.status]
    return best_r, best_l, status


def _rows_problem(robot, scorer, collision, batch, free, members, x0=None):
    """
    Return (PoseProblem, designed angles) of ``batch``'s rows ``members`` with layout ``free``.

    The designed angles anchor every row, pulled or not: the kinematic starts are drawn
    towards them (seeding.SEED_PULL).
    """
    refs = [scorer.reference(k) for k in batch.target_ids[members]]
    designed = np.array([[ref[0 if s == 'right' else 1][j] for s, j in free] for ref in refs])
    problem = PoseProblem(robot, scorer, batch.target_ids[members],
                          (batch.right[members], batch.left[members]), free,
                          collision=collision, x0=x0, anchor=designed,
                          continuity=batch.stay_close[members])
    return problem, designed


def finish_search(problem, algo, x, f, motions, designed, clock, local=None):
    """
    Return ``(x, f, nfev)``: the local steps that follow the algorithm's own search.

    For algorithms that polish (the node's default), the keyframes of a motion share
    their branches (:func:`_share_branches`), then every keyframe takes the reweighted
    Gauss-Newton refinement, a single pose's with the runners-up of the algorithm's
    polish in other basins and its best's kinematic twins
    (:func:`~.least_squares.refine_basins`; ``local``: the result's ``(xl, funl)``; a
    motion's keyframes keep their shared branch); the paper's preset, which does not
    polish, is left as the paper ran it.
    ``x`` (B, D) and ``f`` (B,) are the algorithm's best per row of ``problem``,
    ``motions`` (B,) each row's motion (-1: none) and ``designed`` (B, D) the designed
    angles of the free joints.
    """
    if not getattr(algo, 'polish', 0):
        return x, f, 0
    x, f, shared = _share_branches(problem, x, f, motions, designed, clock,
                                   algo.polish_maxiter, algo.polish_ftol)
    # A motion's keyframes keep the branch they share: another basin for one of them
    # alone would be a jump in the motion.  Single poses take any basin, and their
    # best's twins (twins.pose_twins) are runners-up too.
    alone = ~in_motion(motions)
    if local is None or local[0] is None or not alone.any():
        local = None
    else:
        twins = pose_twins(problem, x)
        xl = np.concatenate((local[0], twins), axis=1)
        fl = np.concatenate((local[1], problem.evaluate(twins)), axis=1)
        local = (xl, np.where(alone[:, None], fl, np.inf))
    x, f, refined = refine_basins(problem, x, f, local, clock)
    return x, f, shared + refined


def in_motion(motions: np.ndarray) -> np.ndarray:
    """Return which rows are keyframes of a motion of several (``motions`` (B,), -1: none)."""
    return np.array([m >= 0 and np.count_nonzero(motions == m) > 1 for m in motions],
                    dtype=bool)


def _share_branches(problem, x, f, motions, designed, clock, maxiter, ftol):
    """
    Restart each keyframe of a motion from its neighbours' solutions; keep what is better.

    The keyframes of a motion are searched independently, and with the node's small
    colony each lands in whichever branch of the arm's redundancy its best bee happened
    to sample, while its designed pose (the locks applied) may lie in a worse basin.
    Measured on the Bye wave with right joint 5 locked: keyframes 1 and 3, the same
    pose, ended in basins 24.8 to 33.0 apart from seed to seed, so the motion's score
    (its worst keyframe) missed the best basin in 3 runs of 8.  A neighbour's solution
    shifted by the designed step between the two keyframes is a start in the branch
    the neighbour found: each keyframe is polished from its ``SHARE_NEIGHBOURS``
    nearest keyframes of the same motion (in designed angles), every start of every
    keyframe in one batched call, and keeps the lowest value (the problem's own
    objective), so no keyframe ends worse.  Sweeps repeat while a keyframe improves
    (at most ``SHARE_SWEEPS``), so that a good branch spreads along the motion.

    It runs with algorithms that polish (the node's default), with their polish
    settings; the paper's preset, which does not, is left as the paper ran it.
    ``x`` (B, D) and ``f`` (B,) are the solutions and values of ``problem``'s rows,
    ``motions`` (B,) their motion (-1: none) and ``designed`` (B, D) the designed angles
    of the free joints.  Returns (x, f, objective evaluations).
    """
    rows = np.nonzero(in_motion(motions))[0]
    if rows.size == 0:
        return x, f, 0
    x, f = x.copy(), f.copy()
    width = min(SHARE_NEIGHBOURS,
                max(np.count_nonzero(motions == motions[k]) for k in rows) - 1)
    near = np.empty((len(rows), width), dtype=int)
    for i, k in enumerate(rows):
        mates = np.nonzero(motions == motions[k])[0]
        mates = mates[mates != k]
        gap = np.abs(designed[mates] - designed[k]).max(axis=1)
        order = mates[np.argsort(gap, kind='stable')][:width]
        near[i] = np.resize(order, width)   # a short motion repeats its neighbours
    sub = problem.subset(rows)
    nfev = 0
    for _ in range(SHARE_SWEEPS):
        if clock.expired():
            break
        starts = sub.clip(x[near] + designed[rows][:, None, :] - designed[near])
        if SHARE_POLISHED < width:
            # Screen: only the starts that already score best are polished.
            f0 = sub.evaluate(starts)
            keep = np.argsort(f0, axis=1, kind='stable')[:, :SHARE_POLISHED]
            starts = np.take_along_axis(starts, keep[..., None], axis=1)
        px, pf = polish(sub, starts, clock, maxiter=maxiter, ftol=ftol)
        nfev += sub.nfev
        sub.nfev = 0
        pick = np.argmin(pf, axis=1)
        fb = pf[np.arange(len(rows)), pick]
        gain = fb < f[rows] - ftol * (1.0 + np.abs(f[rows]))
        if not np.any(gain):
            break
        x[rows[gain]] = px[np.arange(len(rows)), pick][gain]
        f[rows[gain]] = fb[gain]
    return x, f, nfev


def free_layout(robot, arms_used, locked, moving, allowed=None):
    """Free variables: unlocked joints of moving arms used (and ``allowed``, if given)."""
    return tuple((s, j) for s in ARMS if s in moving and s in arms_used
                 for j in range(arm_joint_count(robot, s)) if j not in locked[s]
                 and (allowed is None or (s, j) in allowed))


def joint_set(robot, names):
    return {robot.locate_joint(n) for n in names}


def reconfigure_library(robot, library, faults, settings, *,
                        seed: Optional[int] = None, clock: Optional[Clock] = None,
                        measured=None, optimizer_overrides=None, gestures=None,
                        options: SearchOptions = SearchOptions()) -> LibraryResult:
    """
    Reconfigure every gesture (or those named in ``gestures``) for a fault set.

    ``faults`` maps joint names to lock angles (rad) or None (chosen by
    ``settings.lock_strategy``; ``measured`` maps joints to measured angles for the
    ``measured`` strategy).  ``settings`` is the run's
    :class:`~.engine.RecoverySettings`, whose fields are used as named: ``optimizer`` /
    ``optimizer_preset`` (with ``optimizer_overrides``, options of the preset),
    ``weights``, ``bimanual`` (stage 2 for two-handed gestures: with ``auto`` it runs
    when stage 1 scores above ``DEFAULT_BIMANUAL_THRESHOLD``), ``collision_check``
    (keep the arms and torso apart and report any pose that still collides),
    ``tool_length_mm`` / ``tool_arm`` (a tool lengthens that hand; the references stay
    those of the designed motion on the original structure).  ``clock``
    (:class:`~namo_fault_recovery.optimize.base.Clock`) owns the deadline and the cancel
    flag of the whole library (None: ``settings.deadline_sec`` from now).  The paper's
    problem is ``bimanual='off'`` and ``collision_check=False``.

    A gesture's designed ``joints`` are searched first, and its ``expand`` stages add
    joints while a keyframe's fingertip stays more than ``DEFAULT_EXPANSION_THRESHOLD``
    mm off (staged DOF expansion).  ``options`` (:class:`SearchOptions`) holds what the
    motion adaptation adds: ``stay_close`` and the gestures it ``pulled``,
    ``share_branches`` and the ``lock_start`` of ``lock_strategy='optimal'`` (see
    :func:`_optimise_locks`), and what the torso's lean adds: ``leans``, the gestures
    scored as with their torso leaned (:mod:`.lean`).  Returns a
    :class:`~.result.LibraryResult`, a pure function of the inputs and ``seed`` (None
    draws one) up to where a deadline cuts.
    """
    start = time.monotonic()
    reference = robot
    robot = robot.changed_model(settings.tool_length_mm, settings.tool_arm)
    clock = Clock(settings.deadline_sec) if clock is None else clock
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    rng = np.random.default_rng(seed)
    algo = make_algorithm(settings.optimizer, settings.optimizer_preset,
                          **(optimizer_overrides or {}))
    locks, notes, optimal = _start_locks(robot, library, faults, settings.lock_strategy,
                                         measured, options.lock_start)
    selected = list(library) if gestures is None else [library[g] for g in gestures]
    # The optimisers stop early enough to leave time for what follows them (scoring the
    # result, the collision check).
    search = clock.child(reserve=ENGINE_RESERVE)
    setup = _Setup(robot, reference, selected, locks, settings, algo, options)
    setup.faults, setup.seed = dict(faults), seed
    setup.budget = None if clock.end is None else clock.end - clock.start
    notes += setup.notes
    stats = {'nfev': 0}
    out = _run(setup, [locks], rng, search, stats)
    if optimal:
        locks, out, note = _optimise_locks(setup, locks, out, optimal, rng, search, stats)
        notes.append(note)
    notes += _cleared_note(setup, out['cleared'])
    return _library_result(setup, locks, out, notes, time.monotonic() - start,
                           int(stats['nfev']))


def _start_locks(robot, library, faults, lock_strategy, measured, lock_start):
    """Return the lock angles to start from, the notes, and the joints to optimise."""
    locks, notes = resolve_locks(robot, library, faults, lock_strategy, measured)
    optimal = []
    if lock_strategy == 'optimal':
        optimal = [j for j, a in faults.items() if a is None]
        for joint in optimal:
            if lock_start and lock_start.get(joint) is not None:
                locks[joint] = clamp_lock(robot, joint, lock_start[joint])
    return locks, notes, optimal


def _named(which, name):
    """Return whether gesture ``name`` is one of ``which`` (True: all, False: none)."""
    return which if isinstance(which, bool) else name in which


def leaned_references(reference, targets, owners, selected, leans):
    """
    Return the targets' reference landmarks moved back by their gesture's lean, or None.

    ``owners[k]`` is target k's gesture in ``selected``; ``leans`` maps gesture names
    to shared-joint angles (:class:`SearchOptions`).  None without any lean.
    """
    if not leans:
        return None
    shared = reference.shared
    rows = [k for k, g in enumerate(owners) if selected[g].name in leans]
    if shared is None or not rows:
        return None
    t = np.array([leans[selected[owners[k]].name] for k in rows], dtype=float)
    out = []
    for side in ARMS:
        q = np.array([t_.q_right if side == 'right' else t_.q_left for t_ in targets])
        lm = ArmLandmarks(*(np.array(a) for a in batch_forward(reference, q, side)))
        moved = shared.back(take_landmarks(lm, rows), t)
        for full, part in zip(lm, moved):
            full[rows] = part
        out.append(lm)
    return tuple(out)


class _Setup:
    """What every run on one library shares: targets, scorer, layouts and stage plans."""

    def __init__(self, robot, reference, selected, locks, settings, algo, options):
        self.robot = robot
        self.selected = selected
        self.settings = settings
        self.algo = algo
        self.bimanual = settings.bimanual
        self.notes = []
        self.targets, self.owners = [], []
        for gi, gesture in enumerate(selected):
            for t in gesture_targets(gesture):
                self.targets.append(t)
                self.owners.append(gi)
        # Per target, the motion whose keyframes share branches (-1: none), and the
        # stay_close pull towards its reference pose (0: none).
        self.motions = [g if _named(options.share_branches, selected[g].name) else -1
                        for g in self.owners]
        self.stay_close = np.array([options.stay_close
                                    if _named(options.pulled, selected[g].name) else 0.0
                                    for g in self.owners])
        self.paced = options.pace   # the motions kept within the velocity limits
        targets = self.targets
        self.scorer = SimilarityScore(robot, targets, settings.weights,
                                      reference_robot=reference,
                                      reference_landmarks=leaned_references(
                                          reference, targets, self.owners, selected,
                                          options.leans))
        self.checker = None
        if settings.collision_check:
            self.checker = CollisionModel(robot, targets, robot.capsules)
        self.ref_r = np.array([t.q_right for t in targets])
        self.ref_l = np.array([t.q_left for t in targets])
        # The arms whose structure changed: a failed joint, a tool or a learned correction,
        # both under a torso's lean.  Every lock set tried for this library locks the
        # same joints: all of it is shared.
        self.faulted = {side for side in ARMS
                        if any(robot.locate_joint(j)[0] == side for j in locks)
                        or robot.changed(side) or options.leans}
        self.locked = locked_sets(robot, locks)
        self.frozen = tuple(side for side in ARMS
                            if len(self.locked[side]) == arm_joint_count(robot, side))
        for side in self.frozen:
            self.notes.append(f'all joints of the {side} arm failed: it is frozen at its '
                              f'lock angles')
        owners = self.owners
        self.designed = [joint_set(robot, selected[g].joints) if selected[g].joints else None
                         for g in owners]
        self.layouts = [free_layout(robot, t.arms, self.locked, self.faulted, a)
                        for t, a in zip(targets, self.designed)]
        self.status0 = ['frozen' if any(s in self.faulted for s in t.arms) and not lay
                        else 'unchanged' for t, lay in zip(targets, self.layouts)]
        self.two_stage = self._two_stage_rows()
        self.expandable = any(selected[owners[k]].expand for k in range(len(targets))
                              if self.layouts[k] or self.status0[k] == 'frozen')

    def _two_stage_rows(self):
        """Return the rows stage 2 may run on (two-handed, one faulted arm), with a note."""
        scorer, bimanual = self.scorer, self.bimanual
        rows = [k for k, t in enumerate(self.targets)
                if bimanual != 'off' and t.two_handed and len(self.faulted) == 1]
        if bimanual == 'auto' and rows and all(
                scorer.target_weights(k).wrist >= scorer.target_weights(k).wrist_lr
                and scorer.target_weights(k).tip >= scorer.target_weights(k).tip_lr
                for k in rows):
            # The healthy arm starts at its reference, where its own terms are 0.  Moving
            # its wrist (tip) by d adds d to its wrist (tip) term and can shorten the
            # left-right gap by at most d, so with these weights stage 2 can never lower
            # the score.
            self.notes.append('stage 2 skipped: with wrist >= wrist_lr and tip >= tip_lr '
                              'weights, moving the healthy arm cannot lower the score')
            return []
        return rows

    def totals(self, after, n_sets):
        """Return each lock set's library total: the sum of its gestures' worst scores."""
        worst = np.full((n_sets, len(self.selected)), -np.inf)
        owners = np.asarray(self.owners)
        per_set = np.asarray(after).reshape(n_sets, len(self.targets))
        for gi in range(len(self.selected)):
            worst[:, gi] = per_set[:, owners == gi].max(axis=1)
        return worst.sum(axis=1)


class _Rows:
    """
    The rows of one batched :func:`_run`: every lock set's targets, one after the other.

    Every lock set locks the same joints (only the angles differ), so the rows of all
    of them share their layouts and stage plans.  ``right``/``left``/``after``/
    ``status``/``stage`` hold the solution so far, updated in place by each stage.
    """

    def __init__(self, setup, lock_sets):
        robot = setup.robot
        n_t, n_g, n_c = len(setup.targets), len(setup.selected), len(lock_sets)
        self.ids = np.tile(np.arange(n_t), n_c)
        self.owners = [g + c * n_g for c in range(n_c) for g in setup.owners]
        self.motions = [-1 if g < 0 else g + c * n_g for c in range(n_c)
                        for g in setup.motions]
        self.selected = setup.selected * n_c
        self.targets = setup.targets * n_c
        self.layouts = setup.layouts * n_c
        self.designed = setup.designed * n_c
        self.stay_close = np.tile(setup.stay_close, n_c)
        self.status0 = setup.status0 * n_c
        self.two_stage = [k + c * n_t for c in range(n_c) for k in setup.two_stage]
        bases = [apply_locks(robot, setup.ref_r, setup.ref_l, locks) for locks in lock_sets]
        # Every angle published lies within its limits, bit for bit: a designed angle or a
        # lock accepted within the limits' tolerance is clipped before anything uses it.
        self.base_r = robot.arms['right'].clip(np.concatenate([b[0] for b in bases]))
        self.base_l = robot.arms['left'].clip(np.concatenate([b[1] for b in bases]))
        self.right = self.left = self.after = self.status = None
        self.stage = np.ones(len(self.ids), dtype=int)
        self.expansion = np.zeros(len(self.ids), dtype=int)
        self.paced = np.zeros(len(self.ids), dtype=bool)   # repaired by _pace


def _run(setup, lock_sets, rng, clock, stats):
    """
    Solve the whole library once for each lock set of ``lock_sets``, in one batch.

    Stage 1, the staged DOF expansion and stage 2 run once over the rows of all lock
    sets (:class:`_Rows`).  Returns a dict of per-row arrays (lock sets one after the
    other, each in target order).
    """
    robot, scorer, checker, algo = setup.robot, setup.scorer, setup.checker, setup.algo
    rows = _Rows(setup, lock_sets)
    stage1_clock = clock
    if rows.two_stage or setup.expandable:
        stage1_clock = clock.child(share=STAGE1_SHARE)
    rows.right, rows.left, status = _solve(
        robot, scorer, checker, _Batch(rows.base_r, rows.base_l, rows.ids, rows.layouts,
                                       stay_close=rows.stay_close, motions=rows.motions),
        algo, stage1_clock, rng, stats)
    rows.status = [s0 if s0 == 'frozen' else s for s0, s in zip(rows.status0, status)]
    rows.after = scorer.evaluate(rows.right, rows.left, rows.ids)
    if setup.expandable:
        _expand(setup, rows, clock, rng, stats)
    stage1 = rows.after.copy()
    if rows.two_stage:
        _stage2(setup, rows, clock, rng)
    _take_best_twins(setup, rows)
    cleared = _clear_idle_arms(setup, rows, clock, rng)
    _pace(setup, rows, clock, rng)
    best_r, best_l, after = rows.right, rows.left, rows.after
    # The optimisers search within the limits; clipping again guards that promise.
    clipped_r, clipped_l = robot.arms['right'].clip(best_r), robot.arms['left'].clip(best_l)
    if not (np.array_equal(clipped_r, best_r) and np.array_equal(clipped_l, best_l)):
        best_r, best_l = clipped_r, clipped_l
        after = scorer.evaluate(best_r, best_l, rows.ids)
    return {'right': best_r, 'left': best_l, 'after': after, 'stage1': stage1,
            'stage': rows.stage, 'expansion': rows.expansion, 'status': rows.status,
            'layouts': rows.layouts, 'base_right': rows.base_r, 'base_left': rows.base_l,
            'paced': rows.paced, 'cleared': cleared}


def _take_best_twins(setup, rows):
    """
    Put each gesture's solved keyframes on their best kinematic twins (:mod:`.twins`).

    The same landmarks and score either way, but the far twin swings the arm half a turn,
    maybe through the body, to reach the pose: of the twins, the one whose path from
    rest (the locked joints at their locks) presses the body least, then the one nearest
    the design (in place).
    """
    robot = setup.robot
    q = np.concatenate((rows.right, rows.left), axis=1)
    design = np.concatenate((rows.base_r, rows.base_l), axis=1)
    q, changed = best_twins(
        robot, q, design, rows.layouts, rows.owners,
        lambda poses, ks: pose_values(robot, setup.scorer, setup.checker, poses, rows.ids[ks]),
        joint_bounds(robot), _path_penalty(setup, rows))
    if changed:
        rows.right, rows.left = split_arms(robot, q)
        rows.after = setup.scorer.evaluate(rows.right, rows.left, rows.ids)


def _path_penalty(setup, rows):
    """
    Return ``cost(poses (m, K, J), ks)``: the capsule penalty along the paths from rest.

    Each candidate's path runs straight in joint space from the rest pose (every joint
    at 0, the locked ones at their locks) through its K keyframes (rows ``ks``), sampled
    :data:`TWIN_PATH_SAMPLES` times a leg and judged with each leg's end row's
    allowances; the mean penalty per sample.  None without a collision model.
    """
    robot, checker = setup.robot, setup.checker
    if checker is None:
        return None
    locked = layout_columns(robot, [(side, j) for side in ARMS for j in setup.locked[side]])
    steps = np.arange(1, TWIN_PATH_SAMPLES + 1) / TWIN_PATH_SAMPLES

    def cost(poses, ks):
        m, k, n = poses.shape
        start = np.zeros((m, 1, n))
        start[:, 0, locked] = poses[:, 0, locked]
        legs = np.concatenate((start, poses), axis=1)
        path = (legs[:, :-1, None, :]
                + steps[:, None] * (legs[:, 1:] - legs[:, :-1])[:, :, None, :])
        ids = np.broadcast_to(rows.ids[ks][None, :, None], path.shape[:3]).reshape(-1)
        q_r, q_l = split_arms(robot, path.reshape(-1, n))
        value = checker.penalty(batch_forward(robot, q_r, 'right'),
                                batch_forward(robot, q_l, 'left'), ids)[0]
        return value.reshape(m, -1).mean(axis=1)
    return cost


def pose_values(robot, scorer, checker, q, ids):
    """
    Return the search's value of poses ``q`` (..., J) for targets ``ids`` (...,).

    The similarity score, plus the capsule penalty with a collision ``checker``: what
    the keyframe search minimises, without its ``stay_close`` pull.
    """
    shape = q.shape[:-1]
    q_r, q_l = split_arms(robot, q.reshape(-1, q.shape[-1]))
    ids = np.broadcast_to(ids, shape).reshape(-1)
    lm_r = batch_forward(robot, q_r, 'right')
    lm_l = batch_forward(robot, q_l, 'left')
    f = scorer.evaluate(lm_r, lm_l, ids)
    if checker is not None:
        f = f + checker.penalty(lm_r, lm_l, ids)[0]
    return f.reshape(shape)


def layout_columns(robot, layout) -> np.ndarray:
    """Return the columns of a free ``layout``'s (side, joint) pairs in both arms' angles."""
    first = {side: cols.start for side, cols in arm_columns(robot).items()}
    return np.array([first[s] + j for s, j in layout], dtype=int)


def joint_bounds(robot):
    """Return the (lower, upper) joint limits of both arms, (J,) each, right arm first."""
    return (np.concatenate([robot.arms[s].lower for s in ARMS]),
            np.concatenate([robot.arms[s].upper for s in ARMS]))


class _Motion(NamedTuple):
    """One motion being paced: its gesture (``owner``), its rows ``ks`` and their floors."""

    owner: int
    ks: np.ndarray
    floor: bool         # searched to their floors (:func:`_searched_to_floor`)


class _Reach(NamedTuple):
    """A motion's joint angles (K, J), step limits and joint bounds, as pacing reads them."""

    q: np.ndarray
    limits: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


def _pace(setup, rows, clock, rng):
    """
    Keep every motion of ``rows`` within the joints' velocity limits (in place).

    The rows of a motion (a gesture of several keyframes) are searched one keyframe
    each, so two of them may end in branches of the arm's redundancy too far apart for
    the joints to travel in the time between them.  A motion whose steps break the
    limits of :func:`.pacing.step_limits` is replaced by the best of
    :func:`.pacing.repair`'s feasible candidates (its own keyframes clipped into reach,
    the locked design, the design carried through each solved keyframe), then
    polished within :func:`.pacing.tube` boxes, in which every point stays feasible.
    The repair needs no time (it runs at the deadline too); the polish runs while
    ``clock`` allows.  ``rows.paced`` marks the rows repaired.
    """
    robot, scorer, checker = setup.robot, setup.scorer, setup.checker
    lower, upper = joint_bounds(robot)
    repaired = []
    owners = np.asarray(rows.owners)
    for owner in np.unique(owners):
        ks = np.nonzero(owners == owner)[0]
        if len(ks) < 2 or not _paced(setup, rows.selected[owner]):
            continue
        times = [kf.time_from_start for kf in rows.selected[owner].keyframes]
        ids = rows.ids[ks]
        design = np.concatenate((setup.ref_r[ids], setup.ref_l[ids]), axis=1)
        limits = pacing.step_limits(robot.joint_velocity_limits, times, design)
        q = np.concatenate((rows.right[ks], rows.left[ks]), axis=1)
        if pacing.feasible(q, limits):
            continue
        base = np.concatenate((rows.base_r[ks], rows.base_l[ks]), axis=1)
        motion = _Motion(owner, ks, _searched_to_floor(setup, rows, ks))
        extra = [] if motion.floor else _within_reach(
            setup, rows, motion, _Reach(q, limits, lower, upper), clock, rng)
        if not clock.expired():
            extra += list(_branch_restarts(setup, rows, motion,
                                           pacing.candidates(q, base, limits, lower, upper),
                                           clock))
        best, _ = pacing.repair(q, base, limits, lower, upper,
                                lambda c: pose_values(robot, scorer, checker, c, ids),
                                extra=extra)
        rows.right[ks], rows.left[ks] = split_arms(robot, best)
        rows.paced[ks] = True
        repaired.append((owner, ks, pacing.tube(best, limits, lower, upper)))
    if repaired and not clock.expired():
        _polish_in_tubes(setup, rows, repaired, clock)
    if repaired:
        rows.after = scorer.evaluate(rows.right, rows.left, rows.ids)


def _searched_to_floor(setup, rows, ks):
    """
    Return True if rows ``ks`` were searched to their floors: polished, not cut short.

    Then the repair needs no search within reach (:func:`_within_reach`): the branch
    restarts offer as good a motion.  Over every single fault x 10 seeds of Talos,
    TIAGo++ and Namo (60 repairs) a motion from within reach won 26 times, each time
    with the same worst keyframe as the best other candidate (to 1e-9; the sums 0.01
    apart at most), which the tubes' polish then takes to the same floor; the search
    cost 25-28 ms of the slowest faults' 110-150.  A search cut by the deadline or
    cancelled, or one without a polish (the paper's preset, or the tests' crippled
    colony), still searches within reach.
    """
    return bool(getattr(setup.algo, 'polish', 0)) and not any(
        rows.status[k] in CUT_SHORT for k in ks)


def _paced(setup, gesture):
    """Return True if the search keeps ``gesture`` within the velocity limits."""
    return _named(setup.paced, gesture.name)


def _motion_layout(setup, rows, owner, ks):
    """Return the free joints of one motion's rows (its stage-2 layout if it used one)."""
    if np.any(rows.stage[ks] == 2):
        return free_layout(setup.robot, rows.selected[owner].arms, setup.locked, set(ARMS))
    return rows.layouts[ks[0]]


def _motion_problem(setup, rows, ks, free):
    """Return the keyframe problem of rows ``ks`` with layout ``free``, as the search's."""
    ids = rows.ids[ks]
    anchor, pull = None, rows.stay_close[ks]
    if pull.any():
        col = layout_columns(setup.robot, free)
        anchor = np.concatenate((setup.ref_r[ids], setup.ref_l[ids]), axis=1)[:, col]
    return PoseProblem(setup.robot, setup.scorer, ids, (rows.right[ks], rows.left[ks]), free,
                       collision=setup.checker, anchor=anchor, continuity=pull)


def _within_reach(setup, rows, motion, reach, clock, rng):
    """
    Search every other keyframe again within its neighbours' reach; return the motions.

    ``motion`` is the :class:`_Motion`, ``reach`` its :class:`_Reach`.  For each
    parity, the keyframes of that parity may each move within the box its two kept
    neighbours allow (:func:`.pacing.reach_boxes`, the problem's bounds): a keyframe
    flipped into another branch finds the best pose its neighbours can reach in time,
    and every point searched is feasible.  The boxes of both parities depend on ``q``
    alone, so all of them are one batched search by the run's algorithm; each parity's
    results, with the other keyframes kept, make one motion.

    The search's polish is one batched call for all its starts, plain (a polish
    restarted from steepest descent crawls along the box faces to its iteration cap:
    on TIAGo++ with right joint 1 or 2 locked it made the paced runs 50-75 % slower and
    no run better, 12 faults x 6 seeds) and short (``REACH_MAXITER``): the search only
    offers candidates to :func:`.pacing.repair`, whose pick is polished again within
    its tubes (:func:`_polish_in_tubes`).  The paced faults were the slowest of both
    test robots (TIAGo++ right joints 1 and 2, Talos right joint 7: about 230 ms, 58 %
    of it in the repair, whose search had polished twice for 40 iterations: the
    colony's five starts, then the neighbours' two); see README "Other robots".
    """
    owner, ks, _ = motion
    q, limits, lower, upper = reach
    free = _motion_layout(setup, rows, owner, ks)
    parts = [pacing.reach_boxes(q, limits, lower, upper, parity) for parity in (0, 1)]
    parts = [p for p in parts if p is not None]
    if not free or not parts or clock.expired():
        return []
    col = layout_columns(setup.robot, free)
    picked = np.concatenate([p[0] for p in parts])
    problem = _motion_problem(setup, rows, ks[picked], free)
    problem.restrict(np.concatenate([p[1] for p in parts])[:, col],
                     np.concatenate([p[2] for p in parts])[:, col])
    res = minimize(problem, _unpolished(setup.algo), clock=clock,
                   seed=int(rng.integers(2 ** 63)))
    x, f = np.atleast_2d(res.x), np.atleast_1d(res.fun)
    # One plain polish of the colony's best, the known-good start and the kept
    # neighbours' own poses (starts in the branches they reach); see REACH_MAXITER.
    design = np.concatenate((setup.ref_r[rows.ids[ks]], setup.ref_l[rows.ids[ks]]), axis=1)
    near = [np.clip(picked + d, 0, len(q) - 1) for d in (-1, 1)]
    starts = np.stack([x, problem.x0] + [(q[n] + design[picked] - design[n])[:, col]
                                         for n in near], axis=1)
    px, pf = polish(problem, problem.clip(starts), clock, maxiter=REACH_MAXITER,
                    ftol=getattr(setup.algo, 'polish_ftol', 1e-7))
    pick = np.argmin(pf, axis=1)
    better = pf[np.arange(len(pf)), pick] < f
    x[better] = px[np.arange(len(px)), pick][better]
    out, first = [], 0
    for part_rows, _, _ in parts:
        found = q.copy()
        found[np.ix_(part_rows, col)] = x[first:first + len(part_rows)]
        first += len(part_rows)
        out.append(found)
    return out


def _branch_restarts(setup, rows, motion, starts, clock):
    """
    Polish a motion's keyframes from each feasible start; return the motions (M, K, J).

    Every start (N, K, J) puts the whole motion in one branch (e.g. the design carried
    through one solved keyframe); polishing each of its keyframes freely keeps them in
    that branch, so the polished motion is usually feasible, and a much better one than
    the start (the caller clips it into reach).  All starts of all keyframes are one
    batched polish.  ``motion`` is the :class:`_Motion`.

    The points after iterations ``RESTART_KEEP`` (those before the last) are returned
    too (M = N x the points kept): the polish is free and the repair clips its points
    into reach afterwards, so a longer polish is not a better motion once clipped.  On
    TIAGo++ with right joint 1 locked, Bye repaired from 1, 3, 5, 10 and 20 iterations
    scored 6.74, 6.59, 5.98, 6.37 and 6.82 (the best-known was 6.81).  After a search
    that polished its keyframes (the node's default) the restarts polish
    ``RESTART_MAXITER_POLISHED`` iterations: over every single fault x 5 seeds of Talos
    and TIAGo++ no Bye was worse than with 20, and the slowest faults' restarts took 7
    ms instead of 27-37.  After a search without a polish (the paper's preset) or cut
    short they polish ``RESTART_MAXITER``: there the restarts do the search's work
    (Namo's right joint 5 at one colony cycle: Bye within 1 % of the best-known at 15 of
    seeds 0-29 with 20 iterations, 3 with 5).
    """
    owner, ks, floor = motion
    free = _motion_layout(setup, rows, owner, ks)
    if not free:
        return ()
    col = layout_columns(setup.robot, free)
    problem = _motion_problem(setup, rows, ks, free)
    shots = []

    def keep(x):
        shots.append(x.copy())

    x, _ = polish(problem, problem.clip(np.swapaxes(starts[:, :, col], 0, 1)), clock,
                  maxiter=RESTART_MAXITER_POLISHED if floor else RESTART_MAXITER,
                  ftol=getattr(setup.algo, 'polish_ftol', 1e-7), callback=keep)
    kept = [shots[i - 1] for i in RESTART_KEEP if i < len(shots)] + [x]
    out = np.repeat(np.concatenate((rows.right[ks], rows.left[ks]), axis=1)[None],
                    len(starts) * len(kept), axis=0)
    out[:, :, col] = np.concatenate([np.swapaxes(xs, 0, 1) for xs in kept])
    return out


def _polish_in_tubes(setup, rows, repaired, clock):
    """Polish repaired motions, each keyframe within its box (one batch per layout)."""
    algo = setup.algo
    groups = {}
    for owner, ks, (low, high) in repaired:
        free = _motion_layout(setup, rows, owner, ks)
        if free:
            groups.setdefault(free, []).append((ks, low, high))
    for free, members in groups.items():
        ks = np.concatenate([m[0] for m in members])
        col = layout_columns(setup.robot, free)
        problem = _motion_problem(setup, rows, ks, free)
        problem.restrict(np.concatenate([m[1] for m in members])[:, col],
                         np.concatenate([m[2] for m in members])[:, col])
        x, _ = polish(problem, problem.x0[:, None, :], clock,
                      maxiter=getattr(algo, 'polish_maxiter', 100),
                      ftol=getattr(algo, 'polish_ftol', 1e-7))
        qr, ql = problem.assemble(x[:, 0][:, None])
        rows.right[ks], rows.left[ks] = qr[:, 0], ql[:, 0]


def _stage2(setup, rows, clock, rng):
    """Stage 2: the healthy arm joins in for two-handed gestures that are still poor."""
    robot, scorer, checker = setup.robot, setup.scorer, setup.checker
    best_r, best_l, after, ids = rows.right, rows.left, rows.after, rows.ids
    todo = [k for k in rows.two_stage
            if setup.bimanual == 'on' or after[k] > DEFAULT_BIMANUAL_THRESHOLD]
    if not todo:
        return
    lay2 = [free_layout(robot, rows.targets[k].arms, setup.locked, set(ARMS)) for k in todo]
    x0 = {}
    for i, k in enumerate(todo):
        x0[i] = [(best_r if s == 'right' else best_l)[k, j] for s, j in lay2[i]]
    batch = _Batch(best_r[todo], best_l[todo], ids[todo], lay2, x0,
                   motions=[rows.motions[k] for k in todo])
    r2, l2, st2 = _solve(robot, scorer, checker, batch, setup.algo, clock, rng)
    f2 = scorer.evaluate(r2, l2, ids[todo])
    for i, k in enumerate(todo):
        if f2[i] < after[k] and _no_worse_collision(checker, r2[i], l2[i],
                                                    best_r[k], best_l[k], ids[k]):
            best_r[k], best_l[k], after[k] = r2[i], l2[i], f2[i]
            rows.stage[k] = 2
        if st2[i] in CUT_SHORT:
            rows.status[k] = st2[i]


def _clear_idle_arms(setup, rows, clock, rng):
    """
    Move a faulted arm that a gesture does not use out of the body; return those rows.

    A gesture scores only the arms it uses, so a faulted arm it does not use holds its
    reference pose with the locks applied, and that pose may run into the body: Talos's
    left elbow held at the average of its gestures (-119 deg) puts the resting forearm
    into the torso during every right-arm gesture.  Such rows are solved again on the
    idle arm's healthy joints alone: the collision term pushes it clear, and the
    ``stay_close`` pull keeps it as near its reference pose as it can be.  The score
    does not change (the arm is not scored).  Rows whose idle arm holds the same pose
    are solved once (:func:`_move_rows` on the first, :func:`_take_idle_pose` for the
    others where it is clear with their own moving arm).  Each is first pushed out
    from where it is by a short polish (``PUSH_MAXITER``, the torso's shape included,
    :mod:`..model.torso_field`), and searched only where the push leaves it touching
    (:func:`_search_idle`).  Returns a mask of the rows moved.
    """
    robot, checker = setup.robot, setup.checker
    done = np.zeros(len(rows.ids), dtype=bool)
    if checker is None:
        return done
    idle = {k: tuple(s for s in setup.faulted if s not in t.arms and s not in setup.frozen)
            for k, t in enumerate(rows.targets)}
    todo = [k for k, sides in idle.items() if sides]
    if not todo:
        return done
    hit = _rows_collide(checker, robot, rows.right[todo], rows.left[todo], rows.ids[todo])
    todo = [k for k, h in zip(todo, hit) if h]
    if not todo:
        return done
    # Rows whose idle arm holds one pose (a resting arm, through every one-armed
    # gesture) are solved once, on the first of them; the others take that pose where
    # it is clear with their own moving arm, and are solved themselves where it is not.
    first = {}
    for k in todo:
        first.setdefault(_idle_key(rows, idle[k], k), k)
    _move_rows(setup, rows, idle, sorted(first.values()), done, clock, rng,
               share_branches=False)
    _take_idle_pose(setup, rows, idle, [(k, first[_idle_key(rows, idle[k], k)])
                                        for k in todo if not done[k]], done)
    _move_rows(setup, rows, idle, [k for k in todo if not done[k]], done, clock, rng)
    _hold_idle_still(setup, rows, idle, done)
    if done.any():
        rows.after[done] = setup.scorer.evaluate(rows.right[done], rows.left[done],
                                                 rows.ids[done])
    return done


def _idle_key(rows, sides, k):
    """Return what identifies row ``k``'s idle-arm problem: its arms and their poses."""
    arm = {'right': rows.right, 'left': rows.left}
    return (sides, angle_bytes(arm[s][k] for s in sides))


def _move_rows(setup, rows, idle, ks, done, clock, rng, share_branches=True):
    """Move the idle arm of rows ``ks`` out of the body; mark the rows cleared in ``done``."""
    if not ks or clock.expired():
        return
    robot = setup.robot
    lay = [free_layout(robot, idle[k], setup.locked, setup.faulted) for k in ks]
    # With the collision term from the start: the arm is not scored, so the plain
    # search would only find the colliding reference pose again (the stay_close pull).
    batch = _Batch(rows.right[ks], rows.left[ks], rows.ids[ks], lay,
                   stay_close=IDLE_STAY_CLOSE,
                   motions=[rows.motions[k] if share_branches else -1 for k in ks])
    r2, l2, clear = _move_idle(setup, batch, clock, rng)
    for i, k in enumerate(ks):
        if clear[i]:
            rows.right[k], rows.left[k] = r2[i], l2[i]
            done[k] = True


def _take_idle_pose(setup, rows, idle, pairs, done):
    """Give each row of ``pairs`` (row, solved row) the solved row's idle arm if clear."""
    pairs = [(k, j) for k, j in pairs if done[j]]
    if not pairs:
        return
    ks = [k for k, _ in pairs]
    trial = {'right': rows.right[ks].copy(), 'left': rows.left[ks].copy()}
    for i, (k, j) in enumerate(pairs):
        for s in idle[k]:
            trial[s][i] = (rows.right if s == 'right' else rows.left)[j]
    clear = ~_rows_collide(setup.checker, setup.robot, trial['right'], trial['left'],
                           rows.ids[ks])
    for i, k in enumerate(ks):
        if clear[i]:
            rows.right[k], rows.left[k] = trial['right'][i], trial['left'][i]
            done[k] = True


def _move_idle(setup, batch, clock, rng):
    """
    Return (right, left, clear) of idle-arm rows moved out of the body.

    A local push out of the body (the torso's shape included) from the locked pose;
    the rows it leaves touching are searched (:func:`_search_idle`).  With Talos's or
    TIAGo++'s left elbow stuck, the push alone clears every row.
    """
    robot, checker, ids = setup.robot, setup.checker, batch.target_ids
    # First a push out of the body from the locked pose: most idle arms only rest a
    # little inside it, and the nearest clear pose is a local step away.
    r2, l2 = _push_out(setup, batch, checker.shaped(), clock)
    clear = ~_rows_collide(checker, robot, r2, l2, ids)     # the shape is in every check
    if clear.all() or clock.expired():
        return r2, l2, clear
    rest = np.nonzero(~clear)[0]
    sub = _Batch(batch.right[rest], batch.left[rest], ids[rest],
                 [batch.layouts[i] for i in rest], stay_close=IDLE_STAY_CLOSE,
                 motions=batch.motions[rest])
    r2[rest], l2[rest], clear[rest] = _search_idle(setup, sub, clock, rng)
    return r2, l2, clear


def _search_idle(setup, batch, clock, rng):
    """
    Return (right, left, clear) of idle-arm rows searched out of the body.

    The search on the capsules; then, where the torso's own shape is still touched
    (:mod:`..model.torso_field`), a local push out of it on the shaped model from there,
    and the search on it for the rows the push leaves touching.
    """
    robot, checker, ids = setup.robot, setup.checker, batch.target_ids
    r2, l2, _ = _solve_once(robot, setup.scorer, checker, batch,
                            _repair_algorithm(setup.algo), clock, rng)
    lm_r, lm_l = batch_forward(robot, r2, 'right'), batch_forward(robot, l2, 'left')
    collides, shape_hits = checker.verdicts(lm_r, lm_l, ids)
    inside = np.nonzero(shape_hits)[0]
    if len(inside) and not clock.expired():
        sub = _Batch(r2[inside], l2[inside], ids[inside],
                     [batch.layouts[i] for i in inside], stay_close=IDLE_STAY_CLOSE)
        r2[inside], l2[inside] = _push_out(setup, sub, checker.shaped(), clock)
        collides[inside] = _rows_collide(checker, robot, r2[inside], l2[inside], ids[inside])
    clear = ~collides
    stuck = np.intersect1d(inside, np.nonzero(~clear)[0])
    if len(stuck) and not clock.expired():    # pushed against something else: search
        sub = _Batch(batch.right[stuck], batch.left[stuck], ids[stuck],
                     [batch.layouts[i] for i in stuck], stay_close=IDLE_STAY_CLOSE)
        r2[stuck], l2[stuck], _ = _solve_once(robot, setup.scorer, checker.shaped(), sub,
                                              _repair_algorithm(setup.algo), clock, rng)
        clear = ~_rows_collide(checker, robot, r2, l2, ids)
    return r2, l2, clear


def _push_out(setup, batch, checker, clock):
    """Return (right, left) of ``batch``'s rows polished from their poses on ``checker``."""
    robot, scorer = setup.robot, setup.scorer
    right, left = batch.right.copy(), batch.left.copy()
    groups = {}
    for k, free in enumerate(batch.layouts):
        groups.setdefault(free, []).append(k)
    for free, members in groups.items():
        problem, _ = _rows_problem(robot, scorer, checker, batch, free, members)
        x, _ = polish(problem, problem.x0[:, None, :], clock, maxiter=PUSH_MAXITER,
                      restart=True)
        qr, ql = problem.assemble(x[:, 0])
        right[members], left[members] = qr, ql
    return right, left


def _cleared_note(setup, cleared):
    """Return the note (a list of at most one) naming the gestures whose idle arm moved."""
    if not cleared.any():
        return []
    moved = sorted({setup.selected[setup.owners[k]].name for k in np.nonzero(cleared)[0]})
    return [f'the faulted arm these gestures do not use was moved clear of the body (its '
            f'locked reference pose collides): {", ".join(moved)}']


def _hold_idle_still(setup, rows, idle, done):
    """
    Give the idle arm one correction over each gesture: the same offset at every point.

    Each keyframe's clearance is solved alone and ends somewhere different on the edge
    of contact: the arm would twitch between keyframes, and a dense motion's Kriging
    would blend clear poses into touching ones (Namo's circle with left joint 2 locked).
    Of the corrections found (pose minus locked design), the smallest that is clear at
    every keyframe of the gesture is applied to all of them, so an idle arm whose design
    holds still holds still (in place; ``done`` marks the rows moved).
    """
    robot, checker = setup.robot, setup.checker
    owners = np.asarray(rows.owners)
    arm = {'right': rows.right, 'left': rows.left}
    design = {'right': rows.base_r, 'left': rows.base_l}
    for m in np.unique(owners[done]):
        ks = np.nonzero(owners == m)[0]
        sides = idle[ks[0]]
        offsets = [{s: arm[s][k] - design[s][k] for s in sides} for k in ks if done[k]]
        offsets.sort(key=lambda o: sum(np.abs(v).sum() for v in o.values()))
        for offset in offsets:
            trial = {s: arm[s][ks].copy() for s in ARMS}
            for s in sides:
                trial[s] = robot.arms[s].clip(design[s][ks] + offset[s])
            if not _rows_collide(checker, robot, trial['right'], trial['left'],
                                 rows.ids[ks]).any():
                for s in sides:
                    arm[s][ks] = trial[s]
                done[ks] = True
                break


def _take(out, c, n_t):
    """Return lock set ``c``'s rows of a :func:`_run` output."""
    rows = slice(c * n_t, (c + 1) * n_t)
    return {key: value[rows] for key, value in out.items()}


def _path_figures(setup, out, ks):
    """
    Return the fingertip, joint-step and speed figures of one gesture's rows ``ks``.

    The same figures as a whole motion's (:func:`.figures.describe_motion`), over the
    keyframes this search solved: fingertip distance to the designed keyframe (mm, the
    worse hand), the largest joint step between successive keyframes (deg) and the
    playability figure :func:`.pacing.speed_ratio`.
    """
    scorer, rows = setup.scorer, np.asarray(ks)
    design = np.concatenate((setup.ref_r[rows], setup.ref_l[rows]), axis=1)
    base = np.concatenate((out['base_right'][rows], out['base_left'][rows]), axis=1)
    best = np.concatenate((out['right'][rows], out['left'][rows]), axis=1)
    err_before = scorer.tip_error(out['base_right'][rows], out['base_left'][rows], rows)
    err_after = scorer.tip_error(out['right'][rows], out['left'][rows], rows)
    times = [kf.time_from_start for kf in setup.selected[setup.owners[rows[0]]].keyframes]
    return {'speed_ratio': pacing.speed_ratio(setup.robot.joint_velocity_limits, times, best),
            'tip_error_before_mm': float(err_before.mean()),
            'tip_error_mm': float(err_after.mean()), 'tip_error_max_mm': float(err_after.max()),
            'max_jump_designed_deg': largest_jump(design),
            'max_jump_before_deg': largest_jump(base), 'max_jump_deg': largest_jump(best)}


def _library_result(setup, locks, out, notes, wall, nfev):
    """Describe one lock set's solved rows as a :class:`~.result.LibraryResult`."""
    robot, scorer, checker, settings = setup.robot, setup.scorer, setup.checker, setup.settings
    targets, owners = setup.targets, setup.owners
    ids = np.arange(len(targets))
    best_r, best_l, after = out['right'], out['left'], out['after']
    before = scorer.evaluate(out['base_right'], out['base_left'], ids)
    _, parts = scorer.evaluate(best_r, best_l, ids, breakdown=True)
    collides = [False] * len(targets)
    pairs = [()] * len(targets)
    if checker is not None:
        lm_r, lm_l = batch_forward(robot, best_r, 'right'), batch_forward(robot, best_l, 'left')
        collides = [bool(c) for c in checker.collides(lm_r, lm_l, ids)]
        pairs = [tuple(p) for p in checker.colliding_pairs(lm_r, lm_l, ids)]
    results = []
    for gi, gesture in enumerate(setup.selected):
        ks = [k for k in range(len(targets)) if owners[k] == gi]
        worst = max(ks, key=lambda k: after[k])
        st = _worst_status([out['status'][k] for k in ks])
        stage_used = int(max(out['stage'][k] for k in ks))
        free = (out['layouts'][ks[0]] if stage_used == 1
                else free_layout(robot, gesture.arms, setup.locked, set(ARMS)))
        hit = any(collides[k] for k in ks)
        results.append(GestureResult(
            name=gesture.name,
            times=tuple(float(kf.time_from_start) for kf in gesture.keyframes),
            positions=tuple(tuple(float(a) for a in np.concatenate((best_r[k], best_l[k])))
                            for k in ks),
            right_joints=len(best_r[ks[0]]),
            score_before=float(max(before[k] for k in ks)),
            score_after=float(after[worst]),
            breakdown={c: float(v[worst]) for c, v in parts.items()
                       if c not in ('right', 'left')},
            wall_time=wall, status=st,
            message=_message(gesture.name, st, stage_used, checker is not None and hit),
            free_joints=tuple(robot.arms[s].joint_names[j] for s, j in free),
            stage=stage_used, stage1_score=float(max(out['stage1'][k] for k in ks)),
            collides=hit, colliding_pairs=tuple(p for k in ks for p in pairs[k]),
            expansion_stage=int(max(out['expansion'][k] for k in ks)),
            score_before_mean=float(np.mean([before[k] for k in ks])),
            score_mean=float(np.mean([after[k] for k in ks])),
            typical_points=len(ks), typical_indices=tuple(range(len(ks))),
            nfev=int(round(nfev * len(ks) / max(1, len(targets)))),
            **_path_figures(setup, out, ks)))
    notes = list(notes) + [f'{setup.selected[g].name}: {PACED_NOTE}'
                           for g in sorted({owners[k] for k in ids if out['paced'][k]})]
    deadline_met = not any(g.status in CUT_SHORT for g in results)
    return LibraryResult(
        gestures=tuple(results), faults=setup.faults,
        locks={j: float(a) for j, a in locks.items()}, frozen_arms=setup.frozen,
        wall_time=wall, deadline=setup.budget, deadline_met=deadline_met,
        success=deadline_met and all(np.isfinite(g.score_after) for g in results),
        cancelled=any(g.status == 'cancelled' for g in results),
        settings=settings.public(), tool_mm=float(settings.tool_length_mm),
        tool_arm=settings.tool_arm, seed=setup.seed, notes=tuple(notes), nfev=nfev,
        origin='unbounded' if setup.budget is None else 'deadline')


def _expand(setup, rows, clock, rng, stats):
    """
    Staged DOF expansion: redo a gesture's keyframes with its next ``expand`` stage.

    A gesture moves to its next stage while the fingertip of one of its keyframes is
    more than ``DEFAULT_EXPANSION_THRESHOLD`` mm from its target (it cannot be reached
    well enough); each stage starts from the previous stage's result and adds joints
    in the configured priority order.  ``rows.motions`` says which rows share branches
    (see :class:`_Batch`).  The layouts, the poses, ``after`` and ``status`` of
    ``rows`` are updated in place, and ``rows.expansion`` gets the stage reached per
    keyframe.
    """
    robot, scorer, checker, algo = setup.robot, setup.scorer, setup.checker, setup.algo
    selected, owners, layouts = rows.selected, rows.owners, rows.layouts
    best_r, best_l, after, status, ids = rows.right, rows.left, rows.after, rows.status, rows.ids
    threshold = DEFAULT_EXPANSION_THRESHOLD
    allowed = [None if a is None else set(a) for a in rows.designed]
    for level in range(1, 1 + max(len(selected[g].expand) for g in owners)):
        reach = scorer.tip_error(best_r, best_l, ids)
        todo = []
        for gi, gesture in enumerate(selected):
            ks = [k for k in range(len(rows.targets)) if owners[k] == gi]
            if (len(gesture.expand) >= level and any(layouts[k] for k in ks)
                    and max(reach[k] for k in ks) > threshold):
                todo += ks
        if not todo:
            break
        lay = []
        for k in todo:
            allowed[k] |= joint_set(robot, selected[owners[k]].expand[level - 1])
            lay.append(free_layout(robot, rows.targets[k].arms, setup.locked, setup.faulted,
                                   allowed[k]))
        x0 = {i: [(best_r if s == 'right' else best_l)[k, j] for s, j in lay[i]]
              for i, k in enumerate(todo)}
        later = any(len(selected[g].expand) > level for g in owners)
        stage_clock = clock.child(share=STAGE1_SHARE if (later or rows.two_stage) else 1.0)
        batch = _Batch(best_r[todo], best_l[todo], ids[todo], lay, x0, rows.stay_close[todo],
                       [rows.motions[k] for k in todo])
        r2, l2, st2 = _solve(robot, scorer, checker, batch, algo, stage_clock, rng, stats)
        f2 = scorer.evaluate(r2, l2, ids[todo])
        for i, k in enumerate(todo):
            layouts[k] = lay[i]
            rows.expansion[k] = level
            if f2[i] <= after[k]:
                best_r[k], best_l[k], after[k] = r2[i], l2[i], f2[i]
            if st2[i] in CUT_SHORT or status[k] == 'unchanged':
                status[k] = st2[i]


def locked_sets(robot, locks):
    """Return ``{arm: [joint indices locked]}`` for a ``{joint: angle}`` lock set."""
    out = {side: [] for side in ARMS}
    for joint in locks:
        side, j = robot.locate_joint(joint)
        out[side].append(j)
    return out


def apply_locks(robot, ref_r, ref_l, locks):
    base = {'right': ref_r.copy(), 'left': ref_l.copy()}
    for joint, angle in locks.items():
        side, j = robot.locate_joint(joint)
        base[side][..., j] = angle
    return base['right'], base['left']


def _rows_collide(checker, robot, right, left, ids):
    """Return a bool per row: the poses ``right``/``left`` (rad) touch (``checker.collides``)."""
    return checker.collides(batch_forward(robot, right, 'right'),
                            batch_forward(robot, left, 'left'), ids)


def _no_worse_collision(checker, r_new, l_new, r_old, l_old, k):
    if checker is None:
        return True
    pen = [checker.penetration(batch_forward(checker.robot, r[None], 'right'),
                               batch_forward(checker.robot, left[None], 'left'), np.array([k]))
           .sum() for r, left in ((r_new, l_new), (r_old, l_old))]
    return pen[0] <= pen[1] + 1e-9


def lock_candidates(robot, joint, n=LOCK_CANDIDATES):
    """Return ``n`` lock angles spread over a joint's range (its coarse sweep)."""
    side, j = robot.locate_joint(joint)
    lo, hi = robot.arms[side].lower[j], robot.arms[side].upper[j]
    return np.linspace(lo, hi, n, endpoint=hi - lo < 2 * np.pi - 1e-9)


def _optimise_locks(setup, locks, first, joints, rng, clock, stats):
    """
    Choose lock angles for ``joints`` that minimise the library total.

    ``first`` is the solved library at ``locks`` (the start, e.g. the average): it is a
    candidate, never solved again, and wins ties.  Each joint in turn: a coarse sweep
    over its range, then a finer one around the best, the candidates of a sweep solved
    in one batched :func:`_run` on the very problem of the final result (same layouts,
    expansion, collision term, stage 2, ``stay_close``), each scored by the library
    total (the sum of its gestures' ``score_after``).  The best solved candidate is the
    result: no final run can undo the choice.  Returns (locks, its rows, a note).
    """
    robot = setup.robot
    start_locks = dict(locks)
    start_total = float(setup.totals(first['after'], 1)[0])
    best_total, best_locks, best_out = start_total, dict(locks), first
    cut = False
    # Scores are distances: nothing does better than a start that scores 0.
    for jn, joint in enumerate(joints if start_total > 0.0 else ()):
        side, j = robot.locate_joint(joint)
        lo, hi = robot.arms[side].lower[j], robot.arms[side].upper[j]
        candidates = lock_candidates(robot, joint)
        for sweep in range(2):
            if clock.expired():
                cut = True
                break
            # The time left, shared evenly by the sweeps left.
            sweep_clock = clock.child(share=1.0 / (2 * len(joints) - (2 * jn + sweep)))
            tried = [float(a) for a in np.unique(candidates) if a != best_locks[joint]]
            if tried:
                sets = [dict(best_locks, **{joint: a}) for a in tried]
                out = _run(setup, sets, rng, sweep_clock, stats)
                totals = setup.totals(out['after'], len(sets))
                c = int(np.argmin(totals))
                if totals[c] < best_total:
                    best_total, best_locks = float(totals[c]), sets[c]
                    best_out = _take(out, c, len(setup.targets))
            step = (hi - lo) / LOCK_CANDIDATES
            candidates = np.clip(best_locks[joint] + np.linspace(-step, step, 7), lo, hi)
    chosen = ', '.join(f'{j} = {np.degrees(best_locks[j]):.2f} deg' for j in joints)
    start = ', '.join(f'{np.degrees(start_locks[j]):.2f} deg' for j in joints)
    note = (f'optimal lock: {chosen} (library total {best_total:.3f}; at the start '
            f'{start}: {start_total:.3f})')
    if cut:
        note += '; the deadline cut the search for other angles short'
    return best_locks, best_out, note


_STATUS_ORDER = ('cancelled', 'deadline', 'frozen', 'converged', 'unchanged')


def _worst_status(statuses):
    return min(statuses, key=_STATUS_ORDER.index)


def _message(name, status, stage, collides):
    text = {
        'converged': f'{name}: reconfigured',
        'deadline': f'{name}: deadline reached, best result so far used',
        'cancelled': f'{name}: cancelled, best result so far used',
        'frozen': f'{name}: the faulted arm has no free joint left; frozen at its locks',
        'unchanged': f'{name}: not affected by the faults',
    }[status]
    if stage == 2:
        text += '; the healthy arm moves too (stage 2)'
    if collides:
        text += f'; {COLLIDES_WARNING}'
    return text
