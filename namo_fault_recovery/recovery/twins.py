"""
Of a solved pose and its kinematic twins, the one the arm reaches clear (the same score).

Three joints of an arm whose axes meet reach every orientation twice
(:func:`~..model.kinematics.equivalent_twins`): the outer joints turned by half a turn,
the middle one mirrored.  Every landmark is the same in both, and so is the score, so
the keyframe search ends on either by the luck of its draws.  The arm, though, plays
the gesture from where it is, and the twin far from the design swings half a turn to
get there.  Namo's wai with the right elbow stuck at 44.8 deg ended, in 3 of 30 seeds,
with the shoulder at (-131, 158, 139) deg instead of its twin (49, 22, -41): the same
score, but the path from rest went 122 mm through the torso, and on the simulator the
arm pressed the torso until a healthy joint read as stuck (``bench carry-on`` over 30
seeds: 59 self-contact events and 7 failed plays before, none after).

:func:`best_twins` gives each gesture one combination of twins for all its keyframes
(so that a motion stays on one branch), within the joint limits, where no keyframe's
value (score plus the capsule penalty) gets worse: of the combinations, the one whose
path from rest presses the body least (``path_cost``: the caller's capsule model along
the straight path through the keyframes), then the one nearest the design in joint
space.  A twin that turns a locked joint is no candidate alone, but two that share it
turn it by a whole turn: Namo's wai with right joint 3 stuck at 15 deg ended, at 4
seeds of 8, across the shoulder's and the elbow's twins at once (and the wrist's at 3 of
them; the path from rest 143 mm through the torso), and that branch is the nearer to
the design in joint space (the elbow at +90 as designed), so the path decides, not the
distance.  It runs after the search, before the pacing: about 2 % of a run.
"""

from itertools import combinations
from typing import Callable, Optional

import numpy as np

from ..model.kinematics import arm_columns, equivalent_twins
from ..model.robot import ARMS

TWIN_TOLERANCE = 1e-6     # a twin's value may differ from its pose's by rounding only
_TURNS = np.array([0.0, 2 * np.pi, -2 * np.pi])


def twin_angles(q: np.ndarray, triple: tuple, mirror: float, design: np.ndarray,
                lower: np.ndarray, upper: np.ndarray) -> Optional[np.ndarray]:
    """
    Return ``q`` (rows, J) with one twin ``triple`` (3 columns) taken, or None.

    Each of the three joints reads its twin angle (outer: plus half a turn; middle:
    ``mirror`` minus it) by whichever full turn lies within its limits, nearest
    ``design`` (rows, J); None where some row has no such reading.
    """
    out = np.array(q, dtype=float)
    outer, middle, other = triple
    for column, angle in ((outer, out[:, outer] + np.pi), (middle, mirror - out[:, middle]),
                          (other, out[:, other] + np.pi)):
        readings = angle[:, None] + _TURNS
        inside = (readings >= lower[column]) & (readings <= upper[column])
        if not np.all(inside.any(axis=1)):
            return None
        gap = np.where(inside, np.abs(readings - design[:, column, None]), np.inf)
        out[:, column] = readings[np.arange(len(out)), np.argmin(gap, axis=1)]
    return out


def pose_twins(problem, x: np.ndarray) -> np.ndarray:
    """
    Return the single twins of each row of ``x`` (B, D), a PoseProblem's free joints.

    One per twin triple whose three joints the problem moves, shape (B, m, D); each
    joint reads its twin angle within its limits nearest the design (the problem's
    anchor).  A row without such a reading keeps its own angles there.  The keyframe
    search refines them beside its best (``keyframes.finish_search``): a twin has the
    same landmarks, but not the same limits, and the branch the colony did not take
    may reach lower where its own is held by a limit (TIAGo++'s side_invite with right
    joint 4 locked: joint 7 at its 120 deg limit, 1.55 % above the floor of the other
    branch, in 21 seeds of 200).
    """
    design = problem.anchor if problem.anchor is not None else problem.x0
    found = []
    for side in ARMS:
        column = {j: k for k, (s, j) in enumerate(problem.free) if s == side}
        for *triple, mirror in equivalent_twins(problem.robot, side):
            if not all(j in column for j in triple):
                continue
            twin = np.array(x, dtype=float)
            for b in range(len(twin)):   # a loop over rows: twin_angles is all or none
                taken = twin_angles(twin[b:b + 1], tuple(column[j] for j in triple), mirror,
                                    design[b:b + 1], problem.lower, problem.upper)
                if taken is not None:
                    twin[b] = taken[0]
            found.append(twin)
    return np.stack(found, axis=1) if found else np.empty((len(x), 0, np.shape(x)[-1]))


