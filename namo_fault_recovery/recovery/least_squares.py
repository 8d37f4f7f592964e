"""
Reweighted Gauss-Newton on the score's own terms, for the keyframe search.

The similarity score is a weighted sum of distances
(:meth:`~..objective.score.SimilarityScore.residuals`: landmark offsets in mm, the palm's
rotation in deg, a two-handed gesture's left-right gaps), and its minima lie on kinks,
where one of those distances is exactly 0: a fingertip exactly on its reference, two
hands exactly their reference gap apart.  Near such a floor the quasi-Newton polish
(:mod:`~..optimize.polish`), even on the smoothed score, crawls: measured on TIAGo++'s
Wai with right joint 3 locked, the product colony ended at 28.9-31.8 over 10 seeds (the
fingertip 6-12 mm off), 3,000 more BFGS iterations from there reached 28.5-30.2, and
Nelder-Mead 28.46 from every one of them.  Iteratively reweighted least squares is the
classical answer for a sum of norms (Weiszfeld's): each term weighted by ``w / max(|r|,
floor)``, the weighted least-squares step follows the sum of distances, kinks included.

- :func:`normal_equations`: the reweighted normal matrices and gradients of a
  :class:`~.keyframes.PoseProblem`'s score (with its ``stay_close`` pull);
- :func:`gauss_newton`: plain damped steps, for starting points (:mod:`.seeding`);
- :func:`refine`: the search's last local step.  Bound-held joints are taken out of the
  step (an active set, as L-BFGS-B does), each step is tried at a few lengths against
  the problem's exact objective (the collision term included) and kept only where it
  lowers it, and the floor shrinks where no length gains.  On the case above it reached
  28.51 in 10 iterations and 28.461 in 20, from every seed.
- :func:`refine_basins`: :func:`refine` of each row's best and of the runners-up of
  the colony's polish that lie in other basins, in one batched call.
"""

import numpy as np

from ..model.kinematics import batch_forward, batch_forward_jacobian
from ..model.robot import ARMS
from ..optimize.bee_colony import DISTINCT_RAD

IRLS_FLOOR = 1.0        # mm or deg: a term closer than this is weighted as if this far
DAMPING = 1e-3          # Levenberg damping, a share of the normal matrix's mean diagonal
MAX_STEP = 0.5          # rad: the longest step of one gauss_newton iteration
REFINE_FLOORS = (1.0, 0.3, 0.1, 0.03, 0.01, 0.003, 0.001)   # refine's floors, in turn
REFINE_STEPS = np.array([1.0, 0.5, 0.25, 0.1, 0.03])        # step lengths tried
REFINE_DAMPING = 1e-6   # refine's damping: the line search, not the damping, keeps it safe
REFINE_ITERATIONS = 15  # refine's iterations at most
RUNNER_UP_MARGIN = 0.15  # refine_basins: a runner-up at most this share of |best| above it


def gauss_newton(problem, x, iterations, pull=0.0):
    """
    Return points ``x`` (batch, N, D) after ``iterations`` reweighted damped GN steps.

    Each step solves, per point, ``(H + lambda I) dx = -g`` with ``H = sum c J^T J``,
    ``g = sum c J^T r`` over the score's residual blocks (``c = w / max(|r|,
    IRLS_FLOOR)``) plus the problem's ``stay_close`` pull, at least ``pull`` per deg^2
    towards the problem's anchor (if it has one); steps are capped at ``MAX_STEP`` and
    projected onto the bounds.  No step is checked against the objective: the caller
    ranks the points.
    """
    batch, n, dim = x.shape
    eye = np.eye(dim)
    x = problem.clip(np.array(x, dtype=float))
    continuity = np.maximum(problem.continuity, pull * np.degrees(1.0) ** 2)
    for _ in range(iterations):
        h, g = normal_equations(problem, x, continuity=continuity)
        lam = DAMPING * np.trace(h, axis1=1, axis2=2) / dim + 1e-9
        step = -np.linalg.solve(h + lam[:, None, None] * eye, g[..., None])[..., 0]
        norm = np.linalg.norm(step, axis=-1, keepdims=True)
        step *= np.minimum(1.0, MAX_STEP / np.maximum(norm, 1e-12))
        x = problem.clip(x + step.reshape(batch, n, dim))
    return x


def normal_equations(problem, x, floor=IRLS_FLOOR, continuity=None):
    """
    Return the reweighted normal matrices (B N, D, D) and gradients (B N, D) at ``x``.

    ``x`` is (B, N, D); ``floor`` (mm or deg) is one number, or one per point (B N,);
    ``continuity`` (B,), per rad^2, replaces the problem's own pull weights.
    """
    batch, n, dim = x.shape
    q = dict(zip(ARMS, problem.assemble(x)))
    lms, jacs = {}, {}
    for side in ARMS:
        flat = q[side].reshape(batch * n, -1)
        if problem.columns[side]:
            lms[side], jacs[side] = batch_forward_jacobian(problem.robot, flat, side)
        else:
            lms[side] = batch_forward(problem.robot, flat, side)
    cols = {side: tuple(np.array(c, dtype=int).reshape(-1, 2).T)
            for side, c in problem.columns.items()}
    res, jac, weight = [], [], []
    for r, d_r, w in problem.scorer.residuals(lms, jacs, np.repeat(problem.target_ids, n)):
        block = np.zeros(r.shape + (dim,))
        for side, d in d_r.items():
            block[..., cols[side][0]] = d[..., cols[side][1]]
        res.append(r)
        jac.append(block)
        c = w / np.maximum(np.linalg.norm(r, axis=-1), floor)
        weight.append(np.repeat(c[:, None], r.shape[1], axis=1))
    res, jac, weight = (np.concatenate(a, axis=1) for a in (res, jac, weight))
    h = np.einsum('nmi,nmj->nij', jac * weight[..., None], jac)
    g = np.einsum('nmi,nm->ni', jac, weight * res)
    continuity = problem.continuity if continuity is None else continuity
    if problem.anchor is not None and np.any(continuity):
        c = np.repeat(continuity, n)[:, None]   # per row (B,) of the problem, per rad^2
        h += 2.0 * c[..., None] * np.eye(dim)
        g += 2.0 * c * (x - problem.anchor[:, None]).reshape(batch * n, dim)
    return h, g


