"""The capsule collision model: distances, hand-made poses, and no colliding output."""

from hypothesis import given, HealthCheck, settings, strategies as st
from namo_fault_recovery.model.capsules import CapsuleModel
from namo_fault_recovery.model.kinematics import batch_forward_jacobian, forward_kinematics
from namo_fault_recovery.objective.collision import CollisionModel, segment_distance
from namo_fault_recovery.objective.score import gesture_targets
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import RecoverySettings
from namo_fault_recovery.recovery.keyframes import reconfigure_library
import numpy as np
import pytest


def test_segment_distance_cases():
    p = np.array([[0.0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]])
    q = np.array([[1.0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0]])
    p2 = np.array([[0.5, -1, 1], [2, 0, 0], [0.5, 1, 0], [0, 1, 0]])
    q2 = np.array([[0.5, 1, 1], [3, 0, 0], [0.5, 2, 0], [1, 1, 0]])
    d, s, t = segment_distance(p, q, p2, q2)
    np.testing.assert_allclose(d, [1.0, 1.0, 1.0, 1.0])     # crossing above, collinear,
    np.testing.assert_allclose(s[[0, 1, 2]], [0.5, 1.0, 0.5])   # end-to-end, parallel


def _lm(robot, q, side):
    return forward_kinematics(robot, np.radians(np.atleast_2d(q)), side)


@pytest.fixture(scope='module')
def model(robot, library):
    return CollisionModel(robot, [t for g in library for t in gesture_targets(g)])


def test_reference_poses_and_rest_do_not_collide(robot, library, model):
    for k, g in enumerate(library):
        kf = g.keyframes[0]
        lm_r = forward_kinematics(robot, kf.right[None], 'right')
        lm_l = forward_kinematics(robot, kf.left[None], 'left')
        assert not model.collides(lm_r, lm_l, np.array([k]))[0], g.name
    zero = np.zeros(7)
    assert not model.collides(_lm(robot, zero, 'right'), _lm(robot, zero, 'left'),
                              np.array([1]))[0]


def test_wai_palms_touching_is_contact_not_collision(robot, model):
    wai = [30, 5, -45, 90, -10, -45, 45]
    lm_r, lm_l = _lm(robot, wai, 'right'), _lm(robot, wai, 'left')
    pen = model.penetration(lm_r, lm_l, np.array([0]))
    assert np.all(pen < 1e-9)
    # The same hands 12 mm closer than designed do collide.
    assert model.distances(lm_r, lm_l)[0][0, -1] == pytest.approx(31.65, abs=0.01)


def test_crossing_hands_collide(robot, model):
    # Wai with the hands pushed through each other: joint 1 swung further in.
    crossing = [30, 5, -70, 90, -10, -45, 45]
    lm_r, lm_l = _lm(robot, crossing, 'right'), _lm(robot, crossing, 'left')
    assert model.collides(lm_r, lm_l, np.array([0]))[0]
    pairs = model.colliding_pairs(lm_r, lm_l, np.array([0]))[0]
    assert any('right' in p and 'left' in p for p in pairs)


def test_arm_through_torso_collides_separated_does_not(robot, model):
    through = [0, 60, 0, 0, 0, 0, 0]    # upper arm swung in across the body
    apart = [0, -60, 0, 0, 0, 0, 0]     # raised out to the side
    rest = np.zeros(7)
    assert model.collides(_lm(robot, through, 'right'), _lm(robot, rest, 'left'),
                          np.array([1]))[0]
    assert not model.collides(_lm(robot, apart, 'right'), _lm(robot, rest, 'left'),
                              np.array([1]))[0]


def test_penalty_gradient_matches_finite_differences(robot, model):
    rng = np.random.default_rng(3)
    q = np.radians([30, 5, -70, 90, -10, -45, 45]) + rng.normal(0, 0.05, (6, 7))
    lm_l = forward_kinematics(robot, np.radians([[30, 5, -45, 90, -10, -45, 45]] * 6), 'left')
    lm_r, jac_r = batch_forward_jacobian(robot, q, 'right')
    target = np.zeros(6, dtype=int)
    value, grads = model.penalty(lm_r, lm_l, target, jac_r, None)
    assert np.all(value > 0)
    h = 1e-6
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = h
        up = model.penalty(forward_kinematics(robot, q + dq, 'right'), lm_l, target)[0]
        down = model.penalty(forward_kinematics(robot, q - dq, 'right'), lm_l, target)[0]
        np.testing.assert_allclose(grads['right'][:, i], (up - down) / (2 * h), rtol=1e-4,
                                   atol=1e-3)


def test_capsule_config_validation():
    with pytest.raises(ValueError, match='capsules.hand'):
        CapsuleModel(hand=-1.0)
    with pytest.raises(ValueError, match='capsules.torso_top'):
        CapsuleModel(torso_top=(0, 0))


# The keyframe search's own problem, the paper's: no stage 2, no collision term.
PAPER = RecoverySettings(bimanual='off', collision_check=False)
JOINTS = [f'{side}_arm_joint{k}' for side in ('right', 'left') for k in range(1, 8)]


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(faults=st.dictionaries(st.sampled_from(JOINTS),
                              st.one_of(st.none(), st.floats(-2.5, 2.5)), min_size=1,
                              max_size=3),
       seed=st.integers(0, 2 ** 31))
def test_no_published_pose_collides(robot, library, model, faults, seed):
    report = reconfigure_library(robot, library, faults, PAPER.with_changes(collision_check=True),
                                 seed=seed, clock=Clock(None))
    for k, g in enumerate(report.gestures):
        kf = g.keyframes[0]
        lm_r = forward_kinematics(robot, kf.right[None], 'right')
        lm_l = forward_kinematics(robot, kf.left[None], 'left')
        collides = model.collides(lm_r, lm_l, np.array([k]))[0]
        assert g.collides == collides
        # A pose may only collide if even its locked starting pose did (then the joint
        # lock itself forces the contact), and that is reported.
        if collides:
            ref = library[g.name].keyframes[0]
            base_r, base_l = ref.right.copy(), ref.left.copy()
            for joint, angle in report.locks.items():
                side, j = robot.locate_joint(joint)
                (base_r if side == 'right' else base_l)[j] = angle
            assert model.collides(forward_kinematics(robot, base_r[None], 'right'),
                                  forward_kinematics(robot, base_l[None], 'left'),
                                  np.array([k]))[0], (g.name, faults)
            assert 'collides' in g.message
