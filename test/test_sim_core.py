"""
The simulator's parts without ROS: the trajectory controller's rules and the physics.

The physics runs in simulated time here (no clock, no threads): stepped by hand.
"""

import math

from namo_fault_recovery.sim.physics import contact_pairs, designed_allowances, NamoSim
from namo_fault_recovery.sim.trajectory import (ActiveTrajectory, Command, Point, Rejected,
                                                validate)
import numpy as np
import pytest

JOINTS = tuple(f'right_arm_joint{i}' for i in range(1, 8))
Q = tuple([0.1] * 7)


def command(points, names=JOINTS, stamp=0.0):
    return Command(tuple(names), stamp, tuple(points))


@pytest.mark.parametrize('cmd, reason', [
    (command([Point(1.0, Q)], names=JOINTS[:6] + ('right_arm_joint8',)),
     "incoming joint right_arm_joint8 doesn't match"),
    (command([Point(1.0, Q)], names=JOINTS[:6] + ('left_arm_joint7',)),
     "incoming joint left_arm_joint7 doesn't match"),
    (command([Point(1.0, Q[:6])], names=JOINTS[:6]), "don't match the controller's joints"),
    (command([]), 'empty trajectory'),
    (command([Point(1.0, Q), Point(1.0, Q)]), 'not strictly increasing'),
    (command([Point(1.0, Q), Point(0.5, Q)]), 'not strictly increasing'),
    (command([Point(1.0, Q[:5])]), 'positions (5) at point #0'),
    (command([Point(1.0, Q, velocities=(0.0,) * 3)]), 'velocities (3)'),
    (command([Point(1.0, Q, velocities=(0.1,) * 7)]), 'last trajectory point is not zero'),
    (command([Point(1.0, Q, effort=(1.0,) * 7)]), 'effort'),
    (command([Point(1.0, (math.nan,) * 7)]), 'finite'),
    (command([Point(1.0, Q)], stamp=100.0 - 5.0), 'ends in the past'),
    (command([Point(1.0, Q)], names=JOINTS[:6] + (JOINTS[0],)), 'duplicate'),
])
def test_controller_rejects_with_the_reason(cmd, reason):
    with pytest.raises(Rejected) as info:
        validate(cmd, JOINTS, now=100.0)
    assert reason in str(info.value)


def test_controller_accepts_what_the_real_one_accepts():
    validate(command([Point(0.5, Q), Point(1.0, Q)]), JOINTS, now=100.0)
    validate(command([Point(1.0, Q)], names=tuple(reversed(JOINTS))), JOINTS, now=100.0)
    # A past stamp whose trajectory still runs is joined mid-way, as the real one does.
    validate(command([Point(2.0, Q)], stamp=99.0), JOINTS, now=100.0)
    validate(command([Point(1.0, Q[:2])], names=JOINTS[:2]), JOINTS, now=100.0,
             allow_partial=True)
    validate(command([Point(1.0, Q, velocities=(0.1,) * 7)]), JOINTS, now=100.0,
             allow_nonzero_end_velocity=True)


def test_strict_option_rejects_any_past_start():
    late = command([Point(2.0, Q)], stamp=99.0)
    validate(late, JOINTS, now=100.0)                      # the real controller joins it
    with pytest.raises(Rejected, match='in the past'):
        validate(late, JOINTS, now=100.0, reject_past_start=True)
    validate(command([Point(2.0, Q)], stamp=100.5), JOINTS, now=100.0, reject_past_start=True)
    validate(command([Point(2.0, Q)]), JOINTS, now=100.0, reject_past_start=True)


def test_sampling_interpolates_and_holds():
    zero = (np.zeros(7), np.zeros(7))
    a, b = np.full(7, 1.0), np.full(7, 3.0)
    traj = ActiveTrajectory(command([Point(1.0, tuple(a)), Point(3.0, tuple(b))]),
                            JOINTS, 10.0, zero)
    assert traj.start == 10.0
    np.testing.assert_allclose(traj.sample(10.5)[0], 0.5)          # from the state before
    np.testing.assert_allclose(traj.sample(12.0)[0], 2.0)          # linear, no velocities
    np.testing.assert_allclose(traj.sample(12.0)[1], 1.0)
    np.testing.assert_allclose(traj.sample(20.0)[0], 3.0)          # holds the last point
    np.testing.assert_allclose(traj.sample(20.0)[1], 0.0)
    # A stamp in the future: nothing before it.
    later = ActiveTrajectory(command([Point(1.0, tuple(a))], stamp=15.0), JOINTS, 10.0, zero)
    assert later.sample(14.0) is None
    np.testing.assert_allclose(later.sample(15.5)[0], 0.5)


def test_sampling_with_velocities_is_a_cubic_through_the_knots():
    zero = (np.zeros(7), np.zeros(7))
    v = tuple([2.0] * 7)
    pts = [Point(1.0, tuple([1.0] * 7), v), Point(2.0, tuple([2.0] * 7), tuple([0.0] * 7))]
    traj = ActiveTrajectory(command(pts), JOINTS, 0.0, zero)
    q, qd = traj.sample(1.0)
    np.testing.assert_allclose(q, 1.0)
    np.testing.assert_allclose(qd, 2.0)
    q, qd = traj.sample(2.0 - 1e-9)
    np.testing.assert_allclose(q, 2.0, atol=1e-6)
    np.testing.assert_allclose(qd, 0.0, atol=1e-6)
    # Not the straight line: the start velocity (2) is above the mean one (1).
    assert traj.sample(1.5)[0][0] > 1.5


