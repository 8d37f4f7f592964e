"""
Whole-trajectory optimisation of a dense motion: every point at once, batched.

Kriging from typical points (:mod:`.motion`) is fast but leaves the fingertip off the
path between the typical points; exploring every point in order (``per_point``) reaches
the path but takes seconds per motion.  Here the free joints of all T points of one
motion are stacked into one vector of T x D variables and minimised together,
warm-started from the Kriging result: by a banded Newton method (:func:`banded_newton`,
the whole-motion pass, :func:`optimise_motion`) or projected L-BFGS
(:func:`projected_lbfgs`, numpy; or scipy's L-BFGS-B).  Every objective call runs one
batched forward-kinematics-and-Jacobian pass over all points
(:func:`~namo_fault_recovery.model.kinematics.batch_forward_jacobian`), so the gradient is
analytic and there is no Python loop over the points.

The objective is

    sum_t score_t  +  smoothness * sum_t |x_{t+1} - x_t|^2
                   +  step_penalty * sum_t,j max(0, |x_{t+1,j} - x_{t,j}| - cap)^2
                   [+ the capsule collision penalty of every point]

(steps in degrees): the score is the similarity score of each point against its own
designed pose (with the kinks rounded by ``smooth``, coarse to fine in the whole-motion
pass), the quadratic term
couples neighbouring points so that the motion stays on one redundant branch, and the
hinge keeps each joint's step near ``cap``, the motion's designed largest step.  The
locked joints are not variables, so they stay at their lock; the bounds are the joint
limits.  The run stops at the clock's deadline with the best point seen so far.
"""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solveh_banded
from scipy.optimize import minimize

from .result import CUT_SHORT
from ..model.kinematics import batch_forward, batch_forward_jacobian, take_landmarks
from ..model.robot import ARMS

DEFAULT_SMOOTHNESS = 0.01     # per deg^2 of joint step between consecutive points
DEFAULT_STEP_PENALTY = 1.0    # per deg^2 of a joint step beyond the cap
DEFAULT_SMOOTH = 0.01         # mm / deg: rounding of the score's kinks (as the polish)
# The whole-motion pass's roundings, coarse to fine (the last is the polish's): at 0.01
# alone the points that reach their target are 10^5 times stiffer than the rest, so that
# Newton's model holds only within 0.01 mm of them and it crawls.  From 3 mm the circle
# (right joints 1-7, no deadline) took 42-79 Newton steps in all, against 57-118 from
# 1 mm (then 0.1), to the same optimum.
MOTION_SMOOTHING = (3.0, 0.3, DEFAULT_SMOOTH)
COARSE_FTOL = 1e-6            # relative decrease that ends a coarser rounding's pass
MOTION_FTOL = 1e-9            # ... and the last one's
# Iterations of one pass.  300 left the circle 1-95 % above its best-known at 1 s
# (right joints 1, 3, 6: the pass had not converged); 600 reaches it, in 0.6-0.9 s
# of the library's 1 s; the clock still ends a pass at the deadline.
DEFAULT_MAXITER = 600
# Newton iterations of one pass (:func:`banded_newton`; each costs D + 2 evaluations).
DEFAULT_NEWTON_MAXITER = 200
_DAMPING, _MIN_DAMPING, _MAX_DAMPING = 1e-4, 1e-8, 1e6   # Marquardt: share of the diagonal
_HESSIAN_REUSE = 2            # steps a Hessian serves again after full steps
_DEG = 180.0 / np.pi


class _Stop(Exception):
    """Raised inside the objective when the clock says stop."""


