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
forward-kinematics call per step; their exact values (the problem's objective, the
collision and ``stay_close`` terms included) then pick the colony's sources.  Measured
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

SEED_STARTS = 16        # uniform draws per keyframe
SEED_ITERATIONS = 5     # damped Gauss-Newton steps of each
SEED_PULL = 1e-3        # per deg^2: the steps' pull towards the designed angles


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
    f = problem.evaluate(x)
    best = np.argsort(f, axis=1, kind='stable')[:, :n]
    return np.take_along_axis(x, best[..., None], axis=1)
