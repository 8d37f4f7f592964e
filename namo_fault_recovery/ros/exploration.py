"""
The gesture player's exploration on the robot (issue 18's step 4, through the nodes).

Attached to ``gesture_player`` as :class:`Exploration`.  It offers ``~/explore`` and
``~/stop_exploration`` (std_srvs/Trigger) and, with ``on_structure_change:=adapt``, starts
on its own when the structure watch suspects a change (after the play that noticed it
has ended).  One exploration adapts one motion of one arm:

- the motion is the current library version's gesture (``explore_gesture``, empty: the
  one the change was noticed on, else ``circle``); its design (designed joints, DOF
  expansion stages) comes from ``gesture_file``, the nominal chain from ``profile_file``;
- the typical points are VQ's (:func:`~..recovery.motion.typical_points`, 60 mm for a
  dense motion; every keyframe of a short one); the explorer is
  :func:`~..explore.motion.explore_motion` (``explore_method``, ours by default) on a
  :class:`~..runtime.trial_robot.RosTrialRobot`: the arm's controller and the fingertip tracker;
- every trial pose passes a :class:`~..explore.trial.SafetyCheck` (joint and velocity
  limits, 5 mm of capsule clearance by the model) before it is commanded;
- it runs in a worker thread of its own, never in a callback; trials never run while a
  gesture plays (a play is refused while exploring, and an exploration asked for during
  a play waits for its end); a new ``/actuator_fault`` or ``~/stop_exploration`` ends it
  before its next trial.

Progress and outcome: ``/diagnostics`` status ``gesture_player: exploration`` after
every trial.  The result is served by the player itself: the next plays of that gesture
play the explored version (origin ``explored``) while the library's version of the
gesture is the one it was explored from (the same keyframes), and it is published on
``~/explored_motions`` (latched, stamped with that version).
"""

from dataclasses import dataclass, replace
import math
import os
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .fingertip_topics import measurement, topic, TRACKER_QOS
from .messages import duration_msg
from ..errors import ConfigError
from ..explore.motion import explore_motion, METHODS, motion_layouts, MotionSpec
from ..explore.safety import capsule_clearance
from ..explore.trial import SafetyCheck, TrialSession
from ..model.gestures import load_library
from ..model.robot_profile import load_profile, RobotProfile
from ..model.structure import ArmCorrection, corrected_arm
from ..playback.book import GestureTrack
from ..recovery.motion import DEFAULT_DISTORTION_MM, typical_points
from ..resources import config_path, NAMO_PROFILE_FILE
from ..runtime.explored_store import load_motions, save_motions, stored
from ..runtime.trial_robot import RosTrialRobot, TrialTimeout, TrialTiming

STATUS_NAME = 'gesture_player: exploration'
CORRECTION_NAME = 'gesture_player: structure correction'
DEFAULT_GESTURE = 'circle'
DENSE = 20                  # keyframes: a longer motion is explored at VQ's typical points
SERVED = ('converged', 'budget')


def _declare(node, name, default, text):
    return node.declare_parameter(name, default, ParameterDescriptor(
        description=text, read_only=True)).value