class TrajectoryProblem:
    """
    The free joints of one motion's T points as one bounded problem of T x D variables.

    ``start`` is the pair (right, left) of (T, n) warm starts (the Kriging result, locks
    applied): they also give every joint that is not free, so that the locked joints
    keep their lock.  ``layout`` is a tuple of ``(arm, joint index)``, the free joints
    (the same at every point).  ``target_ids`` (T,) are the points' rows in ``scorer``,
    and ``collision`` an optional
    :class:`~namo_fault_recovery.objective.collision.CollisionModel` of the same targets
    whose penalty joins the objective.  ``step_cap_deg`` is the step beyond which the
    hinge penalty applies (None: no hinge).
    """

    def __init__(self, robot, scorer, target_ids, start, layout, *,
                 smoothness=DEFAULT_SMOOTHNESS, step_cap_deg=None,
                 step_penalty=DEFAULT_STEP_PENALTY, collision=None, smooth=DEFAULT_SMOOTH):
        if not layout:
            raise ValueError('TrajectoryProblem: no free joint to optimise')
        if not (np.isfinite(smoothness) and smoothness >= 0
                and np.isfinite(step_penalty) and step_penalty >= 0):
            raise ValueError(f'TrajectoryProblem: expected smoothness and step_penalty '
                             f'>= 0, got {smoothness!r} and {step_penalty!r}')
        self.robot = robot
        self.scorer = scorer
        self.collision = collision
        self.smooth = float(smooth)
        self.target_ids = np.asarray(target_ids, dtype=int)
        self.start = {side: np.array(pose, dtype=float) for side, pose in zip(ARMS, start)}
        self.layout = tuple(layout)
        self.n_points = len(self.target_ids)
        self.dim = len(self.layout)
        self.columns = {side: (np.array([k for k, (s, _) in enumerate(self.layout) if s == side],
                                        dtype=int),
                               np.array([j for s, j in self.layout if s == side], dtype=int))
                        for side in ARMS}
        low = np.array([robot.arms[s].lower[j] for s, j in self.layout])
        high = np.array([robot.arms[s].upper[j] for s, j in self.layout])
        self.lower = np.tile(low, self.n_points)
        self.upper = np.tile(high, self.n_points)
        # An arm without free joints does not move: its landmarks are computed once.
        self.fixed = {side: batch_forward(robot, self.start[side], side)
                      for side in ARMS if not len(self.columns[side][0])}
        self.smoothness = float(smoothness) * _DEG ** 2
        self.step_penalty = float(step_penalty) * _DEG ** 2
        self.cap = None if step_cap_deg is None else float(step_cap_deg) / _DEG
        self.x0 = np.clip(self.gather(self.start['right'], self.start['left']).ravel(),
                          self.lower, self.upper)
        self.nfev = 0

    def restrict(self, lower, upper):
        """
        Narrow the bounds to ``lower``/``upper`` (T x D, stacked like the variables).

        For constraints that are a box per point (each point of a motion kept near its
        neighbours, :func:`..recovery.pacing.tube`): the projected solver never leaves
        them.  The warm start is clipped into them.
        """
        self.lower = np.maximum(self.lower, np.asarray(lower, dtype=float).ravel())
        self.upper = np.minimum(self.upper, np.asarray(upper, dtype=float).ravel())
        if np.any(self.lower > self.upper):
            raise ValueError('TrajectoryProblem.restrict: the boxes miss the joint limits')
        self.x0 = np.clip(self.x0, self.lower, self.upper)

    def gather(self, q_right, q_left):
        """Return the free joints (T, D) of full angles (T, n) per arm."""
        x = np.empty((len(q_right), self.dim))
        for side, q in (('right', q_right), ('left', q_left)):
            k, j = self.columns[side]
            x[:, k] = q[:, j]
        return x

    def assemble(self, x):
        """Return the full (right, left) angles (T, n) of the stacked variables ``x``."""
        x = np.asarray(x, dtype=float).reshape(self.n_points, self.dim)
        out = []
        for side in ARMS:
            q = self.start[side].copy()
            k, j = self.columns[side]
            q[:, j] = x[:, k]
            out.append(q)
        return tuple(out)

    def bounds(self):
        """Return the (lower, upper) pairs of every variable, for scipy."""
        return list(zip(self.lower, self.upper))

    def value(self, x):
        """Return the objective at the stacked variables ``x``."""
        return self.value_and_grad(x, gradient=False)[0]

    def value_and_grad(self, x, gradient=True):
        """Return the objective and its gradient (T x D,) at the stacked variables ``x``."""
        self.nfev += 1
        x = np.asarray(x, dtype=float).reshape(self.n_points, self.dim)
        total, grad = self.point_terms(x, gradient)
        if self.n_points > 1:
            extra, d_step = self._steps(x)
            total += extra
            grad[1:] += d_step
            grad[:-1] -= d_step
        return total, grad.ravel()

    def point_terms(self, x, gradient=True, rows=None, parts=('score', 'collision')):
        """
        Return the terms of each point alone (score, collision): their sum and gradient.

        ``x`` is (T, D), or with ``rows`` (indices of points, repeats allowed) one row
        per entry of ``rows``; the gradient has the shape of ``x``, row t depending on
        row t of ``x`` only, which is what makes the Hessian of these terms
        block-diagonal (:meth:`point_hessians`).  ``parts`` chooses the terms.
        """
        rows = np.arange(self.n_points) if rows is None else np.asarray(rows, dtype=int)
        x = np.asarray(x, dtype=float).reshape(len(rows), self.dim)
        lms, jacs, args = {}, {}, {}
        for side in ARMS:
            k, j = self.columns[side]
            if side in self.fixed:
                lms[side] = args[side] = take_landmarks(self.fixed[side], rows)
                continue
            q = self.start[side][rows]
            q[:, j] = x[:, k]
            if gradient:
                lms[side], jacs[side] = batch_forward_jacobian(self.robot, q, side)
                args[side] = (lms[side], jacs[side])
            else:
                lms[side] = args[side] = batch_forward(self.robot, q, side)
        ids = self.target_ids[rows]
        total, full = 0.0, dict.fromkeys(ARMS, 0.0)
        if 'score' in parts:
            # Landmarks alone (no Jacobian) give the same rounded score and no gradient.
            f, g_r, g_l = self.scorer.value_and_grad(args['right'], args['left'], ids,
                                                     self.smooth)
            full = {'right': g_r, 'left': g_l}
            total = float(f.sum())
        if self.collision is not None and 'collision' in parts:
            pen, pen_grad = self.collision.penalty(lms['right'], lms['left'], ids,
                                                   jacs.get('right'), jacs.get('left'))
            total += float(pen.sum())
            for side, g in pen_grad.items():
                full[side] = full[side] + g
        grad = np.zeros_like(x)
        if gradient:
            for side in ARMS:
                k, j = self.columns[side]
                if np.ndim(full[side]):
                    grad[:, k] = full[side][:, j]
        return total, grad

    def _steps(self, x):
        """Return the smoothness and hinge terms and their gradient per step (T-1, D)."""
        step = np.diff(x, axis=0)
        d_step = np.zeros_like(step)
        total = 0.0
        if self.smoothness:
            total += self.smoothness * float(np.sum(step ** 2))
            d_step += 2.0 * self.smoothness * step
        if self.cap is not None and self.step_penalty:
            over = np.maximum(np.abs(step) - self.cap, 0.0)
            total += self.step_penalty * float(np.sum(over ** 2))
            d_step += 2.0 * self.step_penalty * over * np.sign(step)
        return total, d_step

    def point_hessians(self, x, h=1e-6):
        """
        Return the Hessian blocks (T, D, D) of :meth:`point_terms` at ``x`` (T, D).

        By forward differences of the gradient: each free joint is moved at every point
        (a point's terms depend on its own joints only), inwards from a bound, and all D
        moved copies of the motion go through one batched evaluation; the collision
        term (60 % of an evaluation) only at the points where it is active.
        Symmetrised.
        """
        x = np.asarray(x, dtype=float).reshape(self.n_points, self.dim)
        step = np.where(x + h > self.upper.reshape(x.shape), -h, h)     # (T, D)
        blocks = self._moved_columns(x, step, np.arange(self.n_points), ('score',))
        if self.collision is not None:
            active = np.flatnonzero(self._collision_rows(x))
            if len(active):
                blocks[active] += self._moved_columns(x[active], step[active], active,
                                                      ('collision',))
        return 0.5 * (blocks + blocks.transpose(0, 2, 1))

    def _moved_columns(self, x, step, rows, parts):
        """Return the forward-difference Hessian blocks [t, i, k] of ``parts`` at rows."""
        self.nfev += 2
        _, base = self.point_terms(x, rows=rows, parts=parts)
        moved = np.repeat(x[None], self.dim, axis=0)              # (D, n, D): copy k moves k
        cols = np.arange(self.dim)
        moved[cols, :, cols] += step.T
        _, g = self.point_terms(moved.reshape(-1, self.dim), rows=np.tile(rows, self.dim),
                                parts=parts)
        diff = (g.reshape(self.dim, len(rows), self.dim) - base[None]) / step.T[:, :, None]
        return diff.transpose(1, 2, 0)

    def _collision_rows(self, x):
        """Return per point whether the collision penalty is active at ``x`` (T, D)."""
        q = dict(zip(ARMS, self.assemble(x)))
        lms = {side: self.fixed[side] if side in self.fixed
               else batch_forward(self.robot, q[side], side) for side in ARMS}
        pen, _ = self.collision.penalty(lms['right'], lms['left'], self.target_ids)
        return np.asarray(pen) > 0

    def step_hessian(self, x):
        """
        Return the Hessian of the step terms as (diagonal (T, D), off-diagonal (T-1, D)).

        The smoothness and hinge terms couple joint j of point t with joint j of point
        t + 1 only; off-diagonal[t, j] is the entry between those two variables.
        """
        x = np.asarray(x, dtype=float).reshape(self.n_points, self.dim)
        diag = np.zeros_like(x)
        if self.n_points < 2:
            return diag, np.zeros((0, self.dim))
        curv = np.full((self.n_points - 1, self.dim), 2.0 * self.smoothness)
        if self.cap is not None and self.step_penalty:
            curv += 2.0 * self.step_penalty * (np.abs(np.diff(x, axis=0)) > self.cap)
        diag[1:] += curv
        diag[:-1] += curv
        return diag, -curv

    def max_step_deg(self, x):
        """Return the largest free-joint step (deg) between consecutive points of ``x``."""
        x = np.asarray(x, dtype=float).reshape(self.n_points, self.dim)
        return float(np.degrees(np.abs(np.diff(x, axis=0))).max()) if self.n_points > 1 else 0.0


