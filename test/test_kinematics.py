"""Forward kinematics against the spec's golden values, mirror symmetry and batching."""

from namo_fault_recovery import forward_kinematics
from namo_fault_recovery.model.kinematics import batch_forward, shoulder_position
import numpy as np
import pytest

GOLDEN = {
    'zero': ([0, 0, 0, 0, 0, 0, 0],
             (0, -182, -206.5), (0, -182, -412.5), (0, -182, -542.5)),
    'wai': ([30, 5, -45, 90, -10, -45, 45],
            (102.86, -164.00, -178.15), (222.66, -18.89, -94.33), (240.65, -15.83, 34.39)),
    'bye': ([46, -11, 24, 95, -53, -32, 41],
            (145.81, -221.40, -140.81), (251.91, -299.91, 17.35), (239.79, -277.72, 144.87)),
    'salute': ([100, -43, -45, 100, 47, 28, 10],
               (148.73, -322.83, 26.23), (194.40, -193.52, 179.94), (188.37, -75.37, 233.83)),
    'side_invite': ([34, -8, 45, 72, 51, 26, 26],
                    (114.35, -210.74, -169.53), (253.67, -356.79, -128.34),
                    (289.53, -446.04, -40.89)),
}
WAI_PALM = [[-0.1384, 0.9901, -0.0245], [-0.0236, -0.0280, -0.9993],
            [-0.9901, -0.1377, 0.0272]]


@pytest.mark.parametrize('name', sorted(GOLDEN))
def test_golden_landmarks(robot, name):
    q, elbow, wrist, tip = GOLDEN[name]
    lm = forward_kinematics(robot, np.radians(q))
    # The spec rounds to 0.01 mm, so the exact values lie within 0.005 mm of them.
    np.testing.assert_allclose(lm.elbow, elbow, atol=0.005 + 1e-9)
    np.testing.assert_allclose(lm.wrist, wrist, atol=0.005 + 1e-9)
    np.testing.assert_allclose(lm.tip, tip, atol=0.005 + 1e-9)


def test_golden_wai_palm(robot):
    lm = forward_kinematics(robot, np.radians(GOLDEN['wai'][0]))
    np.testing.assert_allclose(lm.palm, WAI_PALM, atol=5e-5)
    np.testing.assert_allclose(lm.palm @ lm.palm.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(lm.palm) == pytest.approx(1.0)


def test_wai_hands_meet(robot):
    q = np.radians(GOLDEN['wai'][0])
    right = forward_kinematics(robot, q, 'right')
    left = forward_kinematics(robot, q, 'left')
    assert np.linalg.norm(right.wrist - left.wrist) == pytest.approx(37.785, abs=1e-3)
    assert np.linalg.norm(right.tip - left.tip) == pytest.approx(31.653, abs=1e-3)


def test_mirror_symmetry(robot):
    rng = np.random.default_rng(1)
    q = rng.uniform(-np.pi, np.pi, size=(50, 7))
    right = forward_kinematics(robot, q, 'right')
    left = forward_kinematics(robot, q, 'left')
    flip = np.array([1.0, -1.0, 1.0])
    for a, b in ((right.elbow, left.elbow), (right.wrist, left.wrist), (right.tip, left.tip)):
        np.testing.assert_allclose(b, a * flip, atol=1e-9)
    m = np.diag(flip)
    np.testing.assert_allclose(left.palm, m @ right.palm @ m, atol=1e-12)
    np.testing.assert_allclose(shoulder_position(robot, 'left'), [0, 182, 0], atol=1e-9)


def test_batch_equals_one_at_a_time(robot):
    rng = np.random.default_rng(2)
    q = rng.uniform(-np.pi, np.pi, size=(20, 7))
    batch = forward_kinematics(robot, q)
    for i in range(len(q)):
        single = forward_kinematics(robot, q[i])
        for a, b in zip(batch, single):
            np.testing.assert_allclose(a[i], b, atol=1e-12)
    # Arbitrary leading shapes are kept.
    grid = forward_kinematics(robot, q.reshape(4, 5, 7))
    assert grid.palm.shape == (4, 5, 3, 3)
    np.testing.assert_allclose(grid.tip.reshape(20, 3), batch.tip)


def test_link_lengths_are_rigid(robot):
    rng = np.random.default_rng(3)
    lm = forward_kinematics(robot, rng.uniform(-np.pi, np.pi, size=(100, 7)))
    shoulder = shoulder_position(robot)
    np.testing.assert_allclose(np.linalg.norm(lm.elbow - shoulder, axis=1), 206.5)
    np.testing.assert_allclose(np.linalg.norm(lm.wrist - lm.elbow, axis=1), 206.0)
    np.testing.assert_allclose(np.linalg.norm(lm.tip - lm.wrist, axis=1), 130.0)


@pytest.mark.parametrize('bad, message', [
    (np.zeros(6), r'shape \(\.\.\., 7\)'),
    (np.array([0, 0, np.nan, 0, 0, 0, 0]), 'finite'),
])
def test_bad_input(robot, bad, message):
    with pytest.raises(ValueError, match=message):
        forward_kinematics(robot, bad)
    with pytest.raises(ValueError, match='arm'):
        forward_kinematics(robot, np.zeros(7), 'middle')


def test_a_robot_made_anew_for_each_run_does_not_grow_the_kinematics_caches(robot):
    # The engine child makes a new robot object per run (with_learned, a tool); caches
    # keyed by the object held every one of them: a slow leak in a long-running node.
    from dataclasses import replace
    from namo_fault_recovery.model import kinematics
    q = np.zeros((1, 7))
    batch_forward(robot, q, 'right')
    flips = kinematics.equivalent_flips(robot, 'right')
    plans, answers = len(kinematics._PLANS), len(kinematics._FLIPS)
    for length in (0.0, 0.0, 50.0, 50.0):
        again = replace(robot.with_tool(length), learned=())
        batch_forward(again, q, 'right')
        assert kinematics.equivalent_flips(again, 'right') == flips
    assert len(kinematics._PLANS) == plans
    assert len(kinematics._FLIPS) <= answers + 1          # the 50 mm tool's own answer
