"""Whole-trajectory optimisation: gradient, warm start, locks, bounds, smoothness, solvers."""

from pathlib import Path

from namo_fault_recovery import load_library
from namo_fault_recovery.model.gestures import GestureLibrary
from namo_fault_recovery.objective.collision import CollisionModel
from namo_fault_recovery.objective.score import gesture_targets, SimilarityScore
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import RecoverySettings
from namo_fault_recovery.recovery.motion import adapt_library
from namo_fault_recovery.recovery.trajectory_opt import optimise_trajectory
from namo_fault_recovery.recovery.trajectory_opt import projected_lbfgs, TrajectoryProblem
from namo_fault_recovery.resources import DEMO_MOTION_FILE
import numpy as np
import pytest

CONFIG_DIR = Path(__file__).resolve().parent.parent / 'config'
ELBOW = 'right_arm_joint4'
# The keyframe search's own problem, the paper's: no stage 2, no collision term.
PAPER = RecoverySettings(bimanual='off', collision_check=False)
FREE = (('right', 0), ('right', 1), ('right', 2), ('right', 4), ('right', 5), ('right', 6))


@pytest.fixture(scope='module')
def circle(robot):
    """Load the dense circle from the demo library of motions."""
    return load_library(robot, CONFIG_DIR / DEMO_MOTION_FILE)['circle']


def _problem(robot, gesture, points, start=None, collision=False, **kw):
    """Build the problem of the first ``points`` points, elbow locked at 0, from ``start``."""
    design = gesture.joint_matrix()[:points]
    targets = gesture_targets(gesture, range(points))
    scorer = SimilarityScore(robot, targets, reference_robot=robot)
    start = design.copy() if start is None else start[:points]
    start[:, 3] = 0.0
    checker = CollisionModel(robot, targets, robot.capsules) if collision else None
    return TrajectoryProblem(robot, scorer, np.arange(points), (start[:, :7], start[:, 7:]),
                             FREE, collision=checker, **kw)


@pytest.mark.parametrize('collision', [False, True])
def test_gradient_matches_finite_differences(robot, circle, collision):
    problem = _problem(robot, circle, 8, step_cap_deg=1.0, step_penalty=1.0,
                       smoothness=0.05, collision=collision)
    rng = np.random.default_rng(0)
    x = np.clip(problem.x0 + rng.normal(scale=0.05, size=problem.x0.shape),
                problem.lower + 1e-3, problem.upper - 1e-3)
    f, g = problem.value_and_grad(x)
    assert f == pytest.approx(problem.value(x), rel=1e-12)
    h = 1e-6
    fd = np.array([(problem.value(x + h * e) - problem.value(x - h * e)) / (2 * h)
                   for e in np.eye(x.size)])
    np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-3 * np.abs(fd).max())


@pytest.fixture(scope='module')
def kriging_start(robot, circle):
    lib = GestureLibrary((circle,), '<test>')
    g = adapt_library(robot, lib, {ELBOW: 0.0},
                      PAPER.with_changes(trajectory_method='kriging', collision_check=True),
                      clock=Clock(None), seed=0)['circle']
    return np.array([kf.positions() for kf in g.keyframes])


def test_optimised_trajectory_beats_its_kriging_start_keeps_locks_and_bounds(
        robot, circle, kriging_start):
    problem = _problem(robot, circle, 100, start=kriging_start.copy(), step_cap_deg=3.6,
                       collision=True)
    res = optimise_trajectory(problem, Clock(None), maxiter=40)
    assert res.value < res.value_start
    assert res.value == pytest.approx(problem.value(problem.gather(res.q_right, res.q_left)))
    assert np.all(res.q_right[:, 3] == 0.0)                      # the lock, bit for bit
    np.testing.assert_array_equal(res.q_left, kriging_start[:, 7:])   # not free
    arm = robot.arms['right']
    assert np.all(res.q_right >= arm.lower) and np.all(res.q_right <= arm.upper)


def test_bounds_hold_when_the_optimum_lies_beyond_them(robot, circle):
    problem = _problem(robot, circle, 10)
    # Tight bounds around the start: the unconstrained optimum is outside.
    problem.lower = problem.x0 - 0.01
    problem.upper = problem.x0 + 0.01
    problem.x0 = problem.x0 + 0.01
    res = optimise_trajectory(problem, Clock(None), maxiter=30)
    x = problem.gather(res.q_right, res.q_left).ravel()
    assert np.all(x >= problem.lower) and np.all(x <= problem.upper)
    assert res.value <= res.value_start