@dataclass
class TrajectoryResult:
    """The outcome of one whole-trajectory optimisation."""

    q_right: np.ndarray   # (T, n) rad
    q_left: np.ndarray    # (T, n) rad
    value: float          # objective at the result
    value_start: float    # objective at the (clipped) warm start
    nfev: int
    nit: int
    status: str           # 'converged', 'iterations', 'deadline' or 'cancelled'


SOLVERS = ('lbfgs', 'scipy', 'newton')


def optimise_trajectory(problem, clock, maxiter=None, ftol=1e-9, solver='lbfgs', memory=20):
    """
    Minimise a :class:`TrajectoryProblem` from its warm start; return a result.

    ``solver='lbfgs'`` is :func:`projected_lbfgs` (numpy only), ``'scipy'`` scipy's
    L-BFGS-B: the same method, but on a shared machine scipy's routine spent ~3 ms of
    threaded BLAS per iteration on a 600-variable circle (0.5 ms for the objective),
    against ~0.1 ms for the numpy loop, so the numpy one is the default; a test
    cross-checks the two.  ``'newton'`` is :func:`banded_newton`, which converges where
    L-BFGS crawls (the whole-motion pass uses it).  ``maxiter`` None is the solver's
    default (:data:`DEFAULT_MAXITER`, :data:`DEFAULT_NEWTON_MAXITER`).  ``clock`` (a
    :class:`~namo_fault_recovery.optimize.base.Clock`) owns the deadline and the cancel
    flag: the objective stops the run when it has expired, and the best point evaluated
    so far is returned, so the result is never worse than the warm start on the
    objective.
    """
    if solver not in SOLVERS:
        raise ValueError(f'solver: expected one of {", ".join(SOLVERS)}, got {solver!r}')
    if maxiter is None:
        maxiter = DEFAULT_NEWTON_MAXITER if solver == 'newton' else DEFAULT_MAXITER
    best = {'f': np.inf, 'x': problem.x0}

    def check():
        if clock.expired():
            raise _Stop

    def fun(x):
        check()
        f, g = problem.value_and_grad(x)
        if f < best['f']:
            best['f'], best['x'] = f, x.copy()
        return f, g

    nfev0 = problem.nfev
    start_value = problem.value_and_grad(problem.x0, gradient=False)[0]
    best['f'] = start_value
    status, nit = 'converged', 0
    try:
        if solver == 'scipy':
            res = minimize(fun, problem.x0, jac=True, method='L-BFGS-B',
                           bounds=problem.bounds(),
                           options={'maxiter': maxiter, 'ftol': ftol, 'gtol': 1e-8,
                                    'maxcor': memory})
            nit, done = int(res.nit), res.status != 1
        elif solver == 'newton':
            nit, done = banded_newton(problem, fun, problem.x0, maxiter=maxiter, ftol=ftol,
                                      check=check)
        else:
            nit, done = projected_lbfgs(fun, problem.x0, problem.lower, problem.upper,
                                        maxiter=maxiter, ftol=ftol, memory=memory)
        if not done:
            status = 'iterations'
    except _Stop:
        status = 'cancelled' if clock.reason == 2 else 'deadline'
    x = np.clip(best['x'], problem.lower, problem.upper)
    q_r, q_l = problem.assemble(x)
    return TrajectoryResult(q_r, q_l, float(best['f']), float(start_value),
                            problem.nfev - nfev0, nit, status)


