"""
Batched local polish: quasi-Newton (BFGS) descent on many independent starts at once.

scipy's local minimisers take one start per call; stacking all starts into one scipy
problem couples their line searches, so one badly scaled start stalls all of them (we
measured it: most starts ended far from their basin floor).  Here every start keeps its
own inverse-Hessian estimate and its own step length, and each iteration is a single
batched call for all starts: the value and gradient (analytic when the problem has one)
at several step lengths along each start's direction, of which each start keeps the
longest that satisfies the Armijo condition.  Steps are projected onto the bounds.
"""

import numpy as np

_STEPS = np.array([1.0, 0.4, 0.1, 0.02, 0.002])
_ARMIJO = 1e-4
_FIRST_STEP = 0.1   # radians moved by the first iteration of a start


def polish(problem, x0, clock, maxiter=100, ftol=1e-10, restart=False, callback=None):
    """
    Refine starts ``x0`` (batch, k, D) locally; return ``(x, f)`` for every start.

    Stops after ``maxiter`` iterations, when every start has converged (relative
    decrease below ``ftol``), or when ``clock`` expires; the best point of each start so
    far is returned in every case, with its exact objective value.  With ``restart``, a
    start whose quasi-Newton step finds no decrease at any step length takes a step of
    steepest descent before it is given up (and goes on while that one gains): the
    score is a sum of distances, whose minima lie on kinks (a two-handed gesture's
    left-right gaps at exactly their reference), where the inverse-Hessian estimate
    goes bad long before the floor.  Measured on TIAGo++'s Wai with its right joint 3
    locked, 100 random starts: median 91.7 without, 42.5 with it (best 36.6 and 31.6).
    It costs iterations where many starts crawl along a kink or a bound.

    ``callback(x)``, as scipy's, gets every start's best so far after each iteration.
    """
    batch, k, dim = x0.shape
    n_steps = len(_STEPS)
    x = problem.clip(np.array(x0, dtype=float))
    f, g = problem.value_and_grad(x)
    eye = np.eye(dim)
    h_inv = _steepest(g, eye)
    fresh = np.ones((batch, k), dtype=bool)   # the last step was from steepest descent
    active = np.isfinite(f)
    for _ in range(maxiter):
        if not np.any(active) or clock.expired():
            break
        p = -np.einsum('bkij,bkj->bki', h_inv, g)
        uphill = np.einsum('bki,bki->bk', p, g) >= 0
        if np.any(uphill):   # not a descent direction: restart from steepest descent
            h_inv[uphill] = _steepest(g[uphill], eye)
            p[uphill] = -np.einsum('nij,nj->ni', h_inv[uphill], g[uphill])
            fresh |= uphill
        slope = np.einsum('bki,bki->bk', p, g)
        trial = problem.clip(x[:, :, None, :] + _STEPS[:, None] * p[:, :, None, :])
        ft, gt = problem.value_and_grad(trial.reshape(batch, k * n_steps, dim))
        ft = ft.reshape(batch, k, n_steps)
        gt = gt.reshape(batch, k, n_steps, dim)
        ok = ft <= f[..., None] + _ARMIJO * _STEPS * slope[..., None]
        pick = np.where(ok.any(axis=-1), ok.argmax(axis=-1), ft.argmin(axis=-1))
        f_new = np.take_along_axis(ft, pick[..., None], axis=-1)[..., 0]
        moved = active & (f_new < f)
        retry = active & ~moved & ~fresh & restart
        if not np.any(moved | retry):
            break
        h_inv[retry] = _steepest(g[retry], eye)
        x_new = np.take_along_axis(trial, pick[..., None, None], axis=2)[:, :, 0]
        g_new = np.take_along_axis(gt, pick[..., None, None], axis=2)[:, :, 0]
        h_inv = _bfgs_update(h_inv, x_new - x, g_new - g, moved, eye)
        converged = moved & (f - f_new <= ftol * (1.0 + np.abs(f)))
        active = active & (moved | retry) & ~converged
        fresh = retry | (fresh & ~moved)
        x = np.where(moved[..., None], x_new, x)
        g = np.where(moved[..., None], g_new, g)
        f = np.where(moved, f_new, f)
        if callback is not None:
            callback(x)
    # The gradient may be of a smoothed objective: report the exact value.
    return x, problem.evaluate(x)


def _steepest(g, eye):
    """Return the inverse-Hessian estimates of steepest descent: a first step of 0.1 rad."""
    return eye * (_FIRST_STEP / np.maximum(np.linalg.norm(g, axis=-1), 1e-12))[..., None, None]


def _bfgs_update(h_inv, s, y, moved, eye):
    """Return the BFGS update of ``h_inv`` for the starts that moved by ``s`` (curvature > 0)."""
    sy = np.einsum('...i,...i->...', s, y)
    update = moved & (sy > 1e-12)
    if not np.any(update):
        return h_inv
    rho = np.where(update, 1.0 / np.where(update, sy, 1.0), 0.0)[..., None, None]
    left = eye - rho * s[..., :, None] * y[..., None, :]
    h_upd = left @ h_inv @ np.swapaxes(left, -1, -2) + rho * s[..., :, None] * s[..., None, :]
    return np.where(update[..., None, None], h_upd, h_inv)
