"""
Kinematic starts of the keyframe search: a few damped least-squares steps on the landmarks.

The product's colony is small (8 sources, 8 cycles, 5 of them polished) and its random
sources land in whichever basin of the arm's redundancy they happen to sample: with a
shoulder joint locked the best basin of a pose may be far from the reference (TIAGo++'s
side_invite with right joint 2 locked: 49.7 with joint 1 near 10 deg and joint 3 near
69 deg, 76-81 in the basin around the reference, where 20 seeds in 24 ended).  Raw
random points say little about their basin, and polishing many of them costs the
deadline.  Here ``SEED_STARTS`` uniform draws per keyframe take ``SEED_ITERATIONS``
steps of iteratively reweighted Gauss-Newton on the score's own terms (each landmark
offset weighted by ``w / max(|r|, IRLS_FLOOR)``, so that the least-squares model
follows the score's sum of distances, kinks included), all of them in one batched
forward-kinematics call per step; with them, :func:`flip_starts` (the design through
each of the arm's roll-pitch-roll flips, or with a held outer joint's turn handed to
the other, :func:`transfer_start`; not stepped: the pull would drag them back);
their exact values (the problem's objective, the collision and ``stay_close`` terms
included) then pick the colony's sources, best first.  Measured
on the stage-1 problem of TIAGo++ with right joint 2 locked, 16 starts: the best of
them, polished, reached the best basin of side_invite in 12 trials of 12 after 5 steps
(7 of 12 from the best raw draw).

The Gauss-Newton steps are drawn towards the designed angles (``SEED_PULL`` per deg^2,
or the problem's own ``stay_close`` pull where stronger), as a prior that keeps the
undamped directions of a redundant arm from wandering; the ranking and everything after
it use the problem's own objective, so a single pose, which has no pull of its own, is
still scored on its similarity alone.  Measured on both test robots with a single pose
unpulled (20 seeds at the deadline, within 1 % of the optima of the time): TIAGo++
with right joint 2 locked in 15 of 20 runs without the prior (side_invite in its basin
around the reference, 44-51 % above) and 20 of 20 with it; with right joint 3 (Wai in
a basin 2 % above) 15 and 20.
"""

import numpy as np

from .least_squares import gauss_newton
from ..model.kinematics import equivalent_flips
from ..model.robot import ARMS

SEED_STARTS = 16        # uniform draws per keyframe
SEED_ITERATIONS = 5     # damped Gauss-Newton steps of each
SEED_PULL = 1e-3        # per deg^2: the steps' pull towards the designed angles
FLIP_MARGIN = np.radians(1.0)   # a limit this close stops a joint; a lock this near 0 is 0


def kinematic_starts(problem, rng, n):
    """
    Return ``n`` starts per keyframe of a :class:`~.keyframes.PoseProblem` (batch, n, D).

    The best ``n`` by the problem's exact objective of ``SEED_STARTS`` uniform draws,
    each after ``SEED_ITERATIONS`` damped Gauss-Newton steps pulled towards the
    problem's anchor (``SEED_PULL``)
    (:func:`~.least_squares.gauss_newton`);
    deterministic given ``rng``.
    """
    x = gauss_newton(problem, problem.random(rng, max(n, SEED_STARTS)), SEED_ITERATIONS,
                     pull=SEED_PULL)
    flips = flip_starts(problem)
    if flips is not None:   # not stepped: the pull would drag them back to the design
        x = np.concatenate((x, flips), axis=1)
    f = problem.evaluate(x)
    best = np.argsort(f, axis=1, kind='stable')[:, :n]
    return np.take_along_axis(x, best[..., None], axis=1)


