"""
Reconfigure gestures for a fault set: build the bounded problems and solve them.

For every keyframe of every gesture the failed joints are set to their lock angles and
the remaining joints of the faulted arms that take part in the gesture become the free
variables.  Keyframes with the same free-variable layout are solved together as one
batched problem (one objective call per optimiser phase for all of them), within one
wall-clock budget for the whole library.
"""

from dataclasses import dataclass, field
import time

import numpy as np

from .faults import resolve_locks
from .gestures import Keyframe
from .kinematics import forward_kinematics
from .optimize import make_algorithm, minimize, Problem, STATUS_CANCELLED, STATUS_DEADLINE
from .robot_model import ARMS, N_JOINTS
from .score import gesture_targets, SimilarityScore

_STATUS_NAMES = {0: 'converged', STATUS_DEADLINE: 'deadline', STATUS_CANCELLED: 'cancelled'}


class PoseProblem(Problem):
    """
    The free joints of some arms, for a batch of targets, scored against each target.

    ``base_right``/``base_left`` (T, 7) are the reference poses with failed joints at
    their locks; ``free`` is a tuple of ``(arm, joint index)`` giving the variables.
    """

    def __init__(self, robot, scorer, target_ids, base_right, base_left, free, smooth=0.01):
        if not free:
            raise ValueError('PoseProblem: no free joint to optimise')
        self.robot = robot
        self.scorer = scorer
        self.smooth = float(smooth)
        self.target_ids = np.asarray(target_ids, dtype=int)
        self.base = {'right': np.asarray(base_right, dtype=float),
                     'left': np.asarray(base_left, dtype=float)}
        # base holds the reference angles, so x0 (the free joints' reference) is a start.
        self.free = tuple(free)
        self.columns = {side: [(k, j) for k, (s, j) in enumerate(self.free) if s == side]
                        for side in ARMS}
        lower = [robot.arms[s].lower[j] for s, j in self.free]
        upper = [robot.arms[s].upper[j] for s, j in self.free]
        # An arm without free joints does not move: its landmarks are computed once.
        # It is indexed by target id, as the scorer indexes per-target landmarks.
        self.fixed = {}
        for side in ARMS:
            if not self.columns[side]:
                q = np.zeros((self.target_ids.max() + 1, N_JOINTS))
                q[self.target_ids] = self.base[side]
                self.fixed[side] = forward_kinematics(robot, q, side)
        x0 = [[self.base[s][t, j] for s, j in self.free] for t in range(len(self.target_ids))]
        super().__init__(lower, upper, self._objective, n_batch=len(self.target_ids), x0=x0,
                         value_and_grad=self._value_and_grad)

    def assemble(self, x):
        """Return full (right, left) angles of shape (..., 7) for variables x (T, ..., D)."""
        x = np.asarray(x, dtype=float)
        extra = x.ndim - 2
        out = {}
        for side in ARMS:
            base = self.base[side].reshape((-1,) + (1,) * extra + (N_JOINTS,))
            q = np.broadcast_to(base, x.shape[:-1] + (N_JOINTS,)).copy()
            for k, j in self.columns[side]:
                q[..., j] = x[..., k]
            out[side] = q
        return out['right'], out['left']

    def _objective(self, x):
        batch, n, _ = x.shape
        q_right, q_left = self.assemble(x)
        target = np.repeat(self.target_ids, n)
        right = self.fixed.get('right', q_right.reshape(-1, N_JOINTS))
        left = self.fixed.get('left', q_left.reshape(-1, N_JOINTS))
        return self.scorer.evaluate(right, left, target).reshape(batch, n)

    def _value_and_grad(self, x):
        batch, n, dim = x.shape
        q_right, q_left = self.assemble(x)
        target = np.repeat(self.target_ids, n)
        right = self.fixed.get('right', q_right.reshape(-1, N_JOINTS))
        left = self.fixed.get('left', q_left.reshape(-1, N_JOINTS))
        f, g_right, g_left = self.scorer.value_and_grad(right, left, target, self.smooth)
        grad = np.empty((batch * n, dim))
        for side, g in (('right', g_right), ('left', g_left)):
            for k, j in self.columns[side]:
                grad[:, k] = g[:, j]
        return f.reshape(batch, n), grad.reshape(batch, n, dim)


@dataclass
class GestureReconfiguration:
    """The outcome for one gesture of the library."""

    name: str
    keyframes: tuple
    score_before: float
    score_after: float
    breakdown: dict
    wall_time: float
    status: str
    message: str
    free_joints: tuple = ()
    stage: int = 1
    collides: object = None   # None: not checked (the collision model is not enabled)


@dataclass
class LibraryReconfiguration:
    """The outcome for the whole library."""

    gestures: list
    locks: dict
    frozen_arms: tuple
    wall_time: float
    deadline: object
    seed: int
    algorithm: str
    preset: str = 'default'
    notes: list = field(default_factory=list)

    @property
    def cancelled(self):
        """Return True if any gesture was cut short by a cancel request."""
        return any(g.status == 'cancelled' for g in self.gestures)

    @property
    def deadline_met(self):
        """Return True if no gesture hit the deadline."""
        return not any(g.status in ('deadline', 'cancelled') for g in self.gestures)

    @property
    def success(self):
        """Return True if every gesture has a finite score within the deadline."""
        return self.deadline_met and all(np.isfinite(g.score_after) for g in self.gestures)

    def __getitem__(self, name):
        for g in self.gestures:
            if g.name == name:
                return g
        raise KeyError(f'unknown gesture {name!r}')