def refine(problem, x, f, clock, iterations=REFINE_ITERATIONS):
    """
    Return ``(x, f, nfev)``: the points ``x`` (B, D) of values ``f`` (B,) refined.

    Every row of ``problem`` (a :class:`~.keyframes.PoseProblem`) takes up to
    ``iterations`` reweighted Gauss-Newton steps (see the module); a row ends when no
    step length gains at the smallest floor.  No row ends worse: a step is kept only
    where the exact objective falls.  Stops early when ``clock`` expires.
    """
    x = np.array(x, dtype=float)
    f = np.array(f, dtype=float)
    level = np.zeros(len(f), dtype=int)
    floors = np.array(REFINE_FLOORS)
    nfev = 0
    for _ in range(iterations):
        live = level < len(floors)
        if not np.any(live) or clock.expired():
            break
        h, g = normal_equations(problem, x[:, None, :], floors[np.minimum(level, len(floors) - 1)])
        step = _bounded_step(problem, x, h, g)
        trial = problem.clip(x[:, None, :] + REFINE_STEPS[:, None] * step[:, None, :])
        ft = problem.evaluate(trial)
        nfev += len(REFINE_STEPS) * len(f)
        pick = np.argmin(ft, axis=1)
        f_new = ft[np.arange(len(f)), pick]
        gain = live & (f_new < f - 1e-12 * (1.0 + np.abs(f)))
        x[gain] = trial[np.nonzero(gain)[0], pick[gain]]
        f[gain] = f_new[gain]
        level[live & ~gain] += 1
    return x, f, nfev


def _bounded_step(problem, x, h, g):
    """Return the damped GN steps (B, D) with the joints held at a bound left out."""
    dim = x.shape[-1]
    if problem.row_bounds is None:
        low, high = problem.lower, problem.upper
    else:
        low, high = problem.row_bounds
    held = ((x <= low + 1e-9) & (g > 0)) | ((x >= high - 1e-9) & (g < 0))
    eye = np.eye(dim)
    h = np.where(held[:, :, None] | held[:, None, :], 0.0, h) + eye * held[:, :, None]
    g = np.where(held, 0.0, g)
    lam = REFINE_DAMPING * np.trace(h, axis1=1, axis2=2) / dim + 1e-9
    return -np.linalg.solve(h + lam[:, None, None] * eye, g[..., None])[..., 0]


def refine_basins(problem, x, f, local, clock):
    """
    Return ``(x, f, nfev)``: :func:`refine` of the best points and of their runners-up.

    ``local`` is the algorithm's own local minima, ``(xl (B, k, D), funl (B, k))``
    (:attr:`~..optimize.base.OptimizeResult.xl`; None: refine ``x`` alone); a runner-up
    of value ``inf`` is never refined.  The polish
    stops short of a basin's floor (its iteration cap), and by how far differs from
    basin to basin, so the best polished point is not always in the best basin.
    Measured on Talos's side_invite with right joint 2 locked: the best basin's floor
    is 47.97, another's (joint 3 at its limit) 49.6; in 8 seeds of 100 the colony's
    best was in the second, with a start in the first polished only to 50.8-54.5.
    Every local minimum more than ``DISTINCT_RAD`` from its row's best (in some joint)
    and at most ``RUNNER_UP_MARGIN`` above it is refined with the best, all in one
    batched call (a few more rows cost little), and each row keeps its lowest value:
    the same seeds gave 2 such runs in 100 (and 15 in 200 against 47 on seeds 100-299).
    Without a deadline no row ends worse than :func:`refine` alone would leave it; with
    one, the rows share the iterations the clock allows.
    """
    if local is None or local[0] is None or clock.expired():
        return refine(problem, x, f, clock)
    xl = np.reshape(local[0], (len(f), -1, x.shape[-1]))   # a single problem's (k, D)
    fl = np.reshape(local[1], (len(f), -1))
    far = np.any(np.abs(xl - x[:, None, :]) > DISTINCT_RAD, axis=-1)
    rows, which = np.nonzero(far & (fl <= f[:, None] + RUNNER_UP_MARGIN * np.abs(f[:, None])))
    if rows.size == 0:
        return refine(problem, x, f, clock)
    n = len(f)
    both = problem.subset(np.concatenate((np.arange(n), rows)))
    xr, fr, nfev = refine(both, np.concatenate((x, xl[rows, which])),
                          np.concatenate((f, fl[rows, which])), clock)
    x, f = xr[:n], fr[:n]
    for row, xv, fv in zip(rows, xr[n:], fr[n:]):   # a loop over a few runners-up
        if fv < f[row]:
            x[row], f[row] = xv, fv
    return x, f, nfev
