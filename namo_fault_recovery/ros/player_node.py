"""
``gesture_player``: plays the current gesture library on the arm controllers.

Modelled on PAL's play_motion2.  It keeps the latest ``/gesture_library`` version and
offers one ``std_srvs/Trigger`` service per gesture, ``~/play/<gesture>``, answered when
the motion has finished or failed (with the reason) from an ``async`` callback, so no
executor thread waits.  A play sends each controller (parameter ``controllers``) one
``trajectory_msgs/JointTrajectory`` on ``<controller>/joint_trajectory``: its joints
only, stamped with the motion's time 0 on the play's timeline (a late controller joins
it where the play is), positions and velocities of a smooth speed-limited
trajectory that approaches from the measured ``/joint_states``
(:mod:`..playback.timing`).  A locked joint (from ``recovery_node``'s ``/diagnostics``
and from the player's own fault reports) is commanded at its lock angle at every point.
A joint that stays off its command while the others track is reported on
``/actuator_fault`` with its measured angle (:mod:`..playback.monitor`), and the play
carries on (:mod:`..playback.carry`): the stuck joint is commanded where it is from
then on, the others stop; ``recovery_node`` reconfigures the library,
and the first version that holds the joint there (waited for at most
``carry_on_wait_sec``) is blended onto at the current phase, from the measured pose and
velocity, within the speed limits and ``acceleration_limit_deg``; the play ends with the
reconfigured gesture and its answer says it carried on.  A fault anyone else publishes
on ``/actuator_fault`` mid-play is carried on through the same way (the joint held at
its measured angle).  Without that library in time (or with ``carry_on_wait_sec`` 0)
the play fails with the fault, and the next play waits (``library_wait_sec``) for the
new version.  The callbacks never wait: the play's ``async`` service callback awaits a
future that the joint-state, library, fault and timer callbacks complete.  The structure
watch (:mod:`.structure_watch`) compares the tracked fingertips with the designed path;
the exploration on the robot (:mod:`.exploration`: ``~/explore``, a worker thread of its
own) adapts a motion to what it noticed, and the explored version is played from then on.
"""

import functools
import math
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor, ParameterType
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .exploration import attach_watch, Exploration, PlayerHooks
from .messages import duration_msg, stamp_key, status_values, trajectory_angles
from .spin import run_node
from .structure_watch import StructureWatch
from ..model.self_contact import pressed_joints
from ..playback import monitor as detector
from ..playback.blend import BlendLimits
from ..playback.book import GestureTrack, parse_lock_angle, PlayerBook
from ..playback.carry import CarryOn
from ..playback.clearance import PathClearance
from ..playback.monitor import MonitorThresholds, Outcome
from ..playback.timing import plan_motion, PlayTiming
from ..runtime.realtime import MAX_PRIORITY
from ..runtime.robot_source import robot_source

NODE_NAME = 'gesture_player'
RECOVERY_PREFIX = 'recovery_node: '
TICK = 0.05
# s a controller's subscription must have been seen before the first goal goes to it
MATCH_SETTLE_SEC = 0.3
# s: a library version that arrived this long before a fault reached the player may be
# its answer (someone else's report can reach recovery_node first).
EARLY_ANSWER = 0.25
# s: a /joint_states stamp this far ahead of the ROS clock, or older than the horizon, is
# not this machine's clock (reading_age).
STAMP_SKEW = 0.05
STAMP_HORIZON = 10.0


# The stuck-joint detector's parameters: name -> (default, description).
DETECTOR_PARAMETERS = {
    'fault_threshold_deg': (detector.FAULT_THRESHOLD_DEG, 'deg off the band of its '
                            'predicted angle that make a joint off'),
    'fault_hold_sec': (detector.FAULT_HOLD, 's a joint stays off before it is stuck'),
    'tracking_lag_sec': (detector.TRACKING_LAG, 's of predicted angles in the band (a '
                         'reading may be this late)'),
    'tracking_delay_sec': (detector.TRACKING_DELAY, "s: the controllers' tracking delay, "
                           'measured (bench detection-suite fits it)'),
    'tracking_time_constant_sec': (detector.TRACKING_TIME_CONSTANT, "s: the controllers' "
                                   'first-order tracking lag, measured'),
}


def _detector(node, name):
    default, text = DETECTOR_PARAMETERS[name]
    return node.declare_parameter(name, float(default), ParameterDescriptor(
        description=text, type=ParameterType.PARAMETER_DOUBLE, read_only=True)).value


