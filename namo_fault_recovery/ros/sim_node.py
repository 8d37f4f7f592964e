"""
``namo_sim``: a simulated Namo (or any robot from its URDF) in MuJoCo, driven like its controllers.

What it offers, so that a gesture player can be tried without the robot:

- The robot of ``recovery_node``'s parameters (:mod:`..runtime.robot_source`): Namo's
  DH ``robot_file``, or any two-armed robot from ``robot_profile`` and its URDF (the
  profile's, ``robot_description``, or the ``robot_description`` topic, waited for as
  ``recovery_node`` does), loaded from that URDF (:mod:`..sim.profile_model`).

- Two trajectory controllers, as ros2_control's JointTrajectoryController on
  ``/<controller>/joint_trajectory`` (trajectory_msgs/JointTrajectory): by default
  ``right_arm_controller`` (right_arm_joint1..7) and ``left_arm_controller``; a third,
  ``torso_controller``, for a profile robot whose arms hang from shared joints (Talos's
  torso_1/2_joint; the recovery leans them with ``expand_shared``).  The rules
  (what is rejected, with the reason logged; zero stamp = now; interpolation) are in
  :mod:`..sim.trajectory`.
- ``/joint_states`` (all joints, 14 on Namo, 16 on Talos with its torso; position and
  velocity) at ``joint_state_rate``
  (100 Hz).
- Stuck joints, as a failed actuator: the ``stuck_joints`` parameter (``'NAME'`` = where
  it is, ``'NAME:DEG'`` = at that angle) and the ``~/stick`` topic
  (sensor_msgs/JointState: names and positions in rad, NaN or no positions = where it
  is); ``~/release`` (names) frees them.  A stuck joint is held by the physics and
  ignores commands.
- Self-contacts (arm-arm, arm-torso) as MuJoCo finds them, on ``~/contacts``
  (diagnostic_msgs/DiagnosticArray, ``contact_report_rate``): the contacts of now and
  the running counts since start or the last ``~/reset_contacts`` (std_srvs/Trigger).
- A robot that differs from the planner's (:mod:`..sim.structure_change`): its own URDF
  (``sim_urdf_file``), edited by ``structure_changes`` (``'KIND:JOINT:AMOUNT'``) and
  ``hidden_tool_<side>_mm``.  Nothing of it leaves the simulator except its own log and
  its ``namo_sim: hidden structure`` status on ``/diagnostics``.
- A fingertip tracker (:mod:`..sim.tracker`, ``msg_docs/fingertip_tracker.md``): each
  hand's measured fingertip on ``<tracker_topic>/<side>`` (geometry_msgs/PointStamped,
  base frame, metres, stamped at capture, delivered after ``tracker_latency_sec``).  The
  noise-free truth goes out only with ``publish_ground_truth`` (``~/ground_truth/<side>``,
  for benchmarks).

The physics runs in its own thread on the steady clock (``timestep``, real time), not
in the executor, so no callback waits for it and it never waits for a callback.
"""

import math
from pathlib import Path
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from .description_wait import wait_for_description
from .fingertip_topics import GROUND_TRUTH_TOPIC, point_message, topic, TRACKER_QOS
from .fingertip_topics import TRACKER_TOPIC
from .node import node_models
from .parameters import StartupError
from .spin import run_node
from ..model.urdf import urdf_string
from ..sim.physics import designed_allowances, NamoSim, READING_NOISE_DEG
from ..sim.structure_change import apply_changes, hidden_changes
from ..sim.tracker import FingertipTracker, TrackerSettings, TrueFingertips
from ..sim.trajectory import ActiveTrajectory, Command, Point, Rejected, validate

NODE_NAME = 'namo_sim'
_MAX_LAG = 1.0      # s behind real time before the physics lets time go
STATUS_PERIOD = 1.0     # s between the simulator's /diagnostics status


def sim_command():
    """Return the command that starts the ``namo_sim`` executable (for tests and tools)."""
    from ..runtime.private_node import executable_command
    return executable_command(NODE_NAME, 'namo_fault_recovery.ros.sim_node')


