"""
Test-side rclpy node around ``gesture_player``, for the DDS tests.

It records every command, fault report, joint state, library version and diagnostics,
and calls the play services.
:class:`FakeArms` also emulates the two arm controllers (the DDS tests of the player
alone); with the simulator, :class:`Recorder` alone watches ``namo_sim``.
"""

import re
import threading
import time

from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.resources import config_path, DEMO_MOTION_FILE
from namo_fault_recovery.ros.client import RecoveryClient
from namo_fault_recovery.ros.spun_node import wait_until
from namo_fault_recovery.runtime.diagnostic_keys import format_stamp
import numpy as np
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

ROBOT = load_robot()
# The demo library of motions: the four packaged gestures plus the dense 100-point
# circle, so that the player is tested on a dense motion too.
LIBRARY = load_library(ROBOT, config_path(DEMO_MOTION_FILE))
NAMES = list(ROBOT.joint_names)
CONTROLLERS = {'right_arm_controller': NAMES[:7], 'left_arm_controller': NAMES[7:]}
TIMEOUT_DIAGNOSTICS = 10.0      # s for the node's diagnostics of a version


def _seconds(d):
    return d.sec + d.nanosec * 1e-9


class Recorder:
    """
    Watches the player and the arms; publishes a library and diagnostics on request.

    Built on :class:`RecoveryClient`: the library versions and recovery_node's
    diagnostics are its inbox's.
    """

    def __init__(self, domain, name='play_recorder'):
        self.lock = threading.Lock()
        self.q = np.zeros(14)          # the latest /joint_states, in NAMES order
        self.states = 0
        self.commands = []             # (controller, msg) every command sent
        self.faults = []
        self.diagnostics = []
        self.client = RecoveryClient('/', domain, client_name=name)
        self.node = self.client.node
        for controller in CONTROLLERS:
            self.node.create_subscription(
                JointTrajectory, f'/{controller}/joint_trajectory',
                lambda msg, c=controller: self._on_command(c, msg), 100)
        self.node.create_subscription(JointState, '/actuator_fault', self.faults.append, 10)
        self.node.create_subscription(JointState, '/joint_states', self._on_state, 10)
        latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(DiagnosticArray, '/diagnostics',
                                      self.diagnostics.append, 50)
        self.library_pub = self.node.create_publisher(JointTrajectory, '/gesture_library',
                                                      latched)
        self.diag_pub = self.node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.setup()

    def setup(self):
        """Create further entities (subclasses)."""

    def close(self):
        self.client.close()

    def _on_command(self, controller, msg):
        with self.lock:
            self.commands.append((controller, msg))

    def _on_state(self, msg):
        with self.lock:
            for name, angle in zip(msg.name, msg.position):
                if name in NAMES:
                    self.q[NAMES.index(name)] = angle
            self.states += 1

    def measured(self):
        """Return the latest measured pose (rad, NAMES order)."""
        with self.lock:
            return self.q.copy()

    def settled(self, timeout=5.0, tol=1e-4):
        """Wait until the measured pose stops moving (two reads 0.2 s apart); return it."""
        end = time.monotonic() + timeout
        q = self.measured()
        while time.monotonic() < end:
            time.sleep(0.2)
            q, before = self.measured(), q
            if np.max(np.abs(q - before)) < tol:
                return q
        raise AssertionError(f'the arms still move {timeout} s after the play')

    def wait(self, predicate, timeout, what):
        """Wait until ``predicate()`` is truthy; return it (assert on timeout)."""
        value = wait_until(predicate, timeout)
        if not value:
            raise AssertionError(f'timed out after {timeout} s waiting for {what}')
        return value

    def reconfiguration(self):
        """Return recovery_node's latest ``reconfiguration`` values, or {} if none yet."""
        for msg in reversed(list(self.diagnostics)):
            for status in msg.status:
                if status.name == 'recovery_node: reconfiguration':
                    return {kv.key: kv.value for kv in status.values}
        return {}

    def library_score(self, gesture):
        """Return ``<gesture>.score_after`` of the node's newest up-to-date diagnostics."""
        values = self.reconfiguration()
        if values.get('up_to_date') == 'true':
            return float(values[f'{gesture}.score_after'])
        return None

    def library_settled(self):
        """
        Return True once the node neither runs nor refines: the library stays as it is.

        Only diagnostics that describe the newest library received count: older ones may
        say ``running`` false from before that library was published.
        """
        values = self.reconfiguration()
        library = self.client.newest_library()
        return (library is not None and values.get('up_to_date') == 'true'
                and values.get('running') == 'false'
                and values.get('library_stamp') == format_stamp(library.stamp))

    def wait_locked_library(self, gesture, locked, timeout):
        """
        Wait for a library whose ``gesture`` holds every ``locked`` joint, then settled.

        The node refines that library in the background (better versions may follow):
        the one it settles on is the one to play, so that the executed pose can be
        compared with it.
        """
        def reconfigured():
            lib = self.newest_library()
            return lib and all(np.allclose(lib[gesture][:, NAMES.index(j)], a, atol=1e-9)
                               for j, a in locked.items())
        self.wait(reconfigured, timeout, f'a library with {", ".join(locked)} locked')
        self.wait(self.library_settled, 30.0, 'the end of the refinement')

    def newest_library(self):
        """Return {gesture: positions (keyframes, 14) in NAMES order} of the newest stamp."""
        library = self.client.newest_library()
        return None if library is None else self._positions(library)

    @staticmethod
    def _positions(library):
        order = [library.joint_names.index(j) for j in NAMES]
        return {g.name: np.array([[q[i] for i in order] for q in g.positions])
                for g in library.result.gestures}

    def carried_on_with(self, message):
        """
        Return (library, {gesture: positions}) of the version a play's answer carried on with.

        The answer names it (``reconfigured library <stamp>``); ``library`` is the
        PublishedLibrary (its scores once the node's diagnostics describe it).
        """
        found = re.search(r'reconfigured library (\d+)', message)
        assert found, f'the answer names no library it carried on with: {message}'
        library = self.client.inbox.library(int(found.group(1)), TIMEOUT_DIAGNOSTICS)
        return library, self._positions(library)

    def commanded_after_first(self, since, joint):
        """
        Positions commanded to ``joint`` after the first message to its controller.

        In a play that carried on, the first message per controller is the original
        motion, sent before the fault was known; every later one was sent after it.
        """
        controller = next(c for c, joints in CONTROLLERS.items() if joint in joints)
        with self.lock:
            msgs = [m for c, m in self.commands[since:] if c == controller]
        k = CONTROLLERS[controller].index(joint)
        return len(msgs), np.array([p.positions[k] for m in msgs[1:] for p in m.points])

    def commanded(self, since, joint):
        """All positions commanded to ``joint`` by the messages received after ``since``."""
        out = []
        with self.lock:
            commands = list(self.commands[since:])
        for controller, msg in commands:
            if joint in msg.joint_names:
                k = list(msg.joint_names).index(joint)
                out += [p.positions[k] for p in msg.points]
        return np.array(out)

    def publish_library(self, stamp_sec, locks=None):
        """Publish the demo library (:data:`LIBRARY`), locked joints held at their lock."""
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

    def trigger(self, service, timeout=30.0):
        """Call a std_srvs/Trigger service; return the response (assert on timeout)."""
        client = self.node.create_client(Trigger, service)
        assert client.wait_for_service(timeout_sec=20.0), f'no service {service}'
        future = client.call_async(Trigger.Request())
        assert wait_until(future.done, timeout), f'no answer from {service} within {timeout} s'
        return future.result()

    def play(self, gesture, timeout=30.0):
        """Play one gesture on the gesture_player; return the Trigger response."""
        return self.trigger(f'/gesture_player/play/{gesture}', timeout)


class FakeArms(Recorder):
    """Recorder plus two fake trajectory controllers that publish /joint_states."""

    def setup(self):
        self.stuck = {}
        self.active = {}          # controller -> (start time, start q, msg)
        self.state_pub = self.node.create_publisher(JointState, '/joint_states', 10)
        self.node.create_timer(0.01, self._step)

    def _on_command(self, controller, msg):
        """
        Take a trajectory on as a joint_trajectory_controller does: from its stamp.

        A stamped trajectory runs on its own timeline (a late one joins mid-way, from
        the pose the arm had when it arrived); an unstamped one starts on arrival.
        """
        now = time.monotonic()
        stamp = _seconds(msg.header.stamp)
        if stamp:
            now -= self.node.get_clock().now().nanoseconds * 1e-9 - stamp
        with self.lock:
            self.commands.append((controller, msg))
            self.active[controller] = (now, self.q.copy(), msg)

    def _on_state(self, msg):
        with self.lock:
            self.states += 1

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
        msg = JointState(name=NAMES, position=list(q))
        msg.header.stamp = self.node.get_clock().now().to_msg()    # when it was read
        self.state_pub.publish(msg)