def projected_lbfgs(fun, x0, lower, upper, maxiter=DEFAULT_MAXITER, ftol=1e-9, gtol=1e-8,
                    memory=20, first_step=0.02):
    """
    Minimise ``fun(x) -> (f, g)`` within box bounds by projected L-BFGS; return (nit, done).

    Variables at a bound whose gradient pushes outwards are held there; the L-BFGS
    direction (two-loop recursion over the last ``memory`` pairs) is taken on the others,
    and a backtracking Armijo search runs along the projected path.  ``first_step``
    (rad) is the largest move of the first iteration, before any curvature is known.
    ``done`` is False when ``maxiter`` ran out.  The caller keeps the best point (every
    evaluation goes through ``fun``); all of it is vector arithmetic on x, so there is
    no loop over the points of a motion.
    """
    x = np.clip(np.asarray(x0, dtype=float), lower, upper)
    f, g = fun(x)
    pairs = []
    for nit in range(1, maxiter + 1):
        free = ~(((x <= lower) & (g > 0)) | ((x >= upper) & (g < 0)))
        pg = np.where(free, g, 0.0)
        if np.abs(pg).max(initial=0.0) <= gtol:
            return nit - 1, True
        d = -_two_loop(pg, pairs, free)
        slope = float(g @ d)
        if not slope < 0:
            pairs.clear()
            d, slope = -pg, -float(pg @ pg)
        step = 1.0 if pairs else min(1.0, first_step / np.abs(d).max())
        for _ in range(30):
            xn = np.clip(x + step * d, lower, upper)
            fn, gn = fun(xn)
            if fn <= f + 1e-4 * float(g @ (xn - x)):
                break
            step *= 0.5
        else:
            return nit, True        # no descent left at machine precision
        sk, yk = xn - x, gn - g
        if float(sk @ yk) > 1e-10 * float(yk @ yk):
            pairs.append((sk, yk, 1.0 / float(sk @ yk)))
            if len(pairs) > memory:
                pairs.pop(0)
        done = f - fn <= ftol * max(abs(f), abs(fn), 1.0)
        x, f, g = xn, fn, gn
        if done:
            return nit, True
    return maxiter, False