def reconfigure_library(robot, library, faults, *, algorithm='abc', preset='default',
                        deadline=1.0, seed=None, weights=None, lock_strategy='average',
                        measured=None, cancel=None, gestures=None, settings=None):
    """
    Reconfigure every gesture (or those named in ``gestures``) for a fault set.

    ``faults`` maps joint names to lock angles (rad) or None (chosen by
    ``lock_strategy``).  ``deadline`` (s) is the budget for the whole library.  The
    result is a pure function of the inputs and ``seed`` (None draws one, reported in
    the result), up to where a deadline cuts the search.
    """
    start = time.monotonic()
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    algo = make_algorithm(algorithm, preset, **(settings or {}))
    locks, notes = resolve_locks(robot, library, faults, lock_strategy, measured)
    selected = list(library) if gestures is None else [library[g] for g in gestures]
    frozen = tuple(side for side in ARMS
                   if all(j in locks for j in robot.arms[side].joint_names))
    for side in frozen:
        notes.append(f'all joints of the {side} arm failed: it is frozen at its lock angles')

    targets, owners = [], []
    for gi, gesture in enumerate(selected):
        for t in gesture_targets(gesture):
            targets.append(t)
            owners.append(gi)
    scorer = SimilarityScore(robot, targets, weights)
    base = {side: np.array([getattr(t, f'q_{side}') for t in targets]) for side in ARMS}
    locked = {side: [] for side in ARMS}
    for joint, angle in locks.items():
        side, j = robot.locate_joint(joint)
        base[side][:, j] = angle
        locked[side].append(j)
    ids = np.arange(len(targets))
    before = scorer(base['right'], base['left'], target=ids)
    after = before.copy()
    best_r, best_l = base['right'].copy(), base['left'].copy()
    status = ['unchanged'] * len(targets)
    free_of = []
    for t in targets:
        moving = [s for s in ARMS if s in t.arms and locked[s]]
        free_of.append(tuple((s, j) for s in moving for j in range(N_JOINTS)
                             if j not in locked[s]))
        if moving and not free_of[-1]:
            status[len(free_of) - 1] = 'frozen'

    groups = {}
    for k, free in enumerate(free_of):
        if free:
            groups.setdefault(free, []).append(k)
    rng = np.random.default_rng(seed)
    remaining_targets = sum(len(v) for v in groups.values())
    for free, members in groups.items():
        budget = None
        if deadline is not None:
            left = deadline - (time.monotonic() - start)
            budget = max(left * len(members) / remaining_targets, 0.0)
        remaining_targets -= len(members)
        problem = PoseProblem(robot, scorer, members, base['right'][members],
                              base['left'][members], free)
        res = minimize(problem, algo, deadline=budget, cancel=cancel,
                       seed=int(rng.integers(2 ** 63)))
        x = np.atleast_2d(res.x)
        qr, ql = problem.assemble(x)
        f = np.atleast_1d(res.fun)
        for i, k in enumerate(members):
            if f[i] <= after[k]:
                after[k], best_r[k], best_l[k] = f[i], qr[i], ql[i]
            status[k] = _STATUS_NAMES[res.status]

    _, parts = scorer(best_r, best_l, target=ids, breakdown=True)
    wall = time.monotonic() - start
    results = []
    for gi, gesture in enumerate(selected):
        ks = [k for k in range(len(targets)) if owners[k] == gi]
        worst = max(ks, key=lambda k: after[k])
        frames = tuple(Keyframe(kf.time_from_start, best_r[k].copy(), best_l[k].copy())
                       for kf, k in zip(gesture.keyframes, ks))
        st = _worst_status([status[k] for k in ks])
        results.append(GestureReconfiguration(
            name=gesture.name, keyframes=frames,
            score_before=float(max(before[k] for k in ks)),
            score_after=float(after[worst]),
            breakdown={c: float(v[worst]) for c, v in parts.items()
                       if c not in ('right', 'left')},
            wall_time=wall, status=st, message=_message(gesture.name, st),
            free_joints=tuple(robot.arms[s].joint_names[j] for s, j in free_of[ks[0]])))
    return LibraryReconfiguration(results, locks, frozen, wall, deadline, seed, algo.name,
                                  preset, notes)


_STATUS_ORDER = ('cancelled', 'deadline', 'frozen', 'converged', 'unchanged')


def _worst_status(statuses):
    return min(statuses, key=_STATUS_ORDER.index)


def _message(name, status):
    return {
        'converged': f'{name}: reconfigured',
        'deadline': f'{name}: deadline reached, best result so far used',
        'cancelled': f'{name}: cancelled, best result so far used',
        'frozen': f'{name}: the faulted arm has no free joint left; frozen at its locks',
        'unchanged': f'{name}: not affected by the faults',
    }[status]