ROBOT_PARAMETERS = {
    'robot_file': "arm model YAML (DH); empty = Namo's, or robot_profile",
    'robot_profile': 'recovery profile YAML: the robot from its URDF (as recovery_node)',
    'robot_description': "URDF document replacing the profile's urdf (as recovery_node)",
}


def _robot(node):
    """Return the robot of the robot parameters, as ``recovery_node`` reads them."""
    values = {name: node.declare_parameter(name, '', ParameterDescriptor(
        description=text, type=ParameterType.PARAMETER_STRING, read_only=True)).value
        for name, text in ROBOT_PARAMETERS.items()}
    source = robot_source(values)           # ValueError: one line naming the parameter
    if source.needs_description():
        raise ValueError(f'robot_profile: {source.profile} names no urdf; expected '
                         'robot_description set (the player does not wait for the '
                         '/robot_description topic)')
    return source.load()


def _declare(node):
    """Declare the parameters; return (robot, controllers, timing, monitor, waits)."""
    robot = _robot(node)
    defaults = {'right_arm_controller': robot.arms['right'].joint_names,
                'left_arm_controller': robot.arms['left'].joint_names}
    if robot.shared is not None:        # a torso both arms hang from: its own controller
        defaults['torso_controller'] = robot.shared.names
    controllers = list(node.declare_parameter('controllers', list(defaults)).value)
    groups = {}
    for name in controllers:
        default = list(defaults.get(name, ())) or Parameter.Type.STRING_ARRAY
        joints = node.declare_parameter(f'{name}.joints', default).value or []
        unknown = [j for j in joints if j not in robot.played_joints]
        if not joints or unknown:
            raise ValueError(f'{name}.joints: expected joints of the robot, got {joints!r}')
        groups[name] = list(joints)
    timing = PlayTiming(
        approach_velocity=node.declare_parameter('approach_velocity', 0.5).value,
        approach_min_duration=node.declare_parameter('approach_min_duration', 0.0).value,
        sample_period=node.declare_parameter('sample_period', 0.05).value)
    monitor = MonitorThresholds(
        fault_threshold=math.radians(_detector(node, 'fault_threshold_deg')),
        fault_hold=_detector(node, 'fault_hold_sec'),
        tracking_lag=_detector(node, 'tracking_lag_sec'),
        tracking_delay=_detector(node, 'tracking_delay_sec'),
        tracking_time_constant=_detector(node, 'tracking_time_constant_sec'),
        goal_tolerance=math.radians(node.declare_parameter('goal_tolerance_deg', 2.0).value),
        goal_time=node.declare_parameter('goal_time_sec', 2.0).value)
    waits = {'library': node.declare_parameter('library_wait_sec', 10.0).value,
             'carry_on': node.declare_parameter('carry_on_wait_sec', 3.0).value,
             'acceleration': math.radians(
                 node.declare_parameter('acceleration_limit_deg', 600.0).value),
             'joint_states': node.declare_parameter('joint_states_timeout_sec', 1.0).value,
             'first_states': node.declare_parameter('joint_states_wait_sec', 5.0).value,
             'report_faults': node.declare_parameter('report_faults', True).value,
             'clear_path': node.declare_parameter('clear_path', True, ParameterDescriptor(
                 description='bend a path that presses the body deeper than its keyframes '
                             'do (capsule model; needs both arms played)',
                 read_only=True)).value}
    node.declare_parameter('thread_priority', 0, ParameterDescriptor(
        description="SCHED_FIFO priority of the player's threads once it is built (the "
                    "library's real-time consumer, as recovery_node's); 0 = off",
        integer_range=[IntegerRange(from_value=0, to_value=MAX_PRIORITY, step=1)],
        read_only=True))
    if not waits['carry_on'] >= 0:
        raise ValueError(f'carry_on_wait_sec must be >= 0, got {waits["carry_on"]}')
    if not waits['acceleration'] > 0:
        raise ValueError('acceleration_limit_deg must be > 0, got '
                         f'{math.degrees(waits["acceleration"])}')
    return robot, groups, timing, monitor, waits


def reading_age(now, stamp):
    """
    Return how old (s) a reading stamped ``stamp`` is at ROS time ``now``.

    A reading that waited in a queue (a busy executor handles a burst at once), or that
    a simulator running behind real time stamped in the past, is judged where the arm
    was when it was read, on the timeline the commands are stamped on: the detector's
    band is not stretched by anyone's delays.  A stamp that is not this machine's clock
    (zero, further than :data:`STAMP_SKEW` in the future, or older than
    :data:`STAMP_HORIZON`) gives 0: the reading is taken as fresh.
    """
    if not stamp.sec and not stamp.nanosec:
        return 0.0
    age = now - (stamp.sec + stamp.nanosec * 1e-9)
    return max(age, 0.0) if -STAMP_SKEW <= age <= STAMP_HORIZON else 0.0