_T = ParameterType
# The node's read-only parameters: name -> (default, description, type).
PARAMETERS = {
    'robot_file': ('', 'robot model YAML (empty: the packaged Namo model, unless '
                   'robot_profile is given)', _T.PARAMETER_STRING),
    'robot_profile': ('', 'recovery profile YAML of any robot (config/robots/talos.yaml): '
                      'the robot is simulated from its URDF instead of robot_file',
                      _T.PARAMETER_STRING),
    'robot_description': ('', "the robot's URDF document: it replaces the URDF that "
                          "robot_profile names; empty = the profile's urdf, or if it names "
                          'none the robot_description topic (transient local, waited for)',
                          _T.PARAMETER_STRING),
    'gesture_file': ('', 'gesture library whose two-handed gestures define '
                     'the designed hand contact (empty: the packaged one)',
                     _T.PARAMETER_STRING),
    'right_controller': ('right_arm_controller', 'trajectory controller of the '
                         'right arm', _T.PARAMETER_STRING),
    'left_controller': ('left_arm_controller', 'trajectory controller of the '
                        'left arm', _T.PARAMETER_STRING),
    'torso_controller': ('torso_controller', 'trajectory controller of the joints both '
                         'arms hang from (a profile robot with shared joints: a torso)',
                         _T.PARAMETER_STRING),
    'timestep': (0.002, 'physics step (s), run in real time',
                 _T.PARAMETER_DOUBLE),
    'kp': (300.0, 'position actuator stiffness (N m/rad)', _T.PARAMETER_DOUBLE),
    'kv': (30.0, 'position actuator damping (N m s/rad)', _T.PARAMETER_DOUBLE),
    'gravity': (True, 'gravity on (the arms are gravity-compensated)',
                _T.PARAMETER_BOOL),
    'joint_state_rate': (100.0, '/joint_states rate (Hz)', _T.PARAMETER_DOUBLE),
    'contact_report_rate': (10.0, '~/contacts rate (Hz)', _T.PARAMETER_DOUBLE),
    'joint_state_noise_deg': (READING_NOISE_DEG, 'standard deviation (deg) of the '
                              'Gaussian noise added to each /joint_states position, as an '
                              'encoder reads (0: exact)', _T.PARAMETER_DOUBLE),
    'contact_tolerance_mm': (1.0, 'penetration (mm) below which a contact '
                             'is not counted', _T.PARAMETER_DOUBLE),
    'initial_positions': ([0.0], 'start angles (rad): one per joint, right arm first, then '
                          'any torso (14 on Namo, 16 on Talos), or one angle for every '
                          'joint', _T.PARAMETER_DOUBLE_ARRAY),
    'stuck_joints': ([''], "joints stuck from the start: 'NAME' (where it "
                     "is) or 'NAME:DEG'", _T.PARAMETER_STRING_ARRAY),
    'allow_partial_joints_goal': (False, 'accept trajectories naming only '
                                  'some of the joints of a controller',
                                  _T.PARAMETER_BOOL),
    'reject_past_start': (False, 'stricter than the real controller: reject any '
                          'non-zero stamp before now, even if its trajectory '
                          'still runs', _T.PARAMETER_BOOL),
    'allow_nonzero_velocity_at_trajectory_end': (
        False, 'accept a non-zero velocity at the last point', _T.PARAMETER_BOOL),
    # The simulated robot's own structure, hidden from the planner.
    'sim_urdf_file': ('', "the simulator's own URDF (empty: the planner's, generated from "
                      "robot_file, or robot_profile's)", _T.PARAMETER_STRING),
    'profile_file': ('', 'recovery profile naming the fingertip links of that URDF (empty: '
                     'robot_profile, else the packaged Namo profile)', _T.PARAMETER_STRING),
    'structure_changes': ([''], "hidden changes 'KIND:JOINT:AMOUNT', KIND tool (mm), bend "
                          '(deg), encoder_offset (deg) or link_length (mm)',
                          _T.PARAMETER_STRING_ARRAY),
    'hidden_tool_right_mm': (0.0, 'a tool nobody measured in the right hand (mm)',
                             _T.PARAMETER_DOUBLE),
    'hidden_tool_left_mm': (0.0, 'a tool nobody measured in the left hand (mm)',
                            _T.PARAMETER_DOUBLE),
    # The fingertip tracker (msg_docs/fingertip_tracker.md).
    'tracker_topic': (TRACKER_TOPIC, 'prefix of the tracker topics <prefix>/<side> '
                      '(empty: no tracker)', _T.PARAMETER_STRING),
    'tracker_rate_hz': (30.0, 'tracker captures per second and hand', _T.PARAMETER_DOUBLE),
    'tracker_sigma_mm': (1.0, 'tracker noise per axis (mm)', _T.PARAMETER_DOUBLE),
    'tracker_latency_sec': (0.05, 'capture to delivery (s)', _T.PARAMETER_DOUBLE),
    'tracker_dropout': (0.0, 'probability that a capture of a hand is lost',
                        _T.PARAMETER_DOUBLE),
    'tracker_seed': (0, 'seed of the tracker noise (-1: a fresh one)', _T.PARAMETER_INTEGER),
    'publish_ground_truth': (False, 'also publish the noise-free fingertips on '
                             '~/ground_truth/<side>, at capture (for benchmarks only)',
                             _T.PARAMETER_BOOL),
}