def flip_starts(problem):
    """
    Return the designed poses turned through each roll-pitch-roll flip (batch, m, D), or None.

    A flip (:func:`~..model.kinematics.equivalent_flips`: outer joints turned by half a
    turn, the middle one negated) leaves every landmark where it was, but not the joint
    limits: the flipped branch of a design can move where the design is stopped by a
    limit, and with a locked middle joint (which cannot be negated) the flip makes the
    lock act as its own negative.  Uniform draws find those branches only by chance;
    measured at the 1 s deadline on TIAGo++ (every single fault x 20 seeds): its salute
    with right joint 6 locked ended 6x above the best in 6 seeds of 100 (a locked
    middle), its side_invite with right joint 4 locked 1.55 % above in 11 of 20 (the
    design's joint 7 at its limit); with these starts 0 and 0.  One start per flip whose
    outer joints the problem moves, from the designed angles (the problem's anchor), each
    outer joint turned by +-pi, whichever lands within its limits (else the nearer one,
    clipped).  Only where the flip can change the answer: a held middle joint away from
    0 and pi, or a moving one whose design has an outer joint at a limit (within
    ``FLIP_MARGIN``).  Elsewhere the flipped design is the design itself, far away in
    joint space: the colony would as soon settle there, and the arm swing half a turn to
    reach it (Namo's Wai with the left elbow stuck straight: the whole arm turned over,
    blocked by the body on its way in the simulator); those rows start from the design.
    Where the group's outer joint is the one held, :func:`transfer_start` instead.
    """
    designed = problem.anchor if problem.anchor is not None else problem.x0
    lower, upper = np.asarray(problem.lower), np.asarray(problem.upper)
    starts = []
    for side in ARMS:
        column = {j: k for k, (s, j) in enumerate(problem.free) if s == side}
        if not column:
            continue
        for outer, middle, other in equivalent_flips(problem.robot, side):
            if outer not in column or other not in column:
                start = transfer_start(problem, designed, side, column,
                                       (outer, middle, other))
                if start is not None:
                    starts.append(start)
                continue
            ends = [column[outer], column[other]]
            x = np.array(designed, dtype=float)
            if middle in column:      # worth it where the design is stopped by a limit
                worth = np.any((x[:, ends] <= lower[ends] + FLIP_MARGIN)
                               | (x[:, ends] >= upper[ends] - FLIP_MARGIN), axis=1)
                x[:, column[middle]] *= -1.0
            else:                     # worth it where the held angle is not 0 or pi
                worth = np.abs(np.sin(problem.base[side][:, middle])) > np.sin(FLIP_MARGIN)
            if not worth.any():
                continue
            for k in ends:
                half = x[:, k, None] + np.array([np.pi, -np.pi])
                x[:, k] = nearest_within(half, lower[k], upper[k])
            starts.append(np.where(worth[:, None], x, designed))
    if not starts:
        return None
    return problem.clip(np.stack(starts, axis=1))


def transfer_start(problem, designed, side, column, triple):
    """
    Return the design with a held outer joint's turn handed to the other one, or None.

    With the middle joint of a flip group at 0 its outer joints turn about one axis, so
    the free one can take the turn the held one misses: middle 0, free outer at its
    design plus (the held joint's design - its lock), within its limits where a full
    turn allows (else clipped).  TIAGo++'s side_invite with right joint 7 locked 95 deg
    from its design ends in this basin, or 1.13 % above it with the palm turned away.
    Only rows whose held joint is more than ``FLIP_MARGIN`` from its design; the others
    keep ``designed`` (the free joints' designed angles, as :func:`flip_starts` has them).
    """
    outer, middle, other = triple
    held, moved = (outer, other) if other in column else (other, outer)
    if middle not in column or moved not in column or held in column:
        return None
    arm = 0 if side == ARMS[0] else 1
    design = np.array([problem.scorer.reference(t)[arm][held] for t in problem.target_ids])
    missed = design - problem.base[side][:, held]
    worth = np.abs(missed) > FLIP_MARGIN
    if not worth.any():
        return None
    x = np.array(designed, dtype=float)
    k = column[moved]
    x[:, column[middle]] = 0.0
    x[:, k] = nearest_within(x[:, k, None] + missed[:, None]
                             + np.array([0.0, 2 * np.pi, -2 * np.pi]),
                             problem.lower[k], problem.upper[k])
    return np.where(worth[:, None], x, designed)


def nearest_within(candidates, low, high):
    """Return, per row of ``candidates`` (rows, m), the one nearest to [low, high], clipped."""
    clipped = np.clip(candidates, low, high)
    pick = np.argmin(np.abs(candidates - clipped), axis=1)
    return clipped[np.arange(len(candidates)), pick]