def declare_exploration(node) -> dict:
    """Declare the player's exploration parameters; return {name: value} (checked)."""
    p = {
        'gesture_file': _declare(node, 'gesture_file', '', 'gesture library YAML whose '
                                 'design (designed joints, expansion) the explorer uses '
                                 '(empty: the packaged one)'),
        'profile_file': _declare(node, 'profile_file', '', 'recovery profile of the '
                                 "planner's nominal chains (empty: the packaged Namo one)"),
        'explore_gesture': _declare(node, 'explore_gesture', '', 'gesture ~/explore adapts '
                                    '(empty: the one a change was noticed on, else circle)'),
        'explore_method': _declare(node, 'explore_method', 'secant', "explorer: 'secant' "
                                   "(ours) or 'annealing' (the paper's)"),
        'tracker_sigma_mm': _declare(node, 'tracker_sigma_mm', 1.0, "the tracker's declared "
                                     'noise per axis (mm)'),
        'explore_samples': _declare(node, 'explore_samples', 3, 'tracker readings averaged '
                                    'per trial'),
        'explore_still_deg_s': _declare(node, 'explore_still_deg_s', 0.5, 'an arm whose '
                                        'joints are all slower (deg/s) has settled'),
        'explore_max_settle_sec': _declare(node, 'explore_max_settle_sec', 1.5, 'a trial '
                                           'measures after this long even if not still'),
        'explore_margin_mm': _declare(node, 'explore_margin_mm', 5.0, 'self-collision '
                                      'clearance (mm, by the model) every trial keeps'),
        'explore_state_file': _declare(node, 'explore_state_file', '', 'JSON file the '
                                       'explored motions are kept in across restarts (~ '
                                       'expanded; empty: not kept)'),
    }
    if p['explore_method'] not in METHODS:
        raise ValueError(f'explore_method: {p["explore_method"]!r}; expected one of '
                         f'{", ".join(METHODS)}')
    if not (p['tracker_sigma_mm'] > 0 and math.isfinite(p['tracker_sigma_mm'])):
        raise ValueError(f'tracker_sigma_mm: {p["tracker_sigma_mm"]!r}; expected > 0')
    if not p['explore_margin_mm'] >= 0:
        raise ValueError(f'explore_margin_mm: {p["explore_margin_mm"]!r}; expected >= 0')
    p['timing'] = TrialTiming(p['explore_still_deg_s'], p['explore_max_settle_sec'],
                              p['explore_samples'])
    return p


@dataclass(frozen=True)
class Explored:
    """A motion explored on the robot, as the player serves it."""

    base: object              # the GestureTrack it was explored from (its library version)
    track: object             # the GestureTrack played instead (the base, one arm adapted)
    result: object            # the ExploredMotion

    def adapts(self, track) -> bool:
        """Return True if ``track`` is the motion this was explored from (same keyframes)."""
        base = self.base
        return (track.joint_names == base.joint_names and track.positions.shape ==
                base.positions.shape and np.allclose(track.times, base.times, atol=1e-9)
                and np.allclose(track.positions, base.positions, atol=1e-9))


@dataclass(frozen=True)
class PlayerHooks:
    """What the exploration needs of the player (callables, so no private name crosses)."""

    publishers: dict          # controller -> JointTrajectory publisher
    groups: dict              # controller -> its joints
    playing: object           # () -> True while a gesture plays
    track: object             # name -> the newest GestureTrack, or None
    locks: object             # () -> {joint: lock angle}
    measured: object          # () -> {joint: angle} measured
    wake: object              # () -> wake the executor (a future was completed)


def restored(kept) -> Explored:
    """Return the Explored of a StoredMotion (served for its base keyframes only)."""
    base = GestureTrack(kept.name, kept.joint_names, np.array(kept.times),
                        np.array(kept.base), 0)
    return Explored(base, replace(base, positions=np.array(kept.positions)), None)


def explored_message(track, positions) -> JointTrajectory:
    """Return ``~/explored_motions``' message: ``positions`` on ``track``'s joints and times."""
    msg = JointTrajectory(joint_names=list(track.joint_names))
    msg.header.frame_id = track.name
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(track.stamp), 10 ** 9)
    for t, q in zip(track.times, positions):
        msg.points.append(JointTrajectoryPoint(positions=[float(a) for a in q],
                                               time_from_start=duration_msg(float(t))))
    return msg


def outcome_values(session, res) -> dict:
    """Return the status values of a TrialSession's cost and an ExploredMotion (if any)."""
    values = {}
    if session is not None:
        values.update({'trials': str(session.trials), 'refused': str(session.refused),
                       'robot_seconds': f'{session.seconds:.2f}'})
    if res is not None:
        values.update({
            'origin': res.origin, 'status': res.status,
            'typical_points': str(len(res.typical)),
            'trials_per_point': ' '.join(map(str, res.trials_per_point)),
            'measured_error_mm': f'{res.measured_mean_mm:.2f}',
            'measured_error_max_mm': f'{max(res.measured_error_mm):.2f}',
            'stage': str(res.stage), 'free_joints': ' '.join(res.free_joints),
            'correction': res.correction})
    return values


