"""
Whole-trajectory optimisation of a dense motion: every point at once, batched.

Kriging from typical points (:mod:`.motion`) is fast but leaves the fingertip off the
path between the typical points; exploring every point in order (``per_point``) reaches
the path but takes seconds per motion.  Here the free joints of all T points of one
motion are stacked into one vector of T x D variables and minimised together by
projected L-BFGS (:func:`projected_lbfgs`, numpy; or scipy's L-BFGS-B), warm-started
from the Kriging result.  Every objective call runs one
batched forward-kinematics-and-Jacobian pass over all points
(:func:`~namo_fault_recovery.model.kinematics.batch_forward_jacobian`), so the gradient is
analytic and there is no Python loop over the points.

The objective is

    sum_t score_t  +  smoothness * sum_t |x_{t+1} - x_t|^2
                   +  step_penalty * sum_t,j max(0, |x_{t+1,j} - x_{t,j}| - cap)^2
                   [+ the capsule collision penalty of every point]

(steps in degrees): the score is the similarity score of each point against its own
designed pose (with the kink-free ``smooth`` rounding of the polish), the quadratic term
couples neighbouring points so that the motion stays on one redundant branch, and the
hinge keeps each joint's step near ``cap``, the motion's designed largest step.  The
locked joints are not variables, so they stay at their lock; the bounds are the joint
limits.  The run stops at the clock's deadline with the best point seen so far.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from ..model.kinematics import batch_forward, batch_forward_jacobian
from ..model.robot import ARMS

DEFAULT_SMOOTHNESS = 0.01     # per deg^2 of joint step between consecutive points
DEFAULT_STEP_PENALTY = 1.0    # per deg^2 of a joint step beyond the cap
DEFAULT_SMOOTH = 0.01         # mm / deg: rounding of the score's kinks (as the polish)
# Iterations of one pass.  300 left the circle 1-95 % above its best-known at 1 s
# (right joints 1, 3, 6: the pass had not converged); 600 reaches it, in 0.6-0.9 s
# of the library's 1 s; the clock still ends a pass at the deadline.
DEFAULT_MAXITER = 600
_DEG = 180.0 / np.pi


class _Stop(Exception):
    """Raised inside the objective when the clock says stop."""


class TrajectoryProblem:
    """
    The free joints of one motion's T points as one bounded problem of T x D variables.

    ``start`` is the pair (right, left) of (T, 7) warm starts (the Kriging result, locks
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
        """Return the free joints (T, D) of full angles (T, 7) per arm."""
        x = np.empty((len(q_right), self.dim))
        for side, q in (('right', q_right), ('left', q_left)):
            k, j = self.columns[side]
            x[:, k] = q[:, j]
        return x

    def assemble(self, x):
        """Return the full (right, left) angles (T, 7) of the stacked variables ``x``."""
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
        q = dict(zip(ARMS, self.assemble(x)))
        lms, jacs, args = {}, {}, {}
        for side in ARMS:
            if side in self.fixed:
                lms[side] = args[side] = self.fixed[side]
            elif gradient:
                lms[side], jacs[side] = batch_forward_jacobian(self.robot, q[side], side)
                args[side] = (lms[side], jacs[side])
            else:
                lms[side] = args[side] = batch_forward(self.robot, q[side], side)
        ids = self.target_ids
        # Landmarks alone (no Jacobian) give the same rounded score and no gradient.
        f, g_r, g_l = self.scorer.value_and_grad(args['right'], args['left'], ids,
                                                 self.smooth)
        full = {'right': g_r, 'left': g_l}
        total = float(f.sum())
        if self.collision is not None:
            pen, pen_grad = self.collision.penalty(lms['right'], lms['left'], ids,
                                                   jacs.get('right'), jacs.get('left'))
            total += float(pen.sum())
            for side, g in pen_grad.items():
                full[side] = full[side] + g
        grad = np.zeros_like(x)
        if gradient:
            for side in ARMS:
                k, j = self.columns[side]
                grad[:, k] = full[side][:, j]
        if self.n_points > 1:
            step = np.diff(x, axis=0)
            d_step = np.zeros_like(step)
            if self.smoothness:
                total += self.smoothness * float(np.sum(step ** 2))
                d_step += 2.0 * self.smoothness * step
            if self.cap is not None and self.step_penalty:
                over = np.maximum(np.abs(step) - self.cap, 0.0)
                total += self.step_penalty * float(np.sum(over ** 2))
                d_step += 2.0 * self.step_penalty * over * np.sign(step)
            grad[1:] += d_step
            grad[:-1] -= d_step
        return total, grad.ravel()

    def max_step_deg(self, x):
        """Return the largest free-joint step (deg) between consecutive points of ``x``."""
        x = np.asarray(x, dtype=float).reshape(self.n_points, self.dim)
        return float(np.degrees(np.abs(np.diff(x, axis=0))).max()) if self.n_points > 1 else 0.0


@dataclass
class TrajectoryResult:
    """The outcome of one whole-trajectory optimisation."""

    q_right: np.ndarray   # (T, 7) rad
    q_left: np.ndarray    # (T, 7) rad
    value: float          # objective at the result
    value_start: float    # objective at the (clipped) warm start
    nfev: int
    nit: int
    status: str           # 'converged', 'iterations', 'deadline' or 'cancelled'


SOLVERS = ('lbfgs', 'scipy')


def optimise_trajectory(problem, clock, maxiter=DEFAULT_MAXITER, ftol=1e-9, solver='lbfgs',
                        memory=20):
    """
    Minimise a :class:`TrajectoryProblem` from its warm start; return a result.

    ``solver='lbfgs'`` is :func:`projected_lbfgs` (numpy only), ``'scipy'`` scipy's
    L-BFGS-B: the same method, but on a shared machine scipy's routine spent ~3 ms of
    threaded BLAS per iteration on a 600-variable circle (0.5 ms for the objective),
    against ~0.1 ms for the numpy loop, so the numpy one is the default; a test
    cross-checks the two.  ``clock`` (a :class:`~namo_fault_recovery.optimize.base.Clock`)
    owns the deadline and the cancel flag: the objective stops the run when it has
    expired, and the best point evaluated so far is returned, so the result is never
    worse than the warm start on the objective.
    """
    if solver not in SOLVERS:
        raise ValueError(f'solver: expected one of {", ".join(SOLVERS)}, got {solver!r}')
    best = {'f': np.inf, 'x': problem.x0}

    def fun(x):
        if clock.expired():
            raise _Stop
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

    ``design`` (T, 14) is the designed motion (both arms, rad): its largest step is the
    cap of the step hinge.  The other arguments are those of :class:`TrajectoryProblem`
    (with the default smoothness and step penalty) and :func:`optimise_trajectory`.
    """
    problem = TrajectoryProblem(robot, scorer, target_ids, (start_right, start_left), layout,
                                step_cap_deg=designed_step_deg(design), collision=collision)
    return optimise_trajectory(problem, clock)