def banded_newton(problem, fun, x0, maxiter=DEFAULT_NEWTON_MAXITER, ftol=1e-9, gtol=1e-8,
                  check=None):
    """
    Minimise a :class:`TrajectoryProblem` by damped projected Newton; return (nit, done).

    The Hessian of a motion's objective is banded: a D x D block per point (its score
    and collision terms, :meth:`~TrajectoryProblem.point_hessians`) and the step terms
    between joint j of neighbouring points (:meth:`~TrajectoryProblem.step_hessian`), so
    one Newton step is a banded Cholesky solve of T x D unknowns with bandwidth D.
    Where L-BFGS needed thousands of iterations on the circle (the rounded kinks of the
    points that reach their target exactly are 10^5 times stiffer than the posture
    terms of the others), this converges in tens.  Each block is made positive definite
    (absolute eigenvalues, floored) and the diagonal is scaled by 1 + ``lam``
    (Levenberg-Marquardt), which grows when a step fails the Armijo test (the Hessian
    is then kept) and shrinks when a full step passes; variables at a bound that the
    gradient pushes outwards are held.  ``fun(x) -> (f, g)`` evaluates (and may raise to
    stop the run, as ``check()`` may before the Hessian's evaluations); ``done`` is
    False when ``maxiter`` ran out.
    """
    lower, upper = problem.lower, problem.upper
    x = np.clip(np.asarray(x0, dtype=float), lower, upper)
    f, g = fun(x)
    lam, calm, blocks, age = _DAMPING, 0, None, 0
    for nit in range(1, maxiter + 1):
        free = ~(((x <= lower) & (g > 0)) | ((x >= upper) & (g < 0)))
        pg = np.where(free, g, 0.0)
        if np.abs(pg).max(initial=0.0) <= gtol:
            return nit - 1, True
        if blocks is None:
            if check is not None:
                check()
            blocks, age = _psd_blocks(problem, x), 0
        d = -_newton_direction(problem, x, blocks, g, free, lam)
        if not float(g @ d) < 0:
            d = -pg
        step = _armijo(fun, x, f, g, d, lower, upper)
        if step is None:
            if lam >= _MAX_DAMPING:
                return nit, True     # no descent left at machine precision
            lam *= 10.0
            continue
        lam = max(lam / 3.0, _MIN_DAMPING) if step[0] == 1.0 else min(lam * 4.0, _MAX_DAMPING)
        full, xn, fn, gn = step
        small = f - fn <= ftol * max(abs(f), abs(fn), 1.0)
        x, f, g = xn, fn, gn
        # After full steps the Hessian serves again (it costs ~3 evaluations).
        age += 1
        if not (full == 1.0 and age <= _HESSIAN_REUSE):
            blocks = None
        calm = calm + 1 if small else 0
        if calm >= 2:
            return nit, True
    return maxiter, False


