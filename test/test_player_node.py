"""
The real ``gesture_player`` process over DDS, against fake arms.

The fake arms (``player_harness.FakeArms``) are two trajectory "controllers" in the
test's rclpy node: each follows the last trajectory it received (interpolating its
points on the timeline its stamp sets, as a joint_trajectory_controller does) and
publishes stamped /joint_states at 100 Hz; a joint can be stuck.  The library and the
recovery node's diagnostics are published by the test, so every input is known.
"""

import math
import os
import threading
import time

from namo_fault_recovery.runtime.private_node import player_command
from node_harness import NodeProcess, ros_env, session_domain
import numpy as np
from player_harness import CONTROLLERS, FakeArms, LIBRARY, NAMES
import pytest

pytestmark = pytest.mark.slow

DOMAIN = session_domain(0)       # modules run one after the other: the ids are reused
STUCK = math.radians(-20.0)


@pytest.fixture(scope='module')
def player():
    node = NodeProcess(DOMAIN, command=player_command(), env=ros_env(DOMAIN))
    arms = FakeArms(DOMAIN)
    try:
        arms.publish_library(100)
        yield node, arms
    finally:
        arms.close()
        code = node.stop()
        assert code == 0, node.describe()
        assert 'Traceback' not in node.stderr + node.stdout, node.describe()


def test_play_detect_report_then_play_locked(player):
    node, arms = player
    # a healthy play: one message per controller with its own joints only
    before = len(arms.commands)
    response = arms.play('wai')
    assert response.success, response.message + node.describe()
    sent = arms.commands[before:]
    assert sorted(c for c, _ in sent) == sorted(CONTROLLERS)
    # both stamped with the play's start on the ROS clock: a late controller joins there
    stamps = {m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in sent}
    assert len(stamps) == 1 and abs(stamps.pop() - arms.node.get_clock().now().nanoseconds
                                    * 1e-9) < 30.0
    for controller, msg in sent:
        assert list(msg.joint_names) == CONTROLLERS[controller]
        assert all(len(p.velocities) == len(p.positions) for p in msg.points)
    final = np.concatenate([LIBRARY['wai'].keyframes[-1].right,
                            LIBRARY['wai'].keyframes[-1].left])
    assert np.allclose(arms.q, final, atol=math.radians(2.0))

    # a stuck joint: detected, reported with its held angle, the play fails
    with arms.lock:
        arms.stuck = {'right_arm_joint2': STUCK}
    response = arms.play('salute')
    assert not response.success
    assert 'right_arm_joint2' in response.message, response.message
    deadline = time.monotonic() + 5.0
    while not arms.faults and time.monotonic() < deadline:
        time.sleep(0.02)
    assert arms.faults, 'no /actuator_fault'
    assert list(arms.faults[-1].name) == ['right_arm_joint2']
    assert arms.faults[-1].position[0] == pytest.approx(STUCK, abs=1e-6)

    # the next play waits for a newer library, then never moves the joint from its lock
    locks = {'right_arm_joint2': STUCK}
    before = len(arms.commands)
    timer = threading.Timer(1.0, lambda: (arms.publish_node_faults(locks),
                                          arms.publish_library(200, locks)))
    timer.start()
    t0 = time.monotonic()
    response = arms.play('salute')
    timer.join()
    assert time.monotonic() - t0 >= 1.0     # it waited for the new version
    assert response.success, response.message
    commanded = arms.commanded(before, 'right_arm_joint2')
    assert commanded.size > 10 and np.all(commanded == STUCK), commanded

    # the lock comes from the node's diagnostics too: another angle is obeyed
    other = math.radians(-10.0)
    with arms.lock:
        arms.stuck = {'right_arm_joint2': other}
    arms.publish_node_faults({'right_arm_joint2': other})
    time.sleep(0.5)
    before = len(arms.commands)
    response = arms.play('bye')
    assert response.success, response.message
    commanded = arms.commanded(before, 'right_arm_joint2')
    assert commanded.size > 10 and np.all(commanded == other)


def test_one_and_two_arm_gestures_finish(player):
    node, arms = player
    response = arms.play('wai')
    assert response.success, response.message
    response = arms.play('circle', timeout=60.0)
    assert response.success, response.message
    assert 'finished' in response.message


