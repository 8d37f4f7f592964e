"""The keyframe search ends on the kinematic twin nearest the design (recovery.twins)."""

import math
from pathlib import Path

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.benchmarks.common import case_problems
from namo_fault_recovery.model.kinematics import batch_forward, equivalent_twins, split_arms
from namo_fault_recovery.model.profile_robot import robot_from_profile
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import recover, RecoverySettings
from namo_fault_recovery.recovery.keyframes import joint_bounds
from namo_fault_recovery.recovery.least_squares import refine, refine_basins
from namo_fault_recovery.recovery.twins import best_twins, pose_twins, twin_angles
import numpy as np
import pytest

ROBOT = load_robot()
LIBRARY = load_library(ROBOT)
NAMES = list(ROBOT.joint_names)
ELBOW = NAMES.index('right_arm_joint4')
STUCK = math.radians(44.8)          # where the CI run's elbow stuck mid-wai
BOUNDS = joint_bounds(ROBOT)
RIGHT = tuple(('right', j) for j in range(7) if j != ELBOW)


def _wai_design():
    design = np.array(LIBRARY['wai'].keyframes[-1].positions(), dtype=float)
    design[ELBOW] = STUCK
    return design


def _landmarks(q):
    right, left = split_arms(ROBOT, np.atleast_2d(q))
    return batch_forward(ROBOT, right, 'right'), batch_forward(ROBOT, left, 'left')


def _shoulder_twin(q, design):
    """Return the far reading of the right shoulder (joints 1-3), as the colony found it."""
    (i, j, k, mirror), = [t for t in equivalent_twins(ROBOT, 'right') if t[0] == 0]
    twin = twin_angles(np.atleast_2d(q), (i, j, k), mirror, np.atleast_2d(design), *BOUNDS)
    assert twin is not None
    return twin[0]


def _tip_distance(q):
    """Return a stand-in value: the right fingertip's distance from the design's (mm)."""
    design = _landmarks(_wai_design())[0].tip
    return np.linalg.norm(_landmarks(q)[0].tip - design, axis=-1)


def test_a_far_twin_is_taken_back_to_the_one_nearest_the_design():
    design = _wai_design()
    near = design.copy()
    near[[0, 1, 2]] += np.radians([3.0, -2.0, 4.0])     # a solved pose near the design
    far = _shoulder_twin(near, design)
    assert np.max(np.abs(far - near)) > math.radians(90.0)
    for a, b in zip(_landmarks(near)[0], _landmarks(far)[0]):
        np.testing.assert_allclose(a, b, atol=1e-9)          # twins: every landmark
    q, changed = best_twins(ROBOT, far[None], design[None], [RIGHT], [0],
                            lambda poses, rows: _tip_distance(poses), BOUNDS)
    assert changed == [0]
    np.testing.assert_allclose(q[0], near, atol=1e-9)
    # the near one stays as it is
    q, changed = best_twins(ROBOT, near[None], design[None], [RIGHT], [0],
                            lambda poses, rows: _tip_distance(poses), BOUNDS)
    assert changed == [] and np.array_equal(q[0], near)


def test_one_combination_per_gesture_and_never_a_worse_value():
    design = _wai_design()
    near = design.copy()
    far = _shoulder_twin(near, design)
    poses = np.stack([far, far, near])
    designs = np.stack([design] * 3)
    owners = [0, 0, 1]
    q, changed = best_twins(ROBOT, poses, designs, [RIGHT] * 3, owners,
                            lambda p, rows: _tip_distance(p), BOUNDS)
    assert changed == [0, 1]
    np.testing.assert_allclose(q[:2], np.stack([near, near]), atol=1e-9)
    # a value that the twin makes worse (a capsule it would press, say): left alone
    q, changed = best_twins(ROBOT, poses, designs, [RIGHT] * 3, owners,
                            lambda p, rows: np.abs(p[:, 0] - far[0]), BOUNDS)
    assert changed == [] and np.array_equal(q, poses)


def test_a_locked_or_idle_joint_is_never_turned():
    design = _wai_design()
    far = _shoulder_twin(design, design)
    for layout in ([p for p in RIGHT if p != ('right', 1)], []):
        q, changed = best_twins(ROBOT, far[None], design[None], [tuple(layout)], [0],
                                lambda p, rows: _tip_distance(p), BOUNDS)
        assert changed == [] and np.array_equal(q[0], far)