def first_errors(session, targets) -> tuple:
    """Return per typical point what its first trial measured (mm): the unadapted poses."""
    first = {}
    for point, _, trial in session.log:
        if point in targets and point not in first:
            first[point] = float(np.linalg.norm(trial.tip - targets[point]))
    return tuple(first[p] for p in sorted(first))


def correction_status(robot, profile, track, side, res, unadapted=()) -> DiagnosticStatus:
    """
    Return the ``/structure_correction`` status of an exploration served (latched).

    What ``recovery_node`` adopts with the explored motion of ``~/explored_motions``:
    the arm, the gesture and the library version (``library_stamp``) it was explored
    from, the fitted correction's ``groups`` and ``params`` (one group per ``;``), the
    measured errors at the typical points (after, and at their first trial: before),
    the trials, the explorer and the profile.
    """
    model = res.model
    groups = tuple(model.groups) if model is not None else ()
    params = tuple(model.params) if model is not None else ()
    values = {'arm': side, 'gesture': track.name, 'library_stamp': str(int(track.stamp)),
              'groups': ' '.join(groups),
              'params': '; '.join(' '.join(repr(float(v)) for v in p) for p in params),
              'measured_errors_mm': ' '.join(repr(float(e)) for e in res.measured_error_mm),
              'unadapted_errors_mm': ' '.join(repr(float(e)) for e in unadapted),
              'trials': str(res.trials), 'method': res.method, 'profile': profile.name}
    return DiagnosticStatus(level=DiagnosticStatus.OK, name=CORRECTION_NAME,
                            message=f'{track.name}: {side} arm as measured: {res.correction}'
                            [:300], hardware_id=robot.name,
                            values=[KeyValue(key=k, value=v) for k, v in values.items()])


def corrected_watch(explorer, side, groups, params) -> None:
    """Let the structure watch judge ``side`` on its corrected model (a measured change)."""
    watch = explorer.watch
    if watch is None or not groups:
        return
    arm = corrected_arm(explorer.profile, ArmCorrection(side, tuple(groups), tuple(params)))
    current = dict(watch.robot.corrections)
    current[side] = arm
    watch.robot = watch.robot.with_corrections(current)


def attach_watch(explorer, watch) -> None:
    """Give ``explorer`` the player's StructureWatch, corrected as its kept motions say."""
    explorer.watch = watch
    for side, groups, params in explorer.restored_corrections:
        corrected_watch(explorer, side, groups, params)


def send_pose(explorer, side, q, duration) -> None:
    """Command ``side``'s controller to reach ``q`` in ``duration`` s (from now)."""
    hooks = explorer.hooks
    names = explorer.robot.arms[side].joint_names
    for controller, joints in hooks.groups.items():
        if not set(joints) & set(names):
            continue
        measured = hooks.measured()
        target = dict(zip(names, q))
        msg = JointTrajectory(joint_names=list(joints), points=[JointTrajectoryPoint(
            positions=[float(target.get(j, measured.get(j, 0.0))) for j in joints],
            velocities=[0.0] * len(joints), time_from_start=duration_msg(duration))])
        hooks.publishers[controller].publish(msg)


def motion_spec(explorer, track, side) -> tuple:
    """Return (MotionSpec, SafetyCheck) of ``track``'s ``side`` arm for an Exploration."""
    robot, gesture = explorer.robot, explorer.library[track.name]
    names = robot.arms[side].joint_names
    design = track.positions[:, [track.joint_names.index(j) for j in names]]
    if len(design) > DENSE:
        picks = tuple(int(p) for p in typical_points(robot, [gesture],
                                                     DEFAULT_DISTORTION_MM, 2)
                      [gesture.name].typical)
    else:
        picks = tuple(range(len(design)))
    locks = {names.index(j): a for j, a in explorer.hooks.locks().items() if j in names}
    chain = explorer.chains[side]
    spec = MotionSpec(track.name, chain, design, picks, locks,
                      motion_layouts(robot, gesture, side,
                                     {j: a for j, a in explorer.hooks.locks().items()
                                      if j in names}), names)
    measured = explorer.hooks.measured()
    held = np.array([measured.get(j, 0.0) for j in robot.joint_names])
    safety = SafetyCheck(chain.lower, chain.upper, explorer.arms[side].velocity,
                         capsule_clearance(robot, side, held),
                         explorer.params['explore_margin_mm'])
    return spec, safety