def test_step_hinge_bounds_the_largest_step(robot, circle):
    # Targets with a 20 deg jump of joint 1 in the middle: the score alone follows it.
    design = circle.joint_matrix()[:12].copy()
    design[6:, 0] += np.radians(20.0)
    frames = [type(kf)(kf.time_from_start, design[i, :7], design[i, 7:])
              for i, kf in enumerate(circle.keyframes[:12])]
    jumpy = circle.with_keyframes(frames)
    free = _problem(robot, jumpy, 12, start=design.copy(), smoothness=0.0)
    capped = _problem(robot, jumpy, 12, start=design.copy(), smoothness=0.01,
                      step_cap_deg=4.0, step_penalty=10.0)
    res_free = optimise_trajectory(free, Clock(None), maxiter=100)
    res_capped = optimise_trajectory(capped, Clock(None), maxiter=300)
    assert free.max_step_deg(free.gather(res_free.q_right, res_free.q_left)) > 15.0
    assert capped.max_step_deg(capped.gather(res_capped.q_right, res_capped.q_left)) < 6.0


def test_numpy_lbfgs_matches_scipy(robot, circle, kriging_start):
    problem = _problem(robot, circle, 30, start=kriging_start.copy(), step_cap_deg=3.6)
    ours = optimise_trajectory(problem, Clock(None), maxiter=400, solver='lbfgs')
    ref = optimise_trajectory(problem, Clock(None), maxiter=400, solver='scipy')
    assert ours.value == pytest.approx(ref.value, rel=2e-3, abs=0.5)


@pytest.mark.parametrize('collision', [False, True])
def test_banded_hessian_matches_finite_differences(robot, circle, collision):
    problem = _problem(robot, circle, 6, step_cap_deg=0.5, step_penalty=1.0,
                       smoothness=0.05, collision=collision)
    rng = np.random.default_rng(2)
    x = np.clip(problem.x0 + rng.normal(scale=0.05, size=problem.x0.shape),
                problem.lower + 1e-3, problem.upper - 1e-3)
    n, dim = problem.n_points, problem.dim
    h = 1e-6
    g = problem.value_and_grad(x)[1]
    full = np.array([(problem.value_and_grad(x + h * e)[1] - g) / h for e in np.eye(x.size)])
    full = 0.5 * (full + full.T)
    blocks = problem.point_hessians(x.reshape(n, dim))
    diag, off = problem.step_hessian(x.reshape(n, dim))
    assert np.any(off < -2.0 * problem.smoothness)          # the hinge is active somewhere
    ours = np.zeros_like(full)
    for t in range(n):
        ours[t * dim:(t + 1) * dim, t * dim:(t + 1) * dim] = blocks[t]
        for j in range(dim):
            ours[t * dim + j, t * dim + j] += diag[t, j]
            if t < n - 1:
                ours[t * dim + j, (t + 1) * dim + j] = ours[(t + 1) * dim + j, t * dim + j] = \
                    off[t, j]
    np.testing.assert_allclose(ours, full, atol=1e-4 * np.abs(full).max())


def test_newton_converges_where_lbfgs_stops_on_its_cap(robot, circle, kriging_start):
    problem = _problem(robot, circle, 30, start=kriging_start.copy(), step_cap_deg=3.6,
                       smooth=1.0)
    lbfgs = optimise_trajectory(problem, Clock(None), maxiter=100, solver='lbfgs')
    newton = optimise_trajectory(problem, Clock(None), solver='newton')
    assert lbfgs.status == 'iterations'
    assert newton.status == 'converged' and newton.nit < 100
    assert newton.value < lbfgs.value
    x = problem.gather(newton.q_right, newton.q_left).ravel()
    assert np.all(x >= problem.lower) and np.all(x <= problem.upper)


def test_projected_lbfgs_solves_a_bounded_quadratic():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(20, 20))
    hess = a @ a.T + np.eye(20)
    b = rng.normal(size=20) * 5

    def fun(x):
        return 0.5 * x @ hess @ x - b @ x, hess @ x - b

    lower, upper = -np.ones(20), np.ones(20)
    x = np.zeros(20)
    best = {'f': np.inf}

    def track(z):
        f, g = fun(z)
        if f < best['f']:
            best['f'], best['x'] = f, z.copy()
        return f, g

    projected_lbfgs(track, x, lower, upper, maxiter=500, ftol=1e-14, gtol=1e-9)
    from scipy.optimize import minimize
    ref = minimize(fun, x, jac=True, method='L-BFGS-B', bounds=list(zip(lower, upper)),
                   options={'ftol': 1e-14, 'gtol': 1e-10})
    assert fun(best['x'])[0] == pytest.approx(ref.fun, rel=1e-6)


def test_auto_optimises_the_whole_circle(robot, circle, kriging_start):
    lib = GestureLibrary((circle,), '<test>')
    res = adapt_library(robot, lib, {ELBOW: 0.0},
                        PAPER.with_changes(trajectory_method='auto', collision_check=True),
                        clock=Clock(None), seed=0)
    g = res['circle']
    kriging = adapt_library(robot, lib, {ELBOW: 0.0},
                            PAPER.with_changes(trajectory_method='kriging', collision_check=True),
                            clock=Clock(None), seed=0)['circle']
    assert g.method == 'trajectory'
    assert g.tip_error_mm < kriging.tip_error_mm
    assert g.score_mean < kriging.score_mean
    assert all(kf.right[3] == 0.0 for kf in g.keyframes)
    assert g.max_jump_deg <= 1.5 * g.max_jump_designed_deg