def test_cli_play_and_export_from_the_running_library(player, tmp_path):
    import io

    from namo_fault_recovery.cli.main import main
    from namo_fault_recovery.playback.export import load_motions
    node, arms = player
    out = io.StringIO()
    assert main(['play', 'side_invite', '--domain-id', str(DOMAIN)], out) == 0, out.getvalue()
    assert out.getvalue().startswith('success: side_invite: finished')
    path = tmp_path / 'motions.yaml'
    assert main(['export', '--out', str(path), '--domain-id', str(DOMAIN)], out) == 0
    motions = load_motions(path.read_text())
    newest = arms.newest_library()
    assert sorted(motions) == sorted(newest)
    for name, (joints, times, positions) in motions.items():
        assert joints == NAMES
        assert np.array_equal(positions, newest[name])


def test_a_fault_published_mid_play_is_held_where_it_is_and_carried_on(player):
    """Anyone's /actuator_fault mid-play: the joint held where it is, the play carries on."""
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger
    node, arms = player
    joint, j = 'right_arm_joint1', NAMES.index('right_arm_joint1')
    reporter = arms.node.create_publisher(JointState, '/actuator_fault', 10)
    arms.wait(lambda: reporter.get_subscription_count() >= 2, 20.0, 'the player on the topic')
    client = arms.node.create_client(Trigger, '/gesture_player/play/salute')
    assert client.wait_for_service(timeout_sec=20.0)
    before, start = len(arms.commands), arms.measured()[j]
    future = client.call_async(Trigger.Request())
    arms.wait(lambda: abs(arms.measured()[j] - start) > math.radians(20.0), 20.0,
              'the shoulder on its way')
    with arms.lock:
        angle = float(arms.q[j])
        arms.stuck[joint] = angle
    reporter.publish(JointState(name=[joint], position=[angle]))
    # recovery_node's answer, as it would be: its diagnostics and a version locking it
    locks = {'right_arm_joint2': math.radians(-10.0), joint: angle}
    arms.publish_node_faults(locks)
    arms.publish_library(500, locks)
    assert arms.wait(future.done, 30.0, 'the answer')
    response = future.result()
    assert response.success and 'carried on' in response.message, response.message
    assert joint in response.message and 'library 500000000000 ' in response.message
    count, held = arms.commanded_after_first(before, joint)
    assert count == 3 and held.size > 10 and np.all(held == held[0]), held
    assert held[0] == pytest.approx(angle, abs=math.radians(1.0))
    goal = np.concatenate([LIBRARY['salute'].keyframes[-1].right,
                           LIBRARY['salute'].keyframes[-1].left])
    free = [i for i, n in enumerate(NAMES) if n not in locks]
    assert np.allclose(arms.settled()[free], goal[free], atol=math.radians(2.0))


def test_bad_parameter_refused_in_one_line():
    domain = session_domain(2)
    proc = NodeProcess(domain, command=player_command(), args=['-p', 'fault_hold_sec:=0.0'],
                       env=ros_env(domain))
    code = proc.wait()
    stderr = proc.stderr
    proc.stop()
    assert code == 1, stderr
    assert 'fault_hold must be > 0' in stderr and 'Traceback' not in stderr, stderr


def test_demo_play_runs_the_loop_step_by_step(tmp_path, monkeypatch):
    import io
    import sys

    from namo_fault_recovery.cli import player_commands
    from namo_fault_recovery.cli.main import main
    fake = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'fake_sim_node.py')
    monkeypatch.setattr(player_commands, 'sim_command', lambda: [sys.executable, fake])
    out = io.StringIO()
    code = main(['demo-play', '--domain-id', str(session_domain(4)), '--plot', str(tmp_path)], out)
    text = out.getvalue()
    assert code == 0, text
    assert 'success' in text.split('4. play:')[1].split('\n')[0]
    assert 'carried on' in text.split('4. play:')[1].split('\n')[0]
    assert '5. /actuator_fault from the player: right_arm_joint2 held at -20.00 deg' in text
    assert '6. recovery_node reconfigured the library' in text
    assert 'success' in text.split('7. play again:')[1].split('\n')[0]
    assert '0 away from -20.00 deg' in text
    assert (tmp_path / 'wai_2_replay.png').is_file()