def _armijo(fun, x, f, g, d, lower, upper, tries=10):
    """Return (step, x, f, g) of a backtracking Armijo search along ``d``, or None."""
    step = 1.0
    for _ in range(tries):
        xn = np.clip(x + step * d, lower, upper)
        fn, gn = fun(xn)
        if fn <= f + 1e-4 * float(g @ (xn - x)):
            return step, xn, fn, gn
        step *= 0.5
    return None


def _psd_blocks(problem, x):
    """Return the point Hessian blocks at ``x``, made positive definite (|eigenvalues|)."""
    blocks = problem.point_hessians(x.reshape(problem.n_points, problem.dim))
    w, v = np.linalg.eigh(blocks)
    scale = max(float(np.abs(w).max(initial=0.0)), 1e-12)
    w = np.maximum(np.abs(w), 1e-9 * scale)
    return np.einsum('tik,tk,tjk->tij', v, w, v)


def _newton_direction(problem, x, blocks, g, free, lam):
    """Return H^-1 g on the ``free`` variables for the banded Hessian H at ``x``."""
    n, dim = problem.n_points, problem.dim
    diag, off = problem.step_hessian(x.reshape(n, dim))
    band = np.zeros((dim + 1, n * dim))
    for o in range(dim):
        rows = np.zeros((n, dim))
        rows[:, :dim - o] = blocks[:, np.arange(o, dim), np.arange(dim - o)]
        band[o] = rows.ravel()
    band[0] += diag.ravel()
    band[dim, :(n - 1) * dim] = off.ravel()
    band[0] *= 1.0 + lam
    f = free.astype(float)
    for o in range(dim + 1):
        band[o, :n * dim - o] *= f[:n * dim - o] * f[o:]
    band[0] += 1.0 - f
    return np.where(free, solveh_banded(band, np.where(free, g, 0.0), lower=True), 0.0)


