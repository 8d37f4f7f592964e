"""
The real ``gesture_player`` process over DDS, against fake arms written here.

The fake arms are two trajectory "controllers" in the test's rclpy node: each follows
the last trajectory it received (interpolating its points from the moment it arrived)
and publishes /joint_states at 100 Hz; a joint can be stuck.  The library and the
recovery node's diagnostics are published by the test, so every input is known.
"""

import math
import os
import threading
import time

from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.cli.player_commands import player_command
from node_harness import NodeProcess, ros_env
import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

pytestmark = pytest.mark.slow

ROBOT = load_robot()
LIBRARY = load_library(ROBOT)
NAMES = list(ROBOT.joint_names)
# Domains apart from the recovery-node modules' (session_domain 1..105).
DOMAIN = 120 + int(os.environ.get('NAMO_TEST_DOMAIN_BASE', 1 + (os.getpid() % 20) * 5))
CONTROLLERS = {'right_arm_controller': NAMES[:7], 'left_arm_controller': NAMES[7:]}
STUCK = math.radians(-20.0)


def _seconds(d):
    return d.sec + d.nanosec * 1e-9


class FakeArms:
    """Two fake trajectory controllers, the /joint_states they produce, and a library."""

    def __init__(self, domain):
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('fake_arms', context=self.context)
        self.lock = threading.Lock()
        self.q = np.zeros(14)
        self.stuck = {}
        self.active = {}          # controller -> (start time, start q, msg)
        self.commands = []        # (controller, msg) every command received
        self.faults = []
        for controller in CONTROLLERS:
            self.node.create_subscription(
                JointTrajectory, f'/{controller}/joint_trajectory',
                lambda msg, c=controller: self._on_command(c, msg), 10)
        self.node.create_subscription(JointState, '/actuator_fault', self.faults.append, 10)
        self.state_pub = self.node.create_publisher(JointState, '/joint_states', 10)
        latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.library_pub = self.node.create_publisher(JointTrajectory, '/gesture_library',
                                                      latched)
        self.diag_pub = self.node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.node.create_timer(0.01, self._step)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        try:
            self.executor.spin()
        except Exception:  # noqa: B902 - the context is shut down at the end
            pass

    def close(self):
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)

    def _on_command(self, controller, msg):
        with self.lock:
            self.commands.append((controller, msg))
            self.active[controller] = (time.monotonic(), self.q.copy(), msg)

    def _step(self):
        now = time.monotonic()
        with self.lock:
            for controller, (t0, q0, msg) in self.active.items():
                cols = [NAMES.index(j) for j in msg.joint_names]
                times = [0.0] + [_seconds(p.time_from_start) for p in msg.points]
                for k, col in enumerate(cols):
                    values = [q0[col]] + [p.positions[k] for p in msg.points]
                    self.q[col] = np.interp(now - t0, times, values)
            for joint, angle in self.stuck.items():
                self.q[NAMES.index(joint)] = angle
            q = self.q.copy()
        self.state_pub.publish(JointState(name=NAMES, position=list(q)))

    def publish_library(self, stamp_sec, locks=None):
        """Publish the packaged library, locked joints held at their lock."""
        for gesture in LIBRARY:
            msg = JointTrajectory(joint_names=NAMES)
            msg.header.stamp.sec = stamp_sec
            msg.header.frame_id = gesture.name
            for kf in gesture.keyframes:
                q = np.concatenate([kf.right, kf.left])
                if locks:
                    for joint, angle in locks.items():
                        q[NAMES.index(joint)] = angle
                sec = int(kf.time_from_start)
                msg.points.append(JointTrajectoryPoint(
                    positions=list(q), time_from_start=Duration(
                        sec=sec, nanosec=int(round((kf.time_from_start - sec) * 1e9)))))
            self.library_pub.publish(msg)

    def publish_node_faults(self, locks):
        """Publish recovery_node-style diagnostics for ``locks``."""
        statuses = [DiagnosticStatus(name='recovery_node: faults', values=[
            KeyValue(key='failed_joints', value=' '.join(locks))])]
        for joint, angle in locks.items():
            statuses.append(DiagnosticStatus(name=f'recovery_node: joint {joint}', values=[
                KeyValue(key='lock_angle_rad', value=repr(angle))]))
        self.diag_pub.publish(DiagnosticArray(status=statuses))

    def play(self, gesture, timeout=30.0):
        client = self.node.create_client(Trigger, f'/gesture_player/play/{gesture}')
        assert client.wait_for_service(timeout_sec=20.0), f'no play service for {gesture}'
        future = client.call_async(Trigger.Request())
        end = time.monotonic() + timeout
        while not future.done() and time.monotonic() < end:
            time.sleep(0.02)
        assert future.done(), f'no answer to play {gesture} within {timeout} s'
        return future.result()


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


def _commanded(arms, since, joint):
    """All positions commanded to ``joint`` by the messages received after ``since``."""
    out = []
    for controller, msg in arms.commands[since:]:
        if joint in msg.joint_names:
            k = list(msg.joint_names).index(joint)
            out += [p.positions[k] for p in msg.points]
    return np.array(out)


def test_play_detect_report_then_play_locked(player):
    node, arms = player
    # a healthy play: one message per controller with its own joints only
    before = len(arms.commands)
    response = arms.play('wai')
    assert response.success, response.message + node.describe()
    sent = arms.commands[before:]
    assert sorted(c for c, _ in sent) == sorted(CONTROLLERS)
    for controller, msg in sent:
        assert list(msg.joint_names) == CONTROLLERS[controller]
        assert msg.header.stamp.sec == 0 and msg.header.stamp.nanosec == 0
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
    commanded = _commanded(arms, before, 'right_arm_joint2')
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
    commanded = _commanded(arms, before, 'right_arm_joint2')
    assert commanded.size > 10 and np.all(commanded == other)


def test_one_and_two_arm_gestures_finish(player):
    node, arms = player
    response = arms.play('wai')
    assert response.success, response.message
    response = arms.play('circle', timeout=60.0)
    assert response.success, response.message
    assert 'finished' in response.message