def side_twins(robot, side: str) -> list:
    """Return ``(columns (3,), mirror)`` of the arm's twin triples, in whole-robot columns."""
    first = arm_columns(robot)[side].start
    return [(np.array([first + i, first + j, first + k]), mirror)
            for i, j, k, mirror in equivalent_twins(robot, side)]


def side_candidates(q: np.ndarray, twins: list, design: np.ndarray, lower: np.ndarray,
                    upper: np.ndarray, fixed: np.ndarray) -> list:
    """
    Return the rows ``q`` (rows, J) through every combination of ``twins``: ``q`` first.

    Each twin of a combination is taken once, in order.  A combination counts only where
    the ``fixed`` columns (a locked joint, one the search did not move) end where they
    were: two twins that share a locked joint turn it by a whole turn (Namo's shoulder,
    elbow and wrist twins together leave joint 3 where it is), one alone never does.
    """
    found = [q]
    for n in range(1, len(twins) + 1):
        for chosen in combinations(twins, n):
            trial = q
            for columns, mirror in chosen:
                trial = twin_angles(trial, columns, mirror, design, lower, upper)
                if trial is None:
                    break
            if trial is None or not np.allclose(trial[:, fixed], q[:, fixed], atol=1e-9):
                continue
            trial = trial.copy()
            trial[:, fixed] = q[:, fixed]
            if not any(np.allclose(trial, other, atol=1e-9) for other in found):
                found.append(trial)
    return found


def choose(candidates: list, design: np.ndarray, path_cost: Optional[Callable]) -> np.ndarray:
    """
    Return the candidate whose path from rest presses the body least, then nearest the design.

    ``path_cost(poses (m, K, J))`` returns the body's penetration along each candidate's
    path (m,); without it, the joints' distance from the design alone decides.
    """
    gaps = np.array([np.sum((c - design) ** 2) for c in candidates])
    if path_cost is None or len(candidates) == 1:
        return candidates[int(np.argmin(gaps))]
    cost = np.asarray(path_cost(np.stack(candidates)), dtype=float)
    least = cost <= cost.min() + TWIN_TOLERANCE * (1.0 + abs(cost.min()))
    return candidates[int(np.argmin(np.where(least, gaps, np.inf)))]


def best_twins(robot, q: np.ndarray, design: np.ndarray, layouts: list, owners: list,
               value: Callable, bounds: tuple, path_cost: Optional[Callable] = None) -> tuple:
    """
    Return ``(q, rows)``: each gesture's keyframes on their best kinematic twins.

    ``q`` and ``design`` are (rows, J) angles of both arms (right first); ``layouts``
    the rows' free ``(side, joint)`` pairs; ``owners`` the gesture of each row (one
    combination of twins per gesture, its rows in keyframe order); ``value(q, rows)``
    the search's value of poses ``q`` at those rows; ``bounds`` the (lower, upper)
    limits (J,); ``path_cost(poses (m, K, J), rows)`` the body's penetration along the
    path from rest through each candidate's keyframes (None: not judged).  Of the
    twins, the one whose path presses least, then the one nearest the design
    (:func:`choose`).  A gesture changes only where none of its rows' values is worse
    (beyond :data:`TWIN_TOLERANCE`, relative).  ``rows`` lists the rows changed.
    """
    lower, upper = bounds
    out = np.array(q, dtype=float)
    owners = np.asarray(owners)
    columns = arm_columns(robot)
    twins_of = {side: side_twins(robot, side) for side in ARMS}    # one lookup per run
    moved = []
    for owner in np.unique(owners):
        ks = np.nonzero(owners == owner)[0]
        free = set.intersection(*(set(layouts[k]) for k in ks))
        trial = out[ks]
        for side in ARMS:
            twins = twins_of[side]
            if not twins or not any(s == side for s, _ in free):
                continue
            first = columns[side].start
            fixed = np.array([c for c in range(first, columns[side].stop)
                              if (side, c - first) not in free], dtype=int)
            found = side_candidates(trial, twins, design[ks], lower, upper, fixed)
            cost = None if path_cost is None else (lambda poses, ks=ks: path_cost(poses, ks))
            trial = choose(found, design[ks], cost)
        if not np.array_equal(trial, out[ks]):
            moved.append((ks, trial))
    if not moved:
        return out, []
    rows = np.concatenate([ks for ks, _ in moved])
    old = value(out[rows], rows)
    new = value(np.concatenate([t for _, t in moved]), rows)
    worse = new > old + TWIN_TOLERANCE * (1.0 + np.abs(old))
    changed, at = [], 0
    for ks, trial in moved:
        if not np.any(worse[at:at + len(ks)]):
            out[ks] = trial
            changed.extend(int(k) for k in ks)
        at += len(ks)
    return out, changed
