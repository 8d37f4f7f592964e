"""The played path bent clear of the body where the straight one presses it (no ROS)."""

import math

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.model.self_contact import undesigned_depth
from namo_fault_recovery.playback.blend import resume
from namo_fault_recovery.playback.clearance import PathClearance
from namo_fault_recovery.playback.timing import plan_motion
import numpy as np
import pytest

ROBOT = load_robot()
LIBRARY = load_library(ROBOT)
NAMES = ROBOT.joint_names
LIMITS = np.array(ROBOT.velocity_limits * 2)
CLEARANCE = PathClearance(ROBOT, NAMES)
# Left joint 3 stuck at Wai's own -45 deg: the arm starts from rest with it there, and the
# straight approach brings the palms 11 mm through each other before the key pose.
CROSSING = {'left_arm_joint3': math.radians(-45.0)}


def wai(locks, clearance, name='wai'):
    g = LIBRARY[name]
    frames = [np.concatenate([kf.right, kf.left]) for kf in g.keyframes]
    return plan_motion(NAMES, np.zeros(14), [kf.time_from_start for kf in g.keyframes],
                       frames, LIMITS, locks=locks, clearance=clearance)


def path_depth(plan):
    t = np.arange(0.0, plan.duration + 0.01, 0.01)
    return undesigned_depth(ROBOT, LIBRARY['wai'], plan.command_at(t))


def test_a_path_that_presses_the_palms_through_each_other_is_bent_clear():
    straight, bent = wai(CROSSING, None), wai(CROSSING, CLEARANCE)
    assert path_depth(straight) > 10.0                  # the case is real
    assert path_depth(bent) <= 1.0
    assert len(bent.knots) == len(straight.knots) + 1   # one via pose
    # The gesture is the same: its waypoints at their times, no slower, the lock held.
    np.testing.assert_allclose(bent.waypoint_times, straight.waypoint_times)
    np.testing.assert_allclose(bent.command_at(bent.waypoint_times), straight.waypoints,
                               atol=1e-9)
    assert bent.stretch == pytest.approx(1.0)
    column = NAMES.index('left_arm_joint3')
    assert np.ptp(bent.positions[:, column]) == 0.0
    assert np.all(np.abs(bent.velocities) <= LIMITS + 1e-9)


@pytest.mark.parametrize('name', ['bye', 'salute', 'side_invite'])
def test_a_clear_path_is_played_as_it_was(name):
    straight, checked = wai(None, None, name), wai(None, CLEARANCE, name)
    np.testing.assert_array_equal(checked.knots, straight.knots)
    np.testing.assert_array_equal(checked.positions, straight.positions)


def test_the_designed_palms_are_pressed_no_deeper_on_the_way_than_at_the_key_pose():
    """The reference Wai's approach presses the hands 0.53 mm deeper than its key pose."""
    straight, bent = wai(None, None), wai(None, CLEARANCE)
    key = CLEARANCE.depths(straight.waypoints).max(axis=0)
    for plan, most in ((straight, 0.5), (bent, 0.05)):
        t = np.arange(0.0, plan.duration, 0.01)
        deeper = np.max(CLEARANCE.depths(plan.command_at(t)) - key)
        assert (deeper > most) == (plan is straight), deeper


def test_the_rest_of_a_bent_plan_follows_its_via_pose():
    bent = wai(CROSSING, CLEARANCE)
    t = 0.3 * bent.knots[1]                  # before the via pose
    rest = resume(bent, t)
    tau = np.linspace(0.0, bent.duration - t, 50)
    np.testing.assert_allclose(rest.command_at(tau), bent.command_at(t + tau), atol=1e-9)


def test_a_path_with_one_arm_played_cannot_be_checked():
    with pytest.raises(ValueError, match="'left_arm_joint1' is not among the played joints"):
        PathClearance(ROBOT, NAMES[:7])


def test_an_arm_swung_through_the_torso_of_another_robot_goes_round_it():
    """TIAGo++: the idle left arm moved clear with its elbow stuck; straight, 117 mm deep."""
    from namo_fault_recovery.model.profile_robot import robot_from_profile
    from namo_fault_recovery.model.self_contact import penetrations
    from namo_fault_recovery.resources import config_path
    robot = robot_from_profile(config_path('robots/tiago_dual.yaml'))
    names = robot.joint_names
    limits = np.tile(np.asarray(robot.velocity_limits, dtype=float), 2)
    key = np.zeros(14)
    # The engine's Bye (seed 1000), clear of the torso's shape (model.torso_field).
    key[7:] = np.radians([19.4, 85.6, 215.0, 122.4, -120.0, -2.2, -106.9])
    locks = {'arm_left_4_joint': math.radians(122.4)}
    plans = [plan_motion(names, np.zeros(14), [1.0], [key], limits, locks=locks,
                         clearance=c) for c in (None, PathClearance(robot, names))]
    depth = [penetrations(robot, p.command_at(np.arange(0.0, p.duration, 0.01))).max()
             for p in plans]
    assert depth[0] > 50.0 and depth[1] <= 1.0
    assert plans[1].duration == pytest.approx(plans[0].duration)
    np.testing.assert_allclose(plans[1].final, plans[0].final)