class Exploration:
    """Attached to the player: the services, the worker thread, the explored motions."""

    def __init__(self, node, robot, hooks: PlayerHooks, callback_group=None,
                 service_group=None):
        """Declare the parameters, load the design and the chains, create the interfaces."""
        self.node, self.robot, self.hooks = node, robot, hooks
        self.params = declare_exploration(node)
        try:
            self.library = load_library(robot, self.params['gesture_file'] or None)
            profile = (self.params['profile_file'] or getattr(robot, 'profile', None)
                       or config_path(NAMO_PROFILE_FILE))      # a profile robot: its own
            profile = profile if isinstance(profile, RobotProfile) else load_profile(profile)
        except (ConfigError, FileNotFoundError) as exc:
            raise ValueError(str(exc).splitlines()[0]) from None
        self.profile = profile
        self.watch = None              # the player's StructureWatch (its model is corrected)
        self.chains = {side: profile.arms[side].chain for side in robot.arms}
        self.arms = {side: RosTrialRobot(
            robot.arms[side].joint_names,
            (self.chains[side].lower, self.chains[side].upper,
             np.asarray(robot.arm_velocity_limits(side), dtype=float)),
            lambda q, duration, s=side: send_pose(self, s, q, duration), self._now,
            self.params['timing']) for side in robot.arms}
        self.explored = {}             # gesture -> Explored
        self.restored_corrections = []     # (side, groups, params) from explore_state_file
        self.kept = {}                 # gesture -> StoredMotion (explore_state_file)
        self.noticed = None            # (gesture, side) of the last suspicion
        self.active = None             # (gesture, side) while an exploration runs or waits
        self._stop = threading.Event()
        self._thread = None
        self._lock = threading.Lock()
        self._create_interfaces(callback_group, service_group)
        self._restore()

    def _restore(self):
        """Serve the motions kept in ``explore_state_file`` (a bad file: one-line error)."""
        path = os.path.expanduser(self.params['explore_state_file'])
        if not path:
            return
        try:
            self.kept = load_motions(path)
        except ValueError as exc:
            self.node.get_logger().error(f'explore_state_file: {exc}; starting without '
                                         f'explored motions')
            return
        for name, kept in self.kept.items():
            self.explored[name] = restored(kept)
            self.restored_corrections.append((kept.side, kept.groups, kept.params))
            self.node.get_logger().info(
                f'{name}: explored version restored from {path} ({kept.side} arm, '
                f'{kept.trials} trials, measured {np.mean(kept.measured_error_mm):.2f} mm '
                f'mean; correction {", ".join(kept.groups) or "none"})')

    def _keep(self, track, side, positions, res):
        """Write every explored motion to ``explore_state_file`` (if set; never fatal)."""
        path = os.path.expanduser(self.params['explore_state_file'])
        if not path:
            return
        self.kept[track.name] = stored(track.name, side, track.joint_names, track.times,
                                       track.positions, positions, res)
        try:
            save_motions(path, self.kept)
        except OSError as exc:
            self.node.get_logger().error(f'cannot write {path}: {exc}; the explored '
                                         f'{track.name} will not survive a restart')

    def _create_interfaces(self, group, services):
        node = self.node
        states = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        node.create_subscription(JointState, '/joint_states', self._on_joint_states, states,
                                 callback_group=group)
        prefix = node.get_parameter('tracker_topic').value
        for side in (self.robot.arms if prefix else ()):
            node.create_subscription(
                PointStamped, topic(prefix, side),
                lambda msg, s=side: self.arms[s].fingertip(*measurement(msg)), TRACKER_QOS,
                callback_group=group)
        node.create_subscription(JointState, '/actuator_fault', self._on_fault,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE),
                                 callback_group=group)
        node.create_service(Trigger, '~/explore', self._on_explore, callback_group=services)
        node.create_service(Trigger, '~/stop_exploration', self._on_stop,
                            callback_group=services)
        self._diag_pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        latched = QoSProfile(depth=max(len(self.library), 1),
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._explored_pub = node.create_publisher(JointTrajectory, '~/explored_motions',
                                                   latched)
        self._correction_pub = node.create_publisher(
            DiagnosticStatus, '/structure_correction',
            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))

    def _now(self):
        return self.node.get_clock().now().nanoseconds * 1e-9

    # --- callbacks (never wait) -------------------------------------------------------

    def _on_joint_states(self, msg):
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        for arm in self.arms.values():
            arm.joint_state(stamp or self._now(), msg.name, msg.position, msg.velocity)

    def _on_fault(self, msg):
        if self.active is not None and not self._stop.is_set():
            self._stop.set()
            self.node.get_logger().warning(
                f'exploration: a new fault ({", ".join(msg.name)}) ends it before its next '
                f'trial')

    async def _on_explore(self, request, response):
        future = Future()
        gesture, side = self._choice()
        refused = self.start(gesture, side, future)
        if refused:
            response.success, response.message = False, refused
            return response
        response.success, response.message = await future
        return response

    def _on_stop(self, request, response):
        active = self.active
        if active is None:
            response.success, response.message = False, 'no exploration is running'
            return response
        self._stop.set()
        response.success = True
        response.message = f'stopping the exploration of {active[0]} ({active[1]} arm) ' \
                           f'before its next trial'
        return response

    def _choice(self):
        """Return (gesture, side) that ~/explore adapts."""
        noticed = self.noticed
        gesture = self.params['explore_gesture'] or (
            noticed[0] if noticed else DEFAULT_GESTURE)
        if noticed is not None and noticed[0] == gesture:
            return gesture, noticed[1]
        try:
            return gesture, self.library[gesture].arms[0]
        except KeyError:
            return gesture, None

    # --- starting, stopping, serving ----------------------------------------------

    def notice(self, gesture: str, side: str, adapt: bool) -> None:
        """Take a suspected change of ``side`` noticed on ``gesture``; adapt if asked to."""
        self.noticed = (gesture, side)
        if adapt:
            refused = self.start(gesture, side)
            if refused:
                self.node.get_logger().warning(f'exploration not started: {refused}')

    def start(self, gesture: str, side, future=None) -> str:
        """Start exploring ``gesture`` on ``side`` in the worker thread; return why not, or ''."""
        with self._lock:
            if self.active is not None:
                return f'already exploring {self.active[0]} ({self.active[1]} arm)'
            if side is None or gesture not in self.library.names:
                return f'cannot explore {gesture!r}: not a gesture of {self.library.source}'
            if side not in self.library[gesture].arms:
                return f'cannot explore {gesture!r} on the {side} arm: it does not move it'
            self.active = (gesture, side)
            self._stop.clear()
            self._thread = threading.Thread(target=self._work, args=(gesture, side, future),
                                            name='exploration', daemon=True)
            self._thread.start()
        return ''

    def busy(self) -> str:
        """Return why a play must wait (an exploration runs or waits to), or ''."""
        active = self.active
        if active is None:
            return ''
        return (f'busy exploring {active[0]!r} on the {active[1]} arm (no play while '
                f'trials run; ~/stop_exploration ends it)')

    def served(self, track):
        """Return the explored version of ``track`` if it was explored from it, else ``track``."""
        found = None if track is None else self.explored.get(track.name)
        if found is None or not found.adapts(track):
            return track
        return replace(found.track, stamp=track.stamp)

    def stop(self) -> None:
        """End a running exploration (before its next trial) and wait for its thread."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread.is_alive():
            thread.join(timeout=10.0)

    # --- the worker thread --------------------------------------------------------

    def _work(self, gesture, side, future):
        """Wait for the play to end, explore, serve the result; tell ``future``."""
        ok, text = False, ''
        try:
            while self.hooks.playing() and not self._stop.wait(0.05):
                pass                           # trials never while a gesture plays
            if self._stop.is_set():
                ok, text = False, f'{gesture}: exploration stopped before its first trial'
                self._status('stopped', gesture, side, text)
            else:
                ok, text = self._explore(gesture, side)
        except (TrialTimeout, ValueError, KeyError) as exc:
            text = f'{gesture}: exploration failed: {exc}'
            self._status('failed', gesture, side, text)
        except Exception:  # noqa: B902 - only a shutdown under the thread is expected
            if self.node.context.ok():
                raise
            # A signal shut ROS down under this thread (rclpy's handler, before the node's
            # stop() could end it): its last publish failed; nothing is left to tell.
            text = f'{gesture}: exploration ended: ROS shut down under it'
        finally:
            with self._lock:
                self.active = None
            if ok:          # one call site per severity (rclpy's rule)
                self.node.get_logger().info(text)
            else:
                self.node.get_logger().warning(text)
            if future is not None:
                future.set_result((ok, text))
                self.hooks.wake()

    def _explore(self, gesture, side):
        """Run one exploration; return (served, one line)."""
        track = self.hooks.track(gesture)
        if track is None:
            raise KeyError(f'{gesture!r} is not in the library received')
        spec, safety = motion_spec(self, track, side)
        picks = list(spec.picks)
        targets = dict(zip(picks, spec.chain.batch_forward(spec.design[picks]).tip))
        session = TrialSession(self.arms[side], safety)
        session.should_stop = lambda: self._progress(session, gesture, side, targets)
        sigma = self.params['tracker_sigma_mm'] / math.sqrt(self.params['timing'].samples)
        began = time.monotonic()
        res = explore_motion(session, spec, self.params['explore_method'], sigma)
        text = (f'{gesture}: explored on the {side} arm ({res.method}): {res.trials} trials at '
                f'{len(res.typical)} typical points in {time.monotonic() - began:.1f} s, '
                f'measured error {res.measured_mean_mm:.2f} mm mean, '
                f'{max(res.measured_error_mm):.2f} mm max; {res.status}')
        if res.status not in SERVED:
            self._status('stopped' if res.status == 'stopped' else 'failed', gesture, side,
                         text, session, res)
            return False, text
        self._serve(track, side, res, first_errors(session, targets))
        self._status('done', gesture, side, text + '; the explored version is played from now '
                     'on', session, res)
        return True, text

    def _serve(self, track, side, res, unadapted=()):
        """Keep the explored version of ``track`` to play, and publish it (latched)."""
        names = self.robot.arms[side].joint_names
        positions = np.array(track.positions, dtype=float)
        positions[:, [track.joint_names.index(j) for j in names]] = res.q
        self.explored[track.name] = Explored(track, replace(track, positions=positions), res)
        self._keep(track, side, positions, res)
        self._explored_pub.publish(explored_message(track, positions))
        self._correction_pub.publish(correction_status(self.robot, self.profile, track, side,
                                                       res, unadapted))
        if res.model is not None:
            corrected_watch(self, side, res.model.groups, res.model.params)

    def _progress(self, session, gesture, side, targets):
        """Publish the progress before each trial; return True to stop (should_stop)."""
        stop = self._stop.is_set() or self.hooks.playing()
        if session.log:
            point, _, trial = session.log[-1]
            error = (float(np.linalg.norm(trial.tip - targets[point])) if point in targets
                     else float('nan'))
            self._status('running', gesture, side,
                         f'{gesture}: exploring the {side} arm: {session.trials} trials, '
                         f'typical point {point}: {error:.1f} mm measured', session,
                         extra={'point': str(point), 'last_error_mm': f'{error:.2f}'})
        return stop

    def _status(self, state, gesture, side, text, session=None, res=None, extra=None):
        """Publish ``gesture_player: exploration`` on /diagnostics."""
        level = {'running': DiagnosticStatus.OK, 'done': DiagnosticStatus.OK,
                 'stopped': DiagnosticStatus.WARN}.get(state, DiagnosticStatus.ERROR)
        values = {'state': state, 'gesture': gesture, 'arm': str(side),
                  'method': self.params['explore_method']}
        values.update(outcome_values(session, res))
        if res is not None:
            found = self.explored.get(gesture)
            if found is not None and found.result is res:
                values['library_stamp'] = str(found.base.stamp)
        values.update(extra or {})
        status = DiagnosticStatus(level=level, name=STATUS_NAME, message=text[:300],
                                  hardware_id=self.robot.name,
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        try:
            self._diag_pub.publish(msg)
        except Exception:  # noqa: B902 - the node shut down under the worker thread
            if self.node.context.ok():
                raise