def create_tracker(node, sides):
    """Return the tracker of ``node``'s parameters and its publishers {side: (measured, truth)}."""
    p = node.p
    seed = p['tracker_seed']
    tracker = FingertipTracker(TrackerSettings(
        p['tracker_sigma_mm'], p['tracker_latency_sec'], p['tracker_rate_hz'],
        p['tracker_dropout'], None if seed < 0 else seed))
    pubs = {}
    if p['tracker_topic']:
        for side in sides:
            truth = (node.create_publisher(PointStamped, f'{GROUND_TRUTH_TOPIC}/{side}',
                                           TRACKER_QOS)
                     if p['publish_ground_truth'] else None)
            pubs[side] = (node.create_publisher(PointStamped, topic(p['tracker_topic'], side),
                                                TRACKER_QOS), truth)
    return tracker, pubs


def _describe(text, kind, read_only=True):
    return ParameterDescriptor(description=text, type=kind, read_only=read_only)


def controller_groups(robot, params) -> list:
    """
    Return ``[(controller, joints)]``: each arm's, then a torso's if there is one.

    A torso is the joints both arms hang from
    (:attr:`~..model.robot.RobotJoints.shared`, Talos's torso_1/2_joint).
    """
    groups = [(params[f'{side}_controller'], tuple(robot.arms[side].joint_names))
              for side in ('right', 'left')]
    if robot.shared is not None:
        groups.append((params['torso_controller'], tuple(robot.shared.names)))
    return groups