def test_a_twin_beyond_the_joint_limits_is_not_taken():
    design = _wai_design()
    lower, upper = (b.copy() for b in BOUNDS)
    far = _shoulder_twin(design, design)
    upper[1] = design[1] + 0.1          # the near reading of joint 2 is now out of reach
    lower[1] = far[1] - 0.1
    q, changed = best_twins(ROBOT, far[None], design[None], [RIGHT], [0],
                            lambda p, rows: _tip_distance(p), (lower, upper))
    assert changed == [] and np.array_equal(q[0], far)


@pytest.mark.parametrize('seed', [0, 8, 12, 14, 26])
def test_wai_with_the_elbow_stuck_stays_on_the_designs_shoulder_branch(seed):
    """
    Keep the shoulder on the design's twin: the far one scores the same, played through the body.

    The carry-on test's failures in CI.

    Before the twins were taken, seeds 8, 12 and 26 (of 30) ended with the right
    shoulder at about (-131, 158, 139) deg, the design's (49, 22, -41) turned over: the
    arm swung 122 mm through the torso on its way from rest, and on the simulator it
    pressed the torso until a healthy joint read as stuck.
    """
    result = recover(ROBOT, LIBRARY, {'right_arm_joint4': STUCK},
                     RecoverySettings(deadline_sec=1.0), seed=seed)
    pose = np.asarray(result['wai'].positions[-1], dtype=float)
    design = _wai_design()
    assert pose[ELBOW] == pytest.approx(STUCK)
    shoulder = np.degrees(np.abs(pose[:3] - design[:3]))
    assert np.all(shoulder < 45.0), (seed, np.degrees(pose[:7]).round(1))


@pytest.mark.parametrize('seed', [3, 4, 5, 6])
def test_twins_that_share_the_locked_joint_are_taken_together(seed):
    """
    Namo's wai with right joint 3 stuck at 15 deg: the far branch is three twins at once.

    Joint 3 belongs to the shoulder's and the elbow's twins, so neither alone may be taken;
    the shoulder, elbow and wrist twins together turn it by a whole turn, which leaves it
    where it is.  Seeds 3-6 ended there (shoulder (-58, 145) deg, elbow +90) with the path
    from rest 143 mm through the torso; the combination puts the shoulder back at (122,
    35) with the elbow at -90, and the path is clear (the player's own plan, judged as
    ``bench playability`` judges it).
    """
    from namo_fault_recovery.benchmarks.playability import play_figures
    result = recover(ROBOT, LIBRARY, {'right_arm_joint3': math.radians(15.0)},
                     RecoverySettings(deadline_sec=1.0), seed=seed)
    wai = result['wai']
    pose = np.degrees(np.asarray(wai.positions[-1], dtype=float))
    assert pose[2] == pytest.approx(15.0)
    assert pose[0] > 90.0 and pose[1] < 90.0, pose[:7].round(1)
    _, _, depth, _ = play_figures(ROBOT, wai, result.locks, reference=LIBRARY['wai'])
    assert depth <= 1.0, (depth, pose[:7].round(1))


def test_the_twin_of_a_pose_held_by_a_limit_is_refined_to_the_better_floor():
    """TIAGo++'s side_invite, right joint 4 locked: the colony's best with joint 7 at 120 deg."""
    robots = Path(__file__).resolve().parent.parent / 'config' / 'robots'
    robot = robot_from_profile(robots / 'tiago_dual.yaml')
    library = load_library(robot, robots / 'tiago_dual_gestures.yaml')
    problem, _ = case_problems(robot, library, 'side_invite', {'arm_right_4_joint': None})
    held = np.radians([[49.532, 74.903, -11.558, -77.655, -18.575, 120.0]])
    f_held = problem.evaluate(held[:, None])[:, 0]
    twins = pose_twins(problem, held)
    assert twins.shape == (1, 1, 6)          # the wrist (joints 5-7), all three free
    assert np.degrees(twins[0, 0, 5]) == pytest.approx(-60.0)
    assert problem.evaluate(twins)[0, 0] == pytest.approx(f_held[0], rel=1e-9)
    alone = refine(problem, held, f_held, Clock(None))[1][0]
    x, f, _ = refine_basins(problem, held, f_held, (twins, problem.evaluate(twins)),
                            Clock(None))
    # Best-known 33.15; the branch held by the limit ends 1.5 % above it.
    assert alone > 33.6 and f[0] < 33.25 and abs(np.degrees(x[0, 5]) + 31.6) < 2.0
    # A problem that holds one of the three joints has no twin of them.
    wrist_held, _ = case_problems(robot, library, 'side_invite', {'arm_right_6_joint': None})
    assert pose_twins(wrist_held, wrist_held.x0).shape == (1, 0, 6)