@pytest.mark.parametrize('during_play', [False, True])
def test_sigterm_exits_cleanly(player, during_play):
    """SIGTERM to a running player (idle, or in the middle of a play): exit code 0."""
    import signal

    from std_srvs.srv import Trigger
    node, arms = player
    domain = session_domain(3)
    other = NodeProcess(domain, command=player_command(), env=ros_env(domain))
    fake = FakeArms(domain)
    try:
        fake.publish_library(300)
        client = fake.node.create_client(Trigger, '/gesture_player/play/bye')
        assert client.wait_for_service(timeout_sec=20.0), other.describe()
        if during_play:
            client.call_async(Trigger.Request())
            fake.wait(lambda: fake.commands or None, 20.0, 'the play to start')
        code = other.stop(signal.SIGTERM)
    finally:
        fake.close()
        other.stop()
    assert code == 0, other.describe()
    assert 'Traceback' not in other.stderr, other.describe()


def test_play_without_a_controller_fails_with_the_reason(player):
    from std_srvs.srv import Trigger
    domain = session_domain(3)
    joints = "['right_arm_joint1', 'right_arm_joint2', 'right_arm_joint3', " \
             "'right_arm_joint4', 'right_arm_joint5', 'right_arm_joint6', 'right_arm_joint7']"
    other = NodeProcess(domain, command=player_command(), env=ros_env(domain), args=[
        '-p', "controllers:=['ghost_controller']", '-p', f'ghost_controller.joints:={joints}',
        '-p', 'joint_states_wait_sec:=1.0'])
    fake = FakeArms(domain)
    try:
        fake.publish_library(400)
        client = fake.node.create_client(Trigger, '/gesture_player/play/salute')
        assert client.wait_for_service(timeout_sec=20.0), other.describe()
        response = fake.play('salute')
    finally:
        fake.close()
        other.stop()
    assert not response.success
    assert 'nobody subscribes to ghost_controller/joint_trajectory' in response.message
    assert not fake.commands


def test_a_torso_no_controller_takes_is_said_once_and_only_when_it_leans():
    from namo_fault_recovery.playback.book import GestureTrack
    from namo_fault_recovery.ros.player_node import unplayed_joints
    arms = tuple(NAMES)
    names = arms + ('torso_1_joint', 'torso_2_joint')
    upright = GestureTrack('wai', names, np.array([2.0]), np.zeros((1, 16)), stamp=5)
    said = set()
    assert unplayed_joints(upright, arms, said) == ''        # at 0: nothing is lost
    leaned = np.zeros((1, 16))
    leaned[0, -1] = -0.26
    track = GestureTrack('wai', names, np.array([2.0]), leaned, stamp=6)
    text = unplayed_joints(track, arms, said)
    assert 'torso_2_joint' in text and 'torso_1_joint' not in text
    assert unplayed_joints(track, arms, said) == ''          # once per gesture and joints
    assert unplayed_joints(track, names, set()) == ''        # a torso controller takes it


def test_a_goal_waits_until_a_controllers_subscription_has_settled():
    """CommandLinks: first seen at t, ready at t + MATCH_SETTLE_SEC; gone and back: again."""
    from namo_fault_recovery.ros.player_node import CommandLinks, MATCH_SETTLE_SEC

    class Pub:
        def __init__(self, count):
            self.count = count

        def get_subscription_count(self):
            return self.count

    right, left = Pub(1), Pub(0)
    links = CommandLinks({'right_arm_controller': right, 'left_arm_controller': left})
    assert links.idle() == ['left_arm_controller']
    assert links.settled_at(10.0) == pytest.approx(10.0 + MATCH_SETTLE_SEC)
    left.count = 1
    assert links.idle() == []
    assert links.settled_at(12.0) == pytest.approx(12.0 + MATCH_SETTLE_SEC)   # the newest
    assert links.settled_at(20.0) == pytest.approx(12.0 + MATCH_SETTLE_SEC)   # long settled
    right.count = 0
    links.settled_at(21.0)
    right.count = 1
    assert links.settled_at(22.0) == pytest.approx(22.0 + MATCH_SETTLE_SEC)   # came back
