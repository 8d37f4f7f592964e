"""
A constrained local solve of one pose: the score with the capsules as hard constraints.

The keyframe search (:mod:`.keyframes`) keeps the arms apart with a penalty: the plain
score is searched first and the poses that collide are searched again with the capsule
penalty, from their starting pose and from the plain optimum.  A penalty descent stays
in the basin it starts in, and where the best clear pose lies along the boundary of a
contact, away from both starts, it is not found.  Measured on Talos's Wai with
``arm_right_3_joint`` locked: the penalised searches end at 38.86-38.98 in every seed,
L-BFGS-B on the penalised score from the starting pose at 38.85 (weight 1 per mm^2) or
39.49 (weight 10-1000), while SLSQP with the pairs' clearances as inequality
constraints slides along the contact from the starting pose to 37.66.

:func:`constrained_pose` runs that SLSQP solve (scipy's) on one row of a
:class:`~.keyframes.PoseProblem` without a penalty: its score and gradient, the
joints' bounds, and every checked pair's clearance (:meth:`~..objective.collision.
CollisionModel.clearance`, analytic derivatives) at least 0.  It stops when the clock
runs out, with the best clear pose it has evaluated.  The keyframe search runs it first
on a colliding pose (``keyframes._solve``); the judge keeps the best clear candidate.
"""

from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import minimize, OptimizeResult

from ..optimize.base import Clock, Problem

if TYPE_CHECKING:
    from ..objective.collision import CollisionModel

MAXITER = 60            # SLSQP iterations (the Talos case above takes 35)
FTOL = 1e-6             # SLSQP's stopping tolerance on the score
CLEAR_TOL_MM = 1e-6     # a pose is clear when no pair is deeper than this


class _OutOfTime(Exception):
    """The clock ran out during the solve."""


class _Evaluations:
    """One row's score, gradient, clearances and their Jacobian, cached per pose."""

    def __init__(self, problem, checker, clock):
        self.problem, self.checker, self.clock = problem, checker, clock
        self._key, self._value = None, None
        self.best_x, self.best_f = None, np.inf

    def __call__(self, x):
        key = x.tobytes()
        if key != self._key:
            if self.clock.expired():
                raise _OutOfTime()
            self._key, self._value = key, self._evaluate(x)
            f, _, margin, _ = self._value
            if f < self.best_f and margin.min() >= -CLEAR_TOL_MM:
                self.best_x, self.best_f = x.copy(), f
        return self._value

    def _evaluate(self, x):
        problem = self.problem
        arms, target = problem.arms(x[None, None], jacobian=True)
        f, grad = problem.value_and_grad_at(x[None, None], arms, target)
        lm, jac = problem.split_jacobians(arms)
        margin, rates = self.checker.clearance(lm['right'], lm['left'], target,
                                               jac['right'], jac['left'])
        jacobian = np.zeros((margin.shape[1], len(x)))
        for side, rate in rates.items():
            for col, j in problem.columns[side]:
                jacobian[:, col] = rate[0, :, j]
        return float(f[0, 0]), grad[0, 0], margin[0], jacobian


def constrained_pose(problem: Problem, checker: 'CollisionModel', clock: Clock,
                     maxiter: int = MAXITER) -> OptimizeResult:
    """
    Return scipy's ``OptimizeResult`` of the SLSQP solve from ``problem``'s start.

    ``problem`` is a one-row :class:`~.keyframes.PoseProblem` without a collision
    model (its ``x0`` the start), ``checker`` the
    :class:`~..objective.collision.CollisionModel` whose clearances constrain it.
    ``x`` is the best clear pose (D,) evaluated, None when none was clear; ``fun``
    its value of ``problem``; ``success`` True when SLSQP converged (not cut by the
    clock or ``maxiter``) and ``x`` is a pose: a clear local optimum of the score.  When
    the clock ran out ``nit`` is -1 (and ``fun`` inf if no pose was clear).
    """
    ev = _Evaluations(problem, checker, clock)
    x0 = np.asarray(problem.x0[0], dtype=float)
    try:
        res = minimize(lambda x: ev(x)[:2], x0, jac=True, method='SLSQP',
                       bounds=list(zip(problem.lower, problem.upper)),
                       constraints=[{'type': 'ineq', 'fun': lambda x: ev(x)[2],
                                     'jac': lambda x: ev(x)[3]}],
                       options={'maxiter': maxiter, 'ftol': FTOL})
        converged, message, nit = bool(res.success), str(res.message), int(res.nit)
    except _OutOfTime:
        converged, message, nit = False, 'the clock ran out', -1
    return OptimizeResult(x=ev.best_x, fun=ev.best_f, nit=nit, message=message,
                          success=converged and ev.best_x is not None)