def _joint_limits(robot, joints):
    """Return (velocity limits, lower, upper) of ``joints`` (rad/s, rad), in that order."""
    lower, upper, speed = np.array([robot.joint_bounds(j) for j in joints]).T
    return speed, lower, upper


def plan_message(plan, joints) -> JointTrajectory:
    """Return the JointTrajectory of ``plan`` for one controller's ``joints`` (no t = 0)."""
    positions, velocities = plan.columns(joints)
    msg = JointTrajectory(joint_names=list(joints))
    for t, q, v in zip(plan.times, positions, velocities):
        if t <= 0.0:
            continue       # the controller starts from where the arm is
        msg.points.append(JointTrajectoryPoint(
            positions=[float(a) for a in q], velocities=[float(a) for a in v],
            time_from_start=duration_msg(float(t))))
    return msg


def path_clearance(player, joints) -> PathClearance | None:
    """Return the PathClearance of the played ``joints``, or None (off, or one arm only)."""
    if not player._waits['clear_path']:
        return None
    try:
        return PathClearance(player._robot, joints)
    except ValueError as exc:
        player.get_logger().warning(f'clear_path: {exc}; paths are played unchecked')
        return None


def explorer(player, robot, inputs, services) -> Exploration:
    """Return the player's :class:`~.exploration.Exploration`, wired to its state."""
    return Exploration(player, robot, PlayerHooks(
        player._command_pubs, player._groups, lambda: player._play is not None,
        player._book.gesture, lambda: player._book.locks(dict(player._measured)),
        lambda: dict(player._measured), player._wake.trigger), inputs, services)


def library_track(msg):
    """Return a /gesture_library message as a GestureTrack, or None if it holds none."""
    try:
        positions, times = trajectory_angles(msg)
    except (ValueError, IndexError):
        return None
    track = GestureTrack(msg.header.frame_id, tuple(msg.joint_names), np.array(times),
                         positions, stamp_key(msg.header.stamp))
    return track if track.name and len(times) else None


def unplayed_joints(track, joints, said):
    """
    Return the warning, once per gesture and joint set, for joints no controller takes.

    On a robot with a torso every gesture's trajectory names its shared joints, at 0
    unless the recovery's ``expand_shared`` leaned it.  A player whose ``controllers``
    do not list them plays the arms without them: silently while they stay at 0 (the
    torso is where the design has it), with one warning per gesture and joint set
    (``said`` remembers) for a lean it does not play.
    """
    unplayed = tuple(j for i, j in enumerate(track.joint_names)
                     if j not in joints and np.any(track.positions[:, i]))
    if not unplayed or (track.name, unplayed) in said:
        return ''
    said.add((track.name, unplayed))
    return (f'gesture {track.name!r} leans joints that no controller takes '
            f'({", ".join(unplayed)}): played without them')


class CommandLinks:
    """
    The controllers' command publishers, and since when each has had a subscriber.

    A goal published before the match would be lost.  So, we think, can one published
    right after the publisher first sees the subscription: the controller's side may not
    have matched this publisher yet, and a volatile reader that matches later may take
    the goal for history.  That is our reading of one failure, not reproduced: the
    demo's first play in one CI run of many, where the arm never moved.  A controller
    that a play sees subscribed for the first time, or again after a play found it
    gone, is given :data:`MATCH_SETTLE_SEC` before a goal goes to it.
    """

    def __init__(self, pubs):
        self.pubs = pubs                     # controller -> JointTrajectory publisher
        self.matched_at = {}                 # controller -> when first seen subscribed

    def idle(self):
        """Return the controllers that nobody subscribes to."""
        return [c for c, pub in self.pubs.items() if not pub.get_subscription_count()]

    def settled_at(self, now):
        """Note the subscriptions seen at ``now``; return when the newest one is settled."""
        for controller, pub in self.pubs.items():
            if pub.get_subscription_count():
                self.matched_at.setdefault(controller, now)
            else:
                self.matched_at.pop(controller, None)
        return max(self.matched_at.values(), default=now) + MATCH_SETTLE_SEC

    async def ready(self, wait, timeout):
        """
        Wait for every controller's subscription, then for it to settle; return the idle.

        ``wait(deadline)`` is the node's: a future done at its next input or at
        ``deadline``.  Gives up after ``timeout`` s without every subscription.
        """
        end = time.monotonic() + timeout
        while self.idle() and time.monotonic() < end:
            await wait(end)
        settled = self.settled_at(time.monotonic())
        while not self.idle() and time.monotonic() < settled:
            await wait(settled)
        return self.idle()