def _two_loop(g, pairs, free):
    """Return H g for the L-BFGS inverse Hessian H of ``pairs``, on the ``free`` variables."""
    q = g.copy()
    alphas = []
    for s, y, rho in reversed(pairs):
        a = rho * float(s @ q)
        q -= a * y
        q[~free] = 0.0
        alphas.append(a)
    if pairs:
        s, y, _ = pairs[-1]
        q *= float(s @ y) / float(y @ y)
    for (s, y, rho), a in zip(pairs, reversed(alphas)):
        q += (a - rho * float(y @ q)) * s
        q[~free] = 0.0
    return q


def designed_step_deg(design):
    """Return a motion's designed largest joint step (deg), for the hinge's cap."""
    design = np.asarray(design, dtype=float)
    if len(design) < 2:
        return 0.0
    return float(np.degrees(np.abs(np.diff(design, axis=0))).max())


def optimise_motion(robot, scorer, target_ids, start_right, start_left, layout, design,
                    clock, collision=None):
    """
    Optimise one whole motion from its warm start; return a :class:`TrajectoryResult`.

    ``design`` (T, J) is the designed motion (both arms, rad): its largest step is the
    cap of the step hinge.  The other arguments are those of :class:`TrajectoryProblem`
    (with the default smoothness and step penalty) and :func:`optimise_trajectory`.
    Solved by :func:`banded_newton`, once per rounding of :data:`MOTION_SMOOTHING`, each
    from the previous result; ``value`` and ``value_start`` are both on the last (the
    polish's), and the warm start is returned if the result is not lower there.
    L-BFGS at the polish's rounding alone stopped on its iteration cap (the circle with
    right joint 2 locked 10-40 % above the optimum, by the seed) and needed ~10,000
    iterations to converge; this takes 40-80 Newton steps.
    """
    kw = {'step_cap_deg': designed_step_deg(design), 'collision': collision}
    q, nfev, nit, status = (start_right, start_left), 0, 0, 'converged'
    for k, smooth in enumerate(MOTION_SMOOTHING):
        problem = TrajectoryProblem(robot, scorer, target_ids, q, layout, smooth=smooth, **kw)
        # A coarser rounding only brings the next one near its optimum.
        ftol = MOTION_FTOL if k == len(MOTION_SMOOTHING) - 1 else COARSE_FTOL
        out = optimise_trajectory(problem, clock, solver='newton', ftol=ftol)
        q, nfev, nit, status = (out.q_right, out.q_left), nfev + out.nfev, nit + out.nit, \
            out.status
        if status in CUT_SHORT:
            break
    final = TrajectoryProblem(robot, scorer, target_ids, (start_right, start_left), layout,
                              smooth=MOTION_SMOOTHING[-1], **kw)
    start_value = final.value(final.x0)
    value = final.value(final.gather(*q).ravel())
    if not value < start_value:
        value, q = start_value, final.assemble(final.x0)
    return TrajectoryResult(q[0], q[1], float(value), float(start_value),
                            nfev + final.nfev, nit, status)
