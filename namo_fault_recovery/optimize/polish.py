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


def polish(problem, x0, clock, maxiter=100, ftol=1e-10):
    """
    Refine starts ``x0`` (batch, k, D) locally; return ``(x, f)`` for every start.

    Stops after ``maxiter`` iterations, when every start has converged (relative
    decrease below ``ftol``), or when ``clock`` expires; the best point of each start so
    far is returned in every case, with its exact objective value.
    """
    batch, k, dim = x0.shape
    n_steps = len(_STEPS)
    x = problem.clip(np.array(x0, dtype=float))
    f, g = problem.value_and_grad(x)
    eye = np.eye(dim)
    h_inv = eye * (_FIRST_STEP / np.maximum(np.linalg.norm(g, axis=-1), 1e-12))[..., None, None]
    active = np.isfinite(f)
    for _ in range(maxiter):
        if not np.any(active) or clock.expired():
            break
        p = -np.einsum('bkij,bkj->bki', h_inv, g)
        slope = np.einsum('bki,bki->bk', p, g)
        uphill = slope >= 0
        if np.any(uphill):   # not a descent direction: restart from steepest descent
            scale = _FIRST_STEP / np.maximum(np.linalg.norm(g, axis=-1), 1e-12)
            h_inv[uphill] = eye * scale[uphill][:, None, None]
            p[uphill] = -g[uphill] * scale[uphill][:, None]
            slope = np.einsum('bki,bki->bk', p, g)
        trial = problem.clip(x[:, :, None, :] + _STEPS[:, None] * p[:, :, None, :])
        ft, gt = problem.value_and_grad(trial.reshape(batch, k * n_steps, dim))
        ft = ft.reshape(batch, k, n_steps)
        gt = gt.reshape(batch, k, n_steps, dim)
        ok = ft <= f[..., None] + _ARMIJO * _STEPS * slope[..., None]
        pick = np.where(ok.any(axis=-1), ok.argmax(axis=-1), ft.argmin(axis=-1))
        f_new = np.take_along_axis(ft, pick[..., None], axis=-1)[..., 0]
        moved = active & (f_new < f)
        if not np.any(moved):
            break
        x_new = np.take_along_axis(trial, pick[..., None, None], axis=2)[:, :, 0]
        g_new = np.take_along_axis(gt, pick[..., None, None], axis=2)[:, :, 0]
        s = x_new - x
        y = g_new - g
        sy = np.einsum('bki,bki->bk', s, y)
        update = moved & (sy > 1e-12)
        if np.any(update):
            rho = np.where(update, 1.0 / np.where(update, sy, 1.0), 0.0)[..., None, None]
            left = eye - rho * s[..., :, None] * y[..., None, :]
            h_upd = (left @ h_inv @ np.swapaxes(left, -1, -2)
                     + rho * s[..., :, None] * s[..., None, :])
            h_inv = np.where(update[..., None, None], h_upd, h_inv)
        converged = moved & (f - f_new <= ftol * (1.0 + np.abs(f)))
        active = active & moved & ~converged
        x = np.where(moved[..., None], x_new, x)
        g = np.where(moved[..., None], g_new, g)
        f = np.where(moved, f_new, f)
    # The gradient may be of a smoothed objective: report the exact value.
    return x, problem.evaluate(x)