class GesturePlayer(Node):
    """Play gestures of the current library on trajectory controllers."""

    def __init__(self, **kwargs):
        """Declare parameters and create the interfaces."""
        super().__init__(NODE_NAME, **kwargs)
        (self._robot, self._groups, self._timing, self._monitor,
         self._waits) = _declare(self)
        self._joints = [j for group in self._groups.values() for j in group]
        self._unplayed_said = set()
        self._limits, self._clearance = (_joint_limits(self._robot, self._joints),
                                         path_clearance(self, self._joints))
        self._book = PlayerBook()
        self._measured = {}           # joint -> angle
        self._speeds = {}             # joint -> velocity, when /joint_states has them
        self._measured_at = None
        self._play = None             # (gesture, CarryOn, start time, future)
        self._waiters = []            # (deadline, future): woken by inputs or the deadline
        self._waiter_lock = threading.Lock()
        self._play_services = {}
        self._wake = self.create_guard_condition(lambda: None)
        inputs = MutuallyExclusiveCallbackGroup()
        self._service_group = ReentrantCallbackGroup()
        latched = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(JointTrajectory, '/gesture_library', self._on_library,
                                 latched, callback_group=inputs)
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 50,
                                 callback_group=inputs)
        sensor = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(JointState, '/joint_states', self._on_joint_states, sensor,
                                 callback_group=inputs)
        reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(JointState, '/actuator_fault', self._on_fault, reliable,
                                 callback_group=inputs)
        self._fault_pub = self.create_publisher(JointState, '/actuator_fault', reliable)
        self._command_pubs = {c: self.create_publisher(JointTrajectory,
                                                       f'{c}/joint_trajectory', 10)
                              for c in self._groups}
        self._links = CommandLinks(self._command_pubs)
        self.create_timer(TICK, self._tick, callback_group=inputs)
        self._structure = StructureWatch(self, self._robot, inputs)   # structure_watch.py
        self._exploration = explorer(self, self._robot, inputs, self._service_group)
        self._structure.on_notice = self._exploration.notice
        attach_watch(self._exploration, self._structure)   # judged on its corrected model
        self.get_logger().info(f'controllers: {", ".join(self._groups)}; waiting for '
                               f'/gesture_library')

    # --- inputs ---------------------------------------------------------------------

    def _on_library(self, msg):
        track = library_track(msg)
        if track is None:
            return
        self._book.add_gesture(track, time.monotonic())
        said = unplayed_joints(track, self._joints, self._unplayed_said)
        if said:
            self.get_logger().warning(said)
        self._offer(track)
        if track.name not in self._play_services:
            self._play_services[track.name] = self.create_service(
                Trigger, f'~/play/{track.name}',
                functools.partial(self._on_play, track.name),
                callback_group=self._service_group)
            self.get_logger().info(f'gesture {track.name!r}: ~/play/{track.name} offered')
        self._resolve_waiters(lambda deadline: True)

    def _offer(self, track):
        """Offer a waiting play its gesture's newest version, if it came after the fault."""
        if self._play is None or self._play[0] != track.name or not self._play[1].waiting:
            return
        waited_from = self._play[2] + self._play[1].waiting_since - EARLY_ANSWER
        if self._book.arrivals.get(track.stamp, 0.0) < waited_from:
            return
        try:
            frames = track.positions[:, [track.joint_names.index(j) for j in self._joints]]
        except ValueError:
            return                    # not every played joint: not a version to play
        self._play[1].offer(track.times, frames, f'library {track.stamp}')

    def _on_diagnostics(self, msg):
        statuses = {s.name[len(RECOVERY_PREFIX):]: s for s in msg.status
                    if s.name.startswith(RECOVERY_PREFIX)}
        if 'faults' not in statuses:
            return
        failed = status_values(statuses['faults']).get('failed_joints', '').split()
        locks = {}
        for joint in failed:
            status = statuses.get(f'joint {joint}')
            if status is not None:
                locks[joint] = parse_lock_angle(status_values(status).get('lock_angle_rad'))
        self._book.node_status(failed, locks)

    def _on_joint_states(self, msg):
        now = time.monotonic()
        for name, angle in zip(msg.name, msg.position):
            self._measured[name] = float(angle)
        if len(msg.velocity) == len(msg.name):
            self._speeds.update(zip(msg.name, map(float, msg.velocity)))
        self._measured_at = now
        if self._waiters:
            self._resolve_waiters(lambda deadline: True)
        if self._play is None or any(j not in self._measured for j in self._joints):
            return
        q = [self._measured[j] for j in self._joints]
        v = [self._speeds[j] for j in self._joints] if all(
            j in self._speeds for j in self._joints) else None
        taken = now - reading_age(self.get_clock().now().nanoseconds * 1e-9,
                                  msg.header.stamp)
        self._apply(self._play[1].update(taken - self._play[2], q, v))

    def _on_fault(self, msg):
        """Hold a joint reported by anyone mid-play where it is, and carry on."""
        if self._play is None or self._waits['carry_on'] <= 0:
            return
        faults = []
        for i, joint in enumerate(msg.name):
            angle = self._measured.get(joint)       # where it is: the measured angle
            if angle is None and i < len(msg.position) and math.isfinite(msg.position[i]):
                angle = float(msg.position[i])
            if joint in self._joints and angle is not None:
                faults.append((joint, angle))
        if faults:
            now = time.monotonic()
            for joint, angle in faults:
                if joint not in self._play[1].holds:
                    self._book.report(joint, angle, now)
            self._apply(self._play[1].fault(now - self._play[2], faults))

    def _tick(self):
        now = time.monotonic()
        if self._play is not None:
            session, start = self._play[1], self._play[2]
            stale = self._measured_at is None or now - self._measured_at > \
                self._waits['joint_states']
            expired = session.expire(now - start)
            if expired is not None:
                self._finish(expired)
            elif stale and now - start > session.end_time + self._monitor.goal_time:
                self._finish(session.playback.abort('no /joint_states: cannot tell whether '
                                                    'the motion finished'))
        self._resolve_waiters(lambda deadline: now >= deadline)

    def _wait(self, deadline):
        """Return a future done at the next library or joint state, or at ``deadline``."""
        future = Future()
        with self._waiter_lock:
            self._waiters.append((deadline, future))
        return future

    def _resolve_waiters(self, due):
        with self._waiter_lock:
            done = [f for d, f in self._waiters if due(d)]
            self._waiters = [(d, f) for d, f in self._waiters if not due(d)]
        for future in done:
            future.set_result(None)
        if done:
            self._wake.trigger()

    # --- playing --------------------------------------------------------------------

    async def _on_play(self, gesture, request, response):
        outcome = await self._play_gesture(gesture)
        response.success = outcome.ok
        response.message = f'{gesture}: {outcome.reason}'
        self.get_logger().info(response.message)
        return response

    async def _play_gesture(self, gesture):
        if self._play is not None:
            return Outcome(False, f'busy playing {self._play[0]!r}')
        end = time.monotonic() + self._waits['library']
        while self._book.library_outdated() and time.monotonic() < end:
            await self._wait(end)
        designed = self._book.gesture(gesture)
        track = self._exploration.served(designed)       # its explored version, if any
        if track is None:
            return Outcome(False, 'not in the library')
        end = time.monotonic() + self._waits['first_states']
        while any(j not in self._measured for j in self._joints) and time.monotonic() < end:
            await self._wait(end)   # none yet (just started, or slow discovery)
        fresh = self._measured_at is not None and \
            time.monotonic() - self._measured_at <= self._waits['joint_states']
        missing = [j for j in self._joints if j not in self._measured]
        if not fresh or missing:
            return Outcome(False, 'no recent /joint_states for '
                                  + (', '.join(missing[:3]) if missing else 'the arms'))
        try:
            plan = self._plan(track)
            design = plan if track is designed else self._plan(designed, track)   # watched
        except (KeyError, ValueError) as exc:
            return Outcome(False, f'cannot plan: {exc}')
        idle = await self._links.ready(self._wait, self._waits['first_states'])
        if idle:
            return Outcome(False, f'nobody subscribes to {idle[0]}/joint_trajectory; is the '
                                  f'controller running?')
        if self._exploration.busy():      # no trials while a gesture plays
            return Outcome(False, self._exploration.busy())
        future = Future()
        session = CarryOn(plan, list(self._groups.values()), self._monitor, self._replan,
                          BlendLimits(self._limits[0],
                                      np.full(len(self._joints), self._waits['acceleration'])),
                          self._waits['carry_on'], self._timing.sample_period,
                          functools.partial(pressed_joints, self._robot, self._joints))
        self._play = (gesture, session, time.monotonic(), future)
        self._send(plan)
        explored = (np.ptp(track.times), plan) if track is not designed else ()
        self._structure.start(gesture, design, *explored)    # its design, not its approach
        return await future

    def _plan(self, track, played=None):   # timed as ``played`` is (its approach), if given
        columns = [track.joint_names.index(j) for j in self._joints]
        start = np.array([self._measured[j] for j in self._joints])
        if played is not None:      # the same approach: from as far from the first frame
            start += track.positions[0, columns] - played.positions[0, columns]
        return self._plan_frames(track.times, track.positions[:, columns], start,
                                 self._book.locks(dict(self._measured)))

    def _replan(self, times, frames, start, holds):
        """Time a reconfigured gesture: the play's holds and the locks known now."""
        return self._plan_frames(times, frames, start,
                                 dict(self._book.locks(dict(self._measured)), **holds))

    def _plan_frames(self, times, frames, start, locks):
        """Time keyframes (in the played joints' order) from ``start`` with ``locks``."""
        limits, lower, upper = self._limits
        return plan_motion(self._joints, start, times, frames, limits, locks=locks, lower=lower,
                           upper=upper, timing=self._timing, clearance=self._clearance)

    def _send(self, plan):
        """
        Command ``plan`` on the play's timeline: one message per controller.

        Its time 0 is the play time where the play put it (``segment_start``: the
        reading that caused it), stamped on the ROS clock: a controller that receives
        it late joins it where the play is (as ros2_control's controller does with a
        past stamp), instead of starting it late; the detector's prediction and the
        controller then run on the same timeline whatever the transport's delay.
        """
        session, start = self._play[1], self._play[2]
        session.sent(time.monotonic() - start)
        ago = time.monotonic() - start - session.segment_start
        stamp = self.get_clock().now() - Duration(nanoseconds=int(max(ago, 0.0) * 1e9))
        for controller, joints in self._groups.items():
            msg = plan_message(plan, joints)
            msg.header.stamp = stamp.to_msg()
            self._command_pubs[controller].publish(msg)

    def _apply(self, step):
        """Carry out a Step of the play: report faults, send a motion, end the play."""
        if step.faults:
            self._report(step.faults)
        if step.send is not None and self._play is not None:
            self._send(step.send)
            track = self._book.gesture(self._play[0])
            if track is not None:
                self._offer(track)        # the answer may have come first
        if step.outcome is not None and self._play is not None:
            self._finish(step.outcome)

    def _report(self, faults):
        """Publish the faults the play detected; hold them in every later play too."""
        if not self._waits['report_faults']:
            return
        now = time.monotonic()
        for joint, angle in faults:
            self._book.report(joint, angle, now)
        self._fault_pub.publish(JointState(name=[j for j, _ in faults],
                                           position=[a for _, a in faults]))
        text = ', '.join(f'{j} held at {math.degrees(a):.1f} deg' for j, a in faults)
        self.get_logger().warning(f'{self._play[0]}: actuator fault detected: {text}; '
                                  f'reported on /actuator_fault'
                                  + ('; carrying on' if self._waits['carry_on'] > 0 else ''))

    def _finish(self, outcome):
        future = self._play[3]
        self._play = None
        self._structure.stop()
        if not outcome.ok:
            self._hold()
        future.set_result(outcome)
        self._wake.trigger()

    def _hold(self):
        """Stop a failed play where the arms are (a locked or stuck joint where it is)."""
        locks = self._book.locks(dict(self._measured))
        for controller, joints in self._groups.items():
            q = [locks.get(j, self._measured.get(j, 0.0)) for j in joints]
            self._command_pubs[controller].publish(JointTrajectory(
                joint_names=list(joints), points=[JointTrajectoryPoint(
                    positions=q, velocities=[0.0] * len(joints),
                    time_from_start=duration_msg(0.2))]))

    def stop(self):
        """End an exploration under way (run_node calls it as the node stops)."""
        self._exploration.stop()


def main(args=None):
    """Run the player until Ctrl-C or SIGTERM; return the exit code."""
    return run_node(NODE_NAME, GesturePlayer, args,
                    config_errors=(ValueError, ParameterException))   # a parameter, robot file


if __name__ == '__main__':
    sys.exit(main())
