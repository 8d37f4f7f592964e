"""The capsules' clearances as hard constraints (objective/collision, recovery/constrained)."""

from pathlib import Path

from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.model.kinematics import batch_forward, batch_forward_jacobian
from namo_fault_recovery.model.profile_robot import robot_from_profile
from namo_fault_recovery.objective.collision import CollisionModel
from namo_fault_recovery.objective.score import gesture_targets, SimilarityScore
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.constrained import constrained_pose
from namo_fault_recovery.recovery.engine import recover
from namo_fault_recovery.recovery.keyframes import PoseProblem
from namo_fault_recovery.recovery.settings import RecoverySettings
import numpy as np
import pytest

ROBOTS = Path(__file__).resolve().parent.parent / 'config' / 'robots'
# Talos's Wai with its right arm_3 locked at the library's mean: the penalised searches
# end at 38.86-38.98, the best clear pose is 37.66 (recovery/constrained.py).
LOCK = {'arm_right_3_joint': -0.9967973147764968}


@pytest.fixture(scope='module')
def talos():
    robot = robot_from_profile(ROBOTS / 'talos.yaml')
    return robot, load_library(robot, ROBOTS / 'talos_gestures.yaml')


def _wai_poses(robot, library, n, seed):
    """Return (checker, right, left, ids): Wai's capsules and n poses scattered about it."""
    rng = np.random.default_rng(seed)
    ref = library['wai'].joint_matrix()[0]
    nr = len(robot.arms['right'].joint_names)
    checker = CollisionModel(robot, gesture_targets(library['wai']), robot.capsules)
    return (checker, ref[:nr] + rng.normal(0, 0.3, (n, nr)),
            ref[nr:] + rng.normal(0, 0.3, (n, nr)), np.zeros(n, dtype=int))


def test_clearance_rates_are_the_derivatives_of_the_margins(robot, library):
    checker, qr, ql, ids = _wai_poses(robot, library, 30, seed=1)
    lm_r, jac_r = batch_forward_jacobian(robot, qr, 'right')
    lm_l, jac_l = batch_forward_jacobian(robot, ql, 'left')
    margin, rates = checker.clearance(lm_r, lm_l, ids, jac_r, jac_l)
    assert np.any(margin < 0) and np.any(margin > 0)      # both sides of the boundary
    h = 1e-6
    for j in range(qr.shape[1]):
        step = np.eye(qr.shape[1])[j] * h
        up = checker.clearance(batch_forward(robot, qr + step, 'right'), lm_l, ids)[0]
        down = checker.clearance(batch_forward(robot, qr - step, 'right'), lm_l, ids)[0]
        np.testing.assert_allclose(rates['right'][:, :, j], (up - down) / (2 * h), atol=1e-4)
        up = checker.clearance(lm_r, batch_forward(robot, ql + step, 'left'), ids)[0]
        down = checker.clearance(lm_r, batch_forward(robot, ql - step, 'left'), ids)[0]
        np.testing.assert_allclose(rates['left'][:, :, j], (up - down) / (2 * h), atol=1e-4)


def test_penalty_gradient_is_built_from_the_same_rates(robot, library):
    checker, qr, ql, ids = _wai_poses(robot, library, 30, seed=2)
    lm_r, jac_r = batch_forward_jacobian(robot, qr, 'right')
    lm_l = batch_forward(robot, ql, 'left')
    value, grads = checker.penalty(lm_r, lm_l, ids, jac_r)
    margin, rates = checker.clearance(lm_r, lm_l, ids, jac_r)
    gap = np.maximum(-margin, 0.0)
    assert np.any(gap > 0)
    np.testing.assert_allclose(value, checker.capsules.weight * np.sum(gap ** 2, axis=1))
    np.testing.assert_allclose(grads['right'], np.einsum(
        'np,npj->nj', -2.0 * checker.capsules.weight * gap, rates['right']), atol=1e-9)


def _wai_problem(robot, library):
    targets = gesture_targets(library['wai'])
    scorer = SimilarityScore(robot, targets)
    checker = CollisionModel(robot, targets, robot.capsules).shaped()
    ref = library['wai'].joint_matrix()[0]
    nr = len(robot.arms['right'].joint_names)
    right = ref[:nr].copy()
    locked = robot.arms['right'].joint_names.index('arm_right_3_joint')
    right[locked] = LOCK['arm_right_3_joint']
    free = tuple(('right', j) for j in range(nr) if j != locked)
    problem = PoseProblem(robot, scorer, [0], (right[None], ref[None, nr:]), free)
    return problem, scorer, checker


def test_the_constrained_pose_is_clear_and_finds_the_best_wai_on_talos(talos):
    robot, library = talos
    problem, scorer, checker = _wai_problem(robot, library)
    res = constrained_pose(problem, checker, Clock(None))
    assert res.success and res.nit > 0
    qr, ql = problem.assemble(res.x[None])
    lm_r, lm_l = batch_forward(robot, qr, 'right'), batch_forward(robot, ql, 'left')
    assert not checker.collides(lm_r, lm_l, np.array([0]))[0]
    assert scorer.evaluate(lm_r, lm_l, np.array([0]))[0] < 37.7       # 38.86+ penalised


def test_an_expired_clock_returns_at_most_the_clear_poses_evaluated(talos):
    robot, library = talos
    problem, _, checker = _wai_problem(robot, library)
    clock = Clock(1e-9)
    while not clock.expired():
        pass
    res = constrained_pose(problem, checker, clock)
    assert res.x is None and not res.success and res.message == 'the clock ran out'


def test_the_engine_reaches_the_best_clear_wai(talos):
    robot, library = talos
    for seed in (0, 1):          # no deadline: what is checked is the search, not its speed
        result = recover(robot, library, LOCK, RecoverySettings(), seed=seed,
                         clock=Clock(None))
        assert not result['wai'].collides
        assert result['wai'].score_after < 37.7


def test_the_torso_shapes_distance_derivatives_are_exact_where_it_decides(talos):
    robot, library = talos
    checker, qr, ql, ids = _wai_poses(robot, library, 200, seed=3)
    checker = checker.shaped()
    lm_l = batch_forward(robot, ql, 'left')
    lm_r, jac_r = batch_forward_jacobian(robot, qr, 'right')
    _, _, _, normal = checker.closest(lm_r, lm_l)
    shaped = np.any(normal != 0.0, axis=-1)          # (N, pairs): the shape decides these
    assert shaped.sum() >= 20
    rates = checker.clearance(lm_r, lm_l, ids, jac_r)[1]['right']
    h = 1e-6
    for j in range(qr.shape[1]):
        step = np.eye(qr.shape[1])[j] * h
        up = checker.clearance(batch_forward(robot, qr + step, 'right'), lm_l, ids)[0]
        down = checker.clearance(batch_forward(robot, qr - step, 'right'), lm_l, ids)[0]
        numeric = (up - down) / (2 * h)
        # The nearest of the sampled points can change within the step: skip such rows.
        same = np.abs(numeric - rates[:, :, j]) < 1e-3 * (1.0 + np.abs(numeric))
        assert same[shaped].mean() > 0.97, same[shaped].mean()