def test_partial_goal_holds_the_joints_it_leaves_out():
    state = (np.arange(7) * 0.1, np.zeros(7))
    traj = ActiveTrajectory(command([Point(1.0, (1.0,))], names=(JOINTS[3],)), JOINTS,
                            0.0, state)
    q = traj.sample(5.0)[0]
    assert q[3] == 1.0
    np.testing.assert_allclose(np.delete(q, 3), np.delete(state[0], 3))


@pytest.fixture(scope='module')
def allowances(robot, product_library):
    return designed_allowances(robot, product_library)


def test_designed_contact_is_the_wai_hands_only(allowances):
    assert allowances, 'the reference Wai presses the palms together'
    assert all('torso' not in b for _, b in allowances)
    assert ('right_arm_hand', 'left_arm_hand') in allowances
    assert set(allowances) <= set(contact_pairs())


def run(sim, q, steps):
    sim.set_targets(q)
    sim.step(steps)


def test_position_actuators_reach_and_hold_a_pose(robot, allowances):
    sim = NamoSim(robot, allowances=allowances)
    target = np.radians([30, -20, -20, 60, 10, -20, 30, 0, 0, 0, 0, 0, 0, 0])
    run(sim, target, 1500)
    assert np.abs(sim.positions() - target).max() < math.radians(0.05)
    assert np.abs(sim.velocities()).max() < 1e-3


def test_stuck_joint_holds_against_commands_and_release_frees_it(robot, allowances):
    sim = NamoSim(robot, allowances=allowances)
    sim.stick('right_arm_joint4', math.radians(40.0))
    run(sim, np.zeros(14), 1000)
    target = np.radians([40, -30, 20, -50, 10, 10, 10, 0, 0, 0, 0, 0, 0, 0])
    worst = 0.0
    for _ in range(100):
        run(sim, target, 10)
        worst = max(worst, abs(sim.positions()[3] - math.radians(40.0)))
    # Jammed, not sprung: the stuck joint (and so its reading) stays within 0.05 deg
    # while the others jump to new targets (MuJoCo's default constraint let it swing).
    assert worst < math.radians(0.05), math.degrees(worst)
    assert abs(sim.positions()[0] - target[0]) < math.radians(0.1)   # the others move
    assert sim.release('right_arm_joint4')
    run(sim, target, 1500)
    assert abs(sim.positions()[3] - target[3]) < math.radians(0.1)
    held = sim.stick('right_arm_joint1')                       # where it is now
    assert held == pytest.approx(sim.positions()[0])
    with pytest.raises(KeyError, match='unknown joint'):
        sim.stick('right_arm_joint9')


def test_reference_wai_counts_no_contact_and_the_torso_does(robot, allowances,
                                                            product_library):
    sim = NamoSim(robot, allowances=allowances)
    wai = product_library['wai'].keyframes[-1].positions()
    for s in np.linspace(0.0, 1.0, 400):          # 1.6 s from rest, straight in joints
        run(sim, s * wai, 2)
    run(sim, wai, 500)
    assert sim.contact_events == 0 and sim.contact_steps == 0
    assert np.abs(sim.positions() - wai).max() < math.radians(0.1)
    # Without the designed allowance the same Wai is a contact.
    bare = NamoSim(robot)
    bare.set_positions(wai)
    bare.step(1)
    assert {(c.geom1, c.geom2) for c in bare.contacts()} & {
        ('right_arm_hand', 'left_arm_hand'), ('left_arm_hand', 'right_arm_hand')}
    # The right arm swung in against the torso: counted, and held off physically.
    sim.set_positions(np.zeros(14))
    sim.reset_contact_count()
    run(sim, np.radians([0, 40, 0, 0, 0, 0, 0] + [0] * 7), 1000)
    assert sim.contact_events >= 1 and sim.max_depth > 1e-3
    assert sim.positions()[1] < math.radians(10.0)
    assert sim.pairs_seen and all('torso' in pair and any(g.startswith('right_arm_')
                                                          for g in pair)
                                  for pair in sim.pairs_seen), sim.pairs_seen   # named


@pytest.mark.parametrize('name', ['wai', 'bye', 'salute', 'side_invite'])
def test_reference_gestures_play_from_rest_without_contact(robot, allowances, product_library,
                                                           name):
    """Each paper gesture, played from rest as the controller interpolates it, is clear."""
    sim = NamoSim(robot, allowances=allowances)
    gesture = product_library[name]
    points = tuple(Point(float(kf.time_from_start), tuple(kf.positions()))
                   for kf in gesture.keyframes)
    rest = (np.zeros(14), np.zeros(14))
    traj = ActiveTrajectory(command(points, names=robot.joint_names), robot.joint_names,
                            0.0, rest)
    worst = 0.0
    while sim.time < traj.end + 0.5:
        sim.set_targets(*traj.sample(sim.time))
        sim.step(1)
        worst = max(worst, float(np.abs(sim.positions() - traj.sample(sim.time)[0]).max()))
    assert sim.contact_events == 0 and sim.contact_steps == 0, name
    assert worst < math.radians(1.0), (name, math.degrees(worst))