class SimNode(Node):
    """The simulator node; see the module docstring for its interface."""

    def __init__(self):
        super().__init__(NODE_NAME)
        self.p = self._declare_parameters()
        self.source, self.robot, library = node_models(
            self.p, self.get_logger().warning,
            lambda profile: wait_for_description(self, profile, STATUS_PERIOD))
        for name in ('timestep', 'kp', 'joint_state_rate', 'contact_report_rate'):
            if not self.p[name] > 0:
                raise ValueError(f'parameter {name} must be > 0, got {self.p[name]}')
        self.changes, urdf = self._hidden_structure()
        self.sim = NamoSim(self.robot, timestep=self.p['timestep'], kp=self.p['kp'],
                           kv=self.p['kv'], gravity=self.p['gravity'],
                           allowances=designed_allowances(self.robot, library),
                           tolerance=self.p['contact_tolerance_mm'] * 1e-3, urdf=urdf,
                           shared=True)
        self.sim.set_reading_noise(math.radians(self.p['joint_state_noise_deg']))
        self.tracker, self.tracker_pubs = create_tracker(self, self.truth.chains)
        self.desired = self._initial_state()
        self.lock = threading.Lock()
        self.controllers = self._create_controllers()
        self.state_pub = self.create_publisher(JointState, '/joint_states', 10)
        self.contact_pub = self.create_publisher(DiagnosticArray, '~/contacts', 10)
        self.create_subscription(JointState, '~/stick', self._on_stick, 10)
        self.create_subscription(JointState, '~/release', self._on_release, 10)
        self.create_service(Trigger, '~/reset_contacts', self._on_reset)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_timer(STATUS_PERIOD, self._publish_structure)
        self.rejections = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._physics, name='physics',
                                        daemon=True)
        self._thread.start()
        self.get_logger().info(
            f'simulating {self.robot.name}: controllers {", ".join(self.controllers)}; '
            f'stuck {self._stuck_text()}; hidden from the planner: {self._hidden_text()}')

    # --- start-up ---

    def _declare_parameters(self):
        """Declare the read-only parameters of PARAMETERS; return {name: value}."""
        values = {}
        for name, (default, text, kind) in PARAMETERS.items():
            self.declare_parameter(name, default, _describe(text, kind))
            values[name] = self.get_parameter(name).value
        return values

    def _hidden_structure(self):
        """Return (changes, URDF text) of the simulated robot; the truth of its fingertips."""
        source = self.source
        if source.profile is None:
            planner = urdf_string(self.robot)
        else:
            planner = source.description or Path(self.robot.profile.tree.source)
        base = self.p['sim_urdf_file'] or planner
        profile = self.p['profile_file'] or source.profile or None
        self.truth = TrueFingertips(apply_changes(base, []), profile)
        tools = {side: float(self.p[f'hidden_tool_{side}_mm']) for side in ('right', 'left')}
        changes = hidden_changes(self.p['structure_changes'], tools,
                                 self.truth.fingertip_joints, 'namo_sim parameters')
        urdf = apply_changes(base, changes, self.p['sim_urdf_file']
                             or "structure_changes (namo_sim's copy of the planner's URDF)")
        self.truth = TrueFingertips(urdf, profile)
        return changes, urdf

    def _initial_state(self):
        """Set the start angles and the stuck joints; return the (q, qd) first desired."""
        q0 = list(self.p['initial_positions'])
        count = len(self.sim.joint_names)
        if len(q0) == 1:                       # one angle for every joint (default 0)
            q0 = q0 * count
        if len(q0) != count:
            raise ValueError(f'initial_positions: expected {count} angles (one per joint) or '
                             f'one for all, got {len(q0)}')
        self.sim.set_positions(q0)
        for spec in self.p['stuck_joints']:
            if spec:
                name, _, deg = spec.partition(':')
                angle = math.radians(float(deg)) if deg.strip() else None
                self.sim.stick(name.strip(), angle)
        return np.array(q0, dtype=float), np.zeros(len(q0))

    def _create_controllers(self):
        """Subscribe each arm's (and a torso's) controller; return {controller: its state}."""
        controllers = {}
        for controller, joints in controller_groups(self.robot, self.p):
            controllers[controller] = {
                'joints': joints, 'index': [self.sim.index(j) for j in joints],
                'active': None}
            self.create_subscription(
                JointTrajectory, f'/{controller}/joint_trajectory',
                lambda msg, c=controller: self._on_trajectory(c, msg), 10)
        return controllers

    # --- helpers ---

    def _now(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _hidden_text(self):
        return '; '.join(c.describe() for c in self.changes) or 'nothing'

    def _stuck_text(self):
        return ', '.join(f'{n} at {math.degrees(a):.2f} deg'
                         for n, a in self.sim.stuck.items()) or 'none'

    # --- callbacks (executor) ---

    def _on_trajectory(self, controller, msg):
        try:
            def values(seq):
                return tuple(float(v) for v in seq)
            points = tuple(Point(p.time_from_start.sec + p.time_from_start.nanosec * 1e-9,
                                 values(p.positions), values(p.velocities),
                                 values(p.accelerations), values(p.effort))
                           for p in msg.points)
            stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            command = Command(tuple(msg.joint_names), stamp, points)
            cfg = self.controllers[controller]
            now = self._now()
            validate(command, cfg['joints'], now,
                     self.p['allow_partial_joints_goal'],
                     self.p['allow_nonzero_velocity_at_trajectory_end'],
                     self.p['reject_past_start'])
        except Rejected as exc:
            self.rejections += 1
            self.get_logger().error(f'{controller}: rejected trajectory: {exc}')
            return
        with self.lock:
            q = self.sim.positions()[cfg['index']]
            qd = self.sim.velocities()[cfg['index']]
            cfg['active'] = ActiveTrajectory(command, cfg['joints'], now, (q, qd))
        self.get_logger().info(
            f'{controller}: accepted a trajectory of {len(points)} points '
            f'({points[-1].time:.3f} s)')

    def _joint_names(self, msg, what):
        for name in msg.name:
            if name not in self.sim.joint_names:
                self.get_logger().error(
                    f'{what}: unknown joint {name!r}; expected one of '
                    f'{", ".join(self.sim.joint_names)}')
                return False
        return True

    def _on_stick(self, msg):
        if not self._joint_names(msg, '~/stick'):
            return
        if msg.position and len(msg.position) != len(msg.name):
            self.get_logger().error(f'~/stick: {len(msg.name)} names but '
                                    f'{len(msg.position)} positions')
            return
        with self.lock:
            for i, name in enumerate(msg.name):
                angle = msg.position[i] if msg.position else math.nan
                self.sim.stick(name, None if math.isnan(angle) else angle)
        self.get_logger().info(f'stuck: {self._stuck_text()}')

    def _on_release(self, msg):
        if not self._joint_names(msg, '~/release'):
            return
        with self.lock:
            for name in msg.name:
                self.sim.release(name)
        self.get_logger().info(f'stuck: {self._stuck_text()}')

    def _on_reset(self, request, response):
        with self.lock:
            self.sim.reset_contact_count()
        response.success = True
        response.message = 'contact counts reset'
        return response

    # --- physics thread ---

    def _control(self, now):
        """Set the actuator targets from each controller's trajectory at ``now``."""
        q, qd = self.desired
        for cfg in self.controllers.values():
            active = cfg['active']
            if active is None:
                continue
            sample = active.sample(now)
            if sample is None:
                continue
            q[cfg['index']] = sample[0]
            qd[cfg['index']] = sample[1]
            if now >= active.end:
                cfg['active'] = None
                qd[cfg['index']] = 0.0
        self.sim.set_targets(q, qd)

    def _physics(self):
        """
        Step the physics in real time on the steady clock.

        Simulated time is anchored to ROS time at start: commands are sampled and
        /joint_states stamped at ``anchor + sim time``, so that a thread delayed by
        a busy machine catches up by stepping back to back, with commands and
        states consistent, instead of jumping.  Only when more than
        ``_MAX_LAG`` behind does it let the lost time go (and says so).
        """
        dt = self.sim.timestep
        state_every = max(1, round(1.0 / (self.p['joint_state_rate'] * dt)))
        report_every = max(1, round(1.0 / (self.p['contact_report_rate'] * dt)))
        step = 0
        next_time = time.monotonic()
        with self.lock:
            anchor = self._now() - self.sim.time
            self.tracker.next_capture = anchor + self.sim.time
        while not self._stop.is_set():
            with self.lock:
                now = anchor + self.sim.time
                self._control(now)
                self.sim.step(1)
                state = report = None
                state_due = step % state_every == 0      # /joint_states this step
                if state_due or self.tracker.due(now + dt):
                    # Encoders read with their noise; the tracker sees the true pose.
                    state = (self.sim.readings(), self.sim.velocities(), now + dt,
                             self.sim.positions())
                if step % report_every == 0:
                    report = self._contact_status()
            try:
                if state_due:
                    self._publish_state(*state[:3])
                if report is not None:
                    self.contact_pub.publish(report)
                self._track(now + dt, state)
            except Exception:  # noqa: B902 - the context is shutting down
                if self._stop.is_set() or not self.context.ok():
                    return     # SIGTERM shut ROS down before main() stopped this thread
                raise
            step += 1
            next_time += dt
            delay = next_time - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
            elif delay < -_MAX_LAG:
                anchor -= delay
                next_time -= delay
                self.get_logger().warning(
                    f'physics {-delay:.2f} s behind real time: skipped that time')

    def _track(self, now, state):
        """Capture the true fingertips when due (``state`` is of ``now``); publish arrivals."""
        if not self.tracker_pubs:
            return
        if state is not None and self.tracker.due(now):
            self.tracker.capture(now, self.truth(dict(zip(self.sim.joint_names, state[3]))))
        for m in self.tracker.deliver(now):
            measured, truth = self.tracker_pubs[m.side]
            measured.publish(point_message(m.point_mm, m.capture, self.truth.frame))
            if truth is not None:     # ground truth: stamped at capture, sent at delivery
                truth.publish(point_message(m.truth_mm, m.capture, self.truth.frame))

    def _publish_structure(self):
        msg = structure_status(self.p, self.changes, self.tracker, self.robot.name)
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def _publish_state(self, q, qd, stamp):
        msg = JointState(name=list(self.sim.joint_names), position=q.tolist(),
                         velocity=qd.tolist())
        sec = int(math.floor(stamp))
        msg.header.stamp.sec = sec
        msg.header.stamp.nanosec = min(int((stamp - sec) * 1e9), 999_999_999)
        self.state_pub.publish(msg)

    def _contact_status(self):
        contacts = self.sim.contacts()
        pairs = sorted({f'{c.geom1}-{c.geom2}' for c in contacts})
        counted = self.sim.contact_events > 0
        level = DiagnosticStatus.WARN if contacts or counted else DiagnosticStatus.OK
        text = (f'{len(pairs)} in contact now, {self.sim.contact_events} since reset'
                if contacts or counted else 'no self-contact')
        values = {'contact_events': self.sim.contact_events,
                  'contact_steps': self.sim.contact_steps,
                  'max_depth_mm': f'{self.sim.max_depth * 1e3:.3f}',
                  'current_pairs': ','.join(pairs),
                  'pairs_since_reset': ','.join(sorted(f'{a}-{b}'
                                                       for a, b in self.sim.pairs_seen)),
                  'stuck': ','.join(f'{n}:{math.degrees(a):.3f}'
                                    for n, a in self.sim.stuck.items()),
                  'sim_time': f'{self.sim.time:.3f}'}
        status = DiagnosticStatus(level=level, name=f'{NODE_NAME}: self-contacts',
                                  message=text, hardware_id=self.robot.name,
                                  values=[KeyValue(key=k, value=str(v))
                                          for k, v in values.items()])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        return msg

    def stop(self):
        """Stop the physics thread."""
        self._stop.set()
        self._thread.join(timeout=2.0)


def structure_status(p, changes, tracker, hardware_id):
    """Return the ``namo_sim: hidden structure`` status: what the planner is not told."""
    t = tracker.settings
    values = {'hidden_changes': ' '.join(f'{c.kind}:{c.joint}:{c.amount:g}' for c in changes),
              'urdf': p['sim_urdf_file'] or "the planner's",
              'tracker_topic': p['tracker_topic'],
              'tracker': f'{t.rate_hz:g} Hz, sigma {t.sigma_mm:g} mm, latency '
                         f'{t.latency_s:g} s, dropout {t.dropout:g}',
              'tracker_captures': tracker.captured, 'tracker_dropped': tracker.dropped,
              'ground_truth_published': str(p['publish_ground_truth']).lower()}
    hidden = '; '.join(c.describe() for c in changes) or 'nothing'
    status = DiagnosticStatus(
        level=DiagnosticStatus.OK, name=f'{NODE_NAME}: hidden structure',
        message=f'hidden from the planner: {hidden}', hardware_id=hardware_id,
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
    return DiagnosticArray(status=[status])


def main(args=None):
    """Run the simulator until Ctrl-C or SIGTERM; return the exit code."""
    errors = (ValueError, KeyError, OSError, StartupError)
    return run_node(NODE_NAME, SimNode, args, config_errors=errors)


if __name__ == '__main__':
    sys.exit(main())
