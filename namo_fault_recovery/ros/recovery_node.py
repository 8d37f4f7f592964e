"""
``recovery_node``: the ROS 2 node that reconfigures Namo's gesture library after faults.

The contract (topics, services, QoS, behaviour) is documented in ``msg_docs/``.  In
short: a fault report on ``/actuator_fault`` locks joints and triggers reconfiguration
of the whole library in a worker thread, within ``deadline_sec``; the library is
published on ``/gesture_library`` (transient local, one JointTrajectory per gesture);
``/reconfigure_gestures`` answers once the library it reports on is published;
``/clear_faults`` returns to the reference library.  The fault set and the last library
persist in ``state_dir`` and are republished after a restart.
"""

from concurrent.futures import ThreadPoolExecutor
import math
from pathlib import Path
import signal
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.exceptions import InvalidParameterTypeException, ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray
import yaml

from . import messages as conv
from .inputs import BadInput, parse_fault, parse_joint_state
from .state_store import Fault, fingerprint, StateStore
from ..errors import ConfigError
from ..model.gestures import load_library
from ..model.robot import ARMS, load_robot
from ..objective.score import COMPONENTS, ScoreWeights
from ..optimize import ALGORITHMS, PRESETS
from ..optimize.base import Clock
from ..recovery.engine import recover, RecoverySettings
from ..recovery.keyframes import BIMANUAL_MODES
from ..recovery.locks import frozen_arms
from ..recovery.locks import LOCK_STRATEGIES
from ..recovery.motion import DEFAULT_CONTINUITY, DEFAULT_DISTORTION_MM, METHODS, typical_points

NODE_NAME = 'recovery_node'
DEFAULT_STATE_DIR = '~/.ros/namo_fault_recovery'
EXIT_CONFIG = 1
MAX_REJECTIONS_SHOWN = 10
_WEIGHT_PARAMS = tuple(f'weights.{c}' for c in COMPONENTS)
_CHOICES = {
    'lock_strategy': LOCK_STRATEGIES,
    'optimizer': tuple(ALGORITHMS),
    'optimizer_preset': tuple(PRESETS),
    'bimanual': tuple(BIMANUAL_MODES),
    'trajectory_method': METHODS,
    'tool_arm': ARMS,
}
# Changing one of these changes what the library should be: the node reconfigures again.
_RERUN_PARAMS = frozenset(('deadline_sec', 'lock_strategy', 'optimizer', 'optimizer_preset',
                           'seed', 'bimanual', 'collision_check', 'tool_length_mm',
                           'tool_arm', 'trajectory_method', 'vq_distortion_mm',
                           'continuity_weight') + _WEIGHT_PARAMS
                          + ('weights.normalise',))
_MARKER_PARAMS = frozenset(('marker_frame_id', 'marker_spacing'))
_TYPE_NAMES = {str: 'a string', float: 'a floating-point number', int: 'an integer',
               bool: 'true or false'}


class StartupError(Exception):
    """The node cannot start; the message is the one-line reason shown to the user."""


def _fp_range(low, high):
    return [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]


def _parameter_specs():
    """Return (name, default, descriptor) for every parameter of the node."""
    specs = [
        ('robot_file', '', ParameterDescriptor(
            description='arm model YAML (DH, joint names, limits); empty = the packaged '
                        'Namo model', read_only=True)),
        ('gesture_file', '', ParameterDescriptor(
            description='reference gesture library YAML; empty = the packaged library',
            read_only=True)),
        ('deadline_sec', 1.0, ParameterDescriptor(
            description='hard budget (s) for one reconfiguration of the whole library',
            floating_point_range=_fp_range(0.01, 60.0))),
        ('lock_strategy', 'average', ParameterDescriptor(
            description='lock angle of a joint reported without a position',
            additional_constraints='one of: ' + ', '.join(LOCK_STRATEGIES))),
        ('optimizer', 'abc', ParameterDescriptor(
            description="optimiser (abc = the paper's artificial bee colony; the others for "
                        'comparison)',
            additional_constraints='one of: ' + ', '.join(ALGORITHMS))),
        ('optimizer_preset', 'default', ParameterDescriptor(
            description='optimiser settings: default (product tuning) or paper (Table 3)',
            additional_constraints='one of: ' + ', '.join(PRESETS))),
        ('bimanual', 'auto', ParameterDescriptor(
            description='two-handed gestures: let the healthy arm move too (stage 2): '
                        'auto = when the faulted arm alone scores poorly',
            additional_constraints='one of: ' + ', '.join(BIMANUAL_MODES))),
        ('collision_check', True, ParameterDescriptor(
            description='keep the arms and the torso apart, and report poses that collide')),
        ('tool_length_mm', 0.0, ParameterDescriptor(
            description='a tool in the hand of tool_arm lengthens it by this much (mm): a '
                        'structure change; 0 = none.  Changing it re-adapts the library',
            floating_point_range=_fp_range(0.0, 300.0))),
        ('tool_arm', 'right', ParameterDescriptor(
            description='the arm whose hand holds the tool',
            additional_constraints='one of: ' + ', '.join(ARMS))),
        ('trajectory_method', 'auto', ParameterDescriptor(
            description='motions: kriging = typical points + Kriging (the second paper); '
                        'per_point = every point in order; auto = kriging, then per point '
                        'where the deadline allows',
            additional_constraints='one of: ' + ', '.join(METHODS))),
        ('vq_distortion_mm', DEFAULT_DISTORTION_MM, ParameterDescriptor(
            description='quantisation distortion threshold (mm of fingertip) that sets '
                        'the number of typical points of a dense motion',
            floating_point_range=_fp_range(1.0, 1000.0))),
        ('continuity_weight', DEFAULT_CONTINUITY, ParameterDescriptor(
            description='per-point adaptation: penalty per deg^2 of joint jump away from '
                        'the previous point plus the designed step',
            floating_point_range=_fp_range(0.0, 100.0))),
        ('seed', -1, ParameterDescriptor(
            description='random seed for reproducible runs; -1 draws one per run',
            integer_range=[IntegerRange(from_value=-1, to_value=2 ** 31 - 1, step=1)])),
    ]
    for component in COMPONENTS:
        specs.append((f'weights.{component}', 1.0, ParameterDescriptor(
            description=f'score weight of the {component} component (>= 0)',
            floating_point_range=_fp_range(0.0, 1000.0))))
    specs += [
        ('weights.normalise', True, ParameterDescriptor(
            description='scale the weights a gesture uses so they sum to 1 (the paper)')),
        ('state_dir', DEFAULT_STATE_DIR, ParameterDescriptor(
            description='directory where the fault set and the last library persist',
            read_only=True)),
        ('marker_frame_id', 'base_link', ParameterDescriptor(
            description='frame of the /gesture_markers skeletons (the torso centre)')),
        ('marker_spacing', 0.8, ParameterDescriptor(
            description='distance (m) between the gestures shown on /gesture_markers',
            floating_point_range=_fp_range(0.0, 10.0))),
        ('diagnostics_period_sec', 1.0, ParameterDescriptor(
            description='period (s) of /diagnostics (also published on every change)',
            floating_point_range=_fp_range(0.1, 60.0), read_only=True)),
    ]
    return specs


def check_parameter(name, value, current=None):
    """
    Return None if ``value`` is acceptable for parameter ``name``, else the reason.

    ``current`` maps the other parameters to their values, for the checks that involve
    several (the score weights).  Types and ranges are also enforced by the descriptors.
    """
    if name in _CHOICES and value not in _CHOICES[name]:
        return (f'{name}: unknown value {value!r}; expected one of '
                f'{", ".join(_CHOICES[name])}')
    if name in _WEIGHT_PARAMS or name == 'weights.normalise':
        if name in _WEIGHT_PARAMS and (not isinstance(value, float) or not math.isfinite(value)
                                       or value < 0):
            return f'{name}: expected a finite number >= 0, got {value!r}'
        if current is not None and all(p in current for p in _WEIGHT_PARAMS):
            mapping = {p.split('.', 1)[1]: current[p] for p in _WEIGHT_PARAMS
                       + ('weights.normalise',) if p in current}
            mapping[name.split('.', 1)[1]] = value
            try:
                ScoreWeights.from_mapping(mapping)
            except ValueError as exc:
                return str(exc)
    if name == 'deadline_sec' and (not isinstance(value, float) or not math.isfinite(value)
                                   or value <= 0):
        return f'deadline_sec: expected a positive number of seconds, got {value!r}'
    return None


class RecoveryNode(Node):
    """The fault-recovery node; see the module docstring and ``msg_docs/``."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._ready = False
        self._stopping = False
        self._cond = threading.Condition()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self._declare_parameters()
        self._settings = self._read_settings()

        robot_file = self.get_parameter('robot_file').value or None
        gesture_file = self.get_parameter('gesture_file').value or None
        try:
            self._robot = load_robot(robot_file)
            self._library = load_library(self._robot, gesture_file)
        except (ConfigError, FileNotFoundError) as exc:
            raise StartupError(f'invalid configuration: {_one_line(exc)}') from None
        self._joint_names = tuple(self._robot.joint_names)
        self._fingerprint = fingerprint(self._robot.source, self._library.source)
        self._reference = conv.reference_result(self._library)
        self._typical_cache = None

        # State, guarded by self._cond.
        self._faults = {}                 # joint -> Fault, in arrival order
        self._fault_version = 0           # bumped on every accepted fault-set change
        self._requested_gen = 0           # bumped whenever the library must be recomputed
        self._handled_gen = 0             # highest generation taken by the worker or clear
        self._running_gen = None
        self._published_gen = 0
        self._failed = None               # (gen, reason) of the last failed run
        self._current = None              # LibraryResult last published
        self._library_version = 0
        self._last_stamp_ns = 0
        self._persist_seq = 0
        self._measured = {}               # joint -> latest measured angle (rad)
        self._rejections = []             # (wall time, source, reason), newest last
        self._rejected_total = 0
        self._last_accepted = 0.0
        self._state_problem = None
        self._persist_problem = None
        self._last_state_reject = (None, 0.0)
        self._joint_states_received = 0

        self._store = StateStore(self.get_parameter('state_dir').value or DEFAULT_STATE_DIR)
        self._housekeeping = ThreadPoolExecutor(max_workers=1,
                                                thread_name_prefix='housekeeping')
        try:
            self._start()
        except BaseException:
            self.stop()           # no thread may outlive a node that failed to start
            raise

    def _start(self):
        self._create_interfaces()
        self.get_logger().info(
            f'robot {self._robot.name} ({self._robot.source}), {len(self._library)} gestures '
            f'({self._library.source}); state in {self._store.directory}')
        with self._cond:
            self._publish_locked(self._reference)
        self._restore()
        if self._settings['tool_mm'] > 0 and not self._faults:
            with self._cond:   # a tool from the start is a structure change to adapt to
                self._requested_gen += 1
        self._worker = threading.Thread(target=self._work, name='reconfigure', daemon=True)
        self._worker.start()
        self._ready = True
        self._publish_diagnostics()

    # --- parameters -----------------------------------------------------------------

    def _declare_parameters(self):
        for name, default, descriptor in _parameter_specs():
            self._last_param_reason = None
            try:
                self.declare_parameter(name, default, descriptor)
            except InvalidParameterTypeException:
                override = getattr(self, '_parameter_overrides', {}).get(name)
                value = override.value if override is not None else None
                raise StartupError(
                    f'invalid parameter {name}: expected {_TYPE_NAMES[type(default)]}'
                    + (f' (write {float(value)!r}, not {value!r})' if isinstance(value, int)
                       and isinstance(default, float) else '')
                    + f', got {value!r}') from None
            except ParameterException as exc:
                reason = self._last_param_reason
                if reason is None:
                    text = _one_line(exc)
                    reason = text.split('Reason: ', 1)[-1].removesuffix(f': {name}')
                if not reason.startswith(name):
                    reason = f'{name}: {reason}'
                raise StartupError(f'invalid parameter {reason}') from None

    def _read_settings(self):
        values = {name: self.get_parameter(name).value for name, _, _ in _parameter_specs()}
        for name, value in values.items():
            reason = check_parameter(name, value, values)
            if reason:
                raise StartupError(f'invalid parameter {reason}')
        return self._settings_from(values)

    @staticmethod
    def _settings_from(values):
        weights = {p.split('.', 1)[1]: values[p]
                   for p in _WEIGHT_PARAMS + ('weights.normalise',)}
        seed = int(values['seed'])
        return {
            'deadline': float(values['deadline_sec']),
            'lock_strategy': values['lock_strategy'],
            'algorithm': values['optimizer'],
            'preset': values['optimizer_preset'],
            'seed': None if seed < 0 else seed,
            'bimanual': values['bimanual'],
            'collision': bool(values['collision_check']),
            'tool_mm': float(values['tool_length_mm']),
            'tool_arm': values['tool_arm'],
            'method': values['trajectory_method'],
            'distortion_mm': float(values['vq_distortion_mm']),
            'continuity': float(values['continuity_weight']),
            'weights': ScoreWeights.from_mapping(weights),
            'marker_frame_id': values['marker_frame_id'],
            'marker_spacing': float(values['marker_spacing']),
        }

    def _current_values(self):
        return {name: self.get_parameter(name).value for name, _, _ in _parameter_specs()
                if self.has_parameter(name)}

    def _on_set_parameters(self, parameters):
        current = self._current_values()
        for param in parameters:
            current[param.name] = param.value
        for param in parameters:
            reason = check_parameter(param.name, param.value, current)
            if reason:
                self._last_param_reason = reason
                if self._ready:
                    self._reject('parameter', reason)
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, parameters):
        if not self._ready:
            return
        names = {p.name for p in parameters}
        settings = self._settings_from(self._current_values())
        with self._cond:
            self._settings = settings
            rerun = bool(names & _RERUN_PARAMS) and (bool(self._faults) or 'tool_length_mm'
                                                     in names or settings['tool_mm'] > 0)
            if rerun:
                self._requested_gen += 1
                self._cond.notify_all()
            current = self._current
        changed = ', '.join(f'{p.name}={p.value!r}' for p in parameters)
        self.get_logger().info(f'parameters set: {changed}'
                               + ('; reconfiguring the library' if rerun else ''))
        if names & _MARKER_PARAMS and current is not None:
            self._publish_markers(current, self.get_clock().now().to_msg())

    # --- interfaces -----------------------------------------------------------------

    def _create_interfaces(self):
        library_qos = QoSProfile(depth=len(self._library), history=HistoryPolicy.KEEP_LAST,
                                 reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
        latched = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        fault_qos = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                               reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.VOLATILE)
        states_qos = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                                reliability=ReliabilityPolicy.BEST_EFFORT,
                                durability=DurabilityPolicy.VOLATILE)
        # Relative names: /gesture_library etc. in the root namespace, and per robot
        # under `--ros-args -r __ns:=/robot1`.  /diagnostics is global by convention.
        self._library_pub = self.create_publisher(JointTrajectory, 'gesture_library',
                                                  library_qos)
        self._marker_pub = self.create_publisher(MarkerArray, 'gesture_markers', latched)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        # Fault reports are handled one at a time, in order; joint states in their own
        # group so that a fast stream never delays a fault.  The reconfigure service
        # waits for the worker, in its own group, so it never blocks anything else.
        self.create_subscription(JointState, 'actuator_fault', self._on_fault, fault_qos,
                                 callback_group=MutuallyExclusiveCallbackGroup())
        self.create_subscription(JointState, 'joint_states', self._on_joint_states,
                                 states_qos, callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(Trigger, 'reconfigure_gestures', self._on_reconfigure,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(Trigger, 'clear_faults', self._on_clear,
                            callback_group=MutuallyExclusiveCallbackGroup())
        period = self.get_parameter('diagnostics_period_sec').value
        self.create_timer(period, self._publish_diagnostics)

    # --- inputs ---------------------------------------------------------------------

    def _reject(self, source, reason):
        self.get_logger().warning(f'rejected {source}: {reason}; previous state kept')
        with self._cond:
            self._rejected_total += 1
            self._rejections.append((time.time(), source, reason))
            del self._rejections[:-MAX_REJECTIONS_SHOWN]
        if self._ready:
            self._publish_diagnostics()

    def _on_fault(self, msg):
        try:
            parsed = parse_fault(self._robot, msg.name, msg.position, msg.velocity, msg.effort)
        except BadInput as exc:
            self._reject('/actuator_fault', str(exc))
            return
        with self._cond:
            for joint, angle in parsed.items():
                old = self._faults.get(joint)
                if angle is None and old is not None:
                    fault = old            # still stuck where it was reported
                else:
                    fault = Fault(angle, self._measured.get(joint))
                self._faults[joint] = fault
            self._fault_version += 1
            self._requested_gen += 1
            self._last_accepted = time.time()
            self._cond.notify_all()
            frozen = frozen_arms(self._robot, self._faults)
        # Persistence and diagnostics happen in the worker, so that a burst of reports is
        # taken off the 10-deep subscription queue as fast as it arrives.
        described = ', '.join(
            f'{j} at {conv.fmt_angle(a)}' if a is not None else
            f'{j} (lock angle: {self._settings["lock_strategy"]} strategy)'
            for j, a in parsed.items())
        self.get_logger().info(f'fault accepted: {described}; reconfiguring the library'
                               + (f" (arm {', '.join(frozen)} frozen)" if frozen else ''))

    def _on_joint_states(self, msg):
        try:
            measured = parse_joint_state(self._robot, msg.name, msg.position)
        except BadInput as exc:
            # A stream: the same bad reading is reported at most once a second.
            reason, now = str(exc), time.monotonic()
            if reason != self._last_state_reject[0] or now - self._last_state_reject[1] > 1.0:
                self._last_state_reject = (reason, now)
                self._reject('/joint_states', reason)
            return
        with self._cond:
            self._measured.update(measured)
            self._joint_states_received += 1

    # --- services -------------------------------------------------------------------

    def _on_reconfigure(self, request, response):
        timeout = max(10.0, 5.0 * self._settings['deadline'])
        with self._cond:
            failed_gen = self._failed[0] if self._failed else 0
            if self._requested_gen > max(self._published_gen, failed_gen):
                target = self._requested_gen      # a run for the current state is pending
            else:
                self._requested_gen += 1          # run again for the current fault set
                target = self._requested_gen
                self._cond.notify_all()
            end = time.monotonic() + timeout
            while (not self._stopping and self._published_gen < target
                   and not (self._failed and self._failed[0] >= target)):
                remaining = end - time.monotonic()
                if remaining <= 0:
                    break
                self._cond.wait(remaining)
            published = self._published_gen >= target
            current = self._current
            version = self._library_version
            stamp = self._last_stamp_ns
            failed = self._failed
        if published:
            response.success = bool(current.success)
            response.message = (f'{conv.summary(current)} [library version {version}, '
                                f'stamp {stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d}]')
        elif self._stopping:
            response.success = False
            response.message = 'the node is shutting down; no library was published'
        elif failed and failed[0] >= target:
            response.success = False
            response.message = f'reconfiguration failed: {failed[1]}; previous library kept'
        else:
            response.success = False
            response.message = (f'timed out after {timeout:.1f} s waiting for the '
                                f'reconfiguration; previous library kept')
        return response

    def _on_clear(self, request, response):
        with self._cond:
            count = len(self._faults)
            self._faults = {}
            self._fault_version += 1
            self._requested_gen += 1
            self._last_accepted = time.time()
            tool_mm = self._settings['tool_mm']
            if tool_mm <= 0:
                self._handled_gen = self._requested_gen
                self._published_gen = self._requested_gen
                result = conv.reference_result(self._library, self._settings['deadline'],
                                               engine_settings(self._settings).public())
                self._persist_locked(result)
                self._publish_locked(result)
            # else the tool is still there: the worker adapts the library to it alone.
            self._cond.notify_all()
        if tool_mm <= 0:
            done = f'the reference library is published ({len(self._library)} gestures)'
        else:
            done = (f'the library is being adapted to the {tool_mm:g} mm tool alone '
                    f'(tool_length_mm)')
        self.get_logger().info(f'cleared {count} fault(s); {done}')
        self._publish_diagnostics()
        response.success = True
        response.message = f'cleared {count} fault(s); {done}'
        return response

    # --- the worker -----------------------------------------------------------------

    def _warm_up(self):
        """
        Run one throw-away reconfiguration so the first real fault meets warm caches.

        The first call after start-up pays one-off costs (imports, first allocations) of
        some 20 ms inside its deadline; this pays them before any fault arrives.
        """
        try:
            joint = self._robot.arms['right'].joint_names[0]
            recover(self._robot, self._library, {joint: None},
                    RecoverySettings(trajectory_method='kriging'), seed=0,
                    clock=Clock(0.2, lambda: self._stopping),
                    quantisations=self._typical_points(self._settings['distortion_mm']))
        except Exception as exc:  # noqa: B902 - a warm-up problem must not stop the node
            self.get_logger().warning(f'warm-up run failed: {type(exc).__name__}: {exc}')

    def _work(self):
        self._warm_up()
        while not self._stopping:
            try:
                self._work_once()
            except Exception as exc:  # noqa: B902 - the worker must outlive any bug
                if not self._live():
                    return            # e.g. a publish raced with SIGTERM
                with self._cond:
                    self._running_gen = None
                    self._failed = (self._handled_gen, f'{type(exc).__name__}: {exc}')
                    self._cond.notify_all()
                self.get_logger().error(f'reconfiguration worker: {type(exc).__name__}: '
                                        f'{exc}; previous library kept')

    def _work_once(self):
        """Wait for a request, run it, publish the result unless it went stale."""
        while True:
            with self._cond:
                while not self._stopping and self._requested_gen <= self._handled_gen:
                    self._cond.wait()
                if self._stopping:
                    return
                gen = self._requested_gen
                self._handled_gen = gen
                self._running_gen = gen
                faults = dict(self._faults)
                measured = dict(self._measured)
                settings = dict(self._settings)
                snapshot = self._snapshot_locked(self._current)
            # The new fault set (with the old library) is persisted, and the diagnostics
            # say a run started, beside the run rather than before it.
            self._background(self._write, snapshot)
            self._background(self._publish_diagnostics)

            def cancel(gen=gen):
                return self._stopping or self._requested_gen != gen

            try:
                result = self._compute(faults, measured, settings, cancel)
                problem = self._check_result(result, faults)
            except Exception as exc:  # noqa: B902 - a failed run must not kill the worker
                result, problem = None, f'{type(exc).__name__}: {exc}'
            with self._cond:
                self._running_gen = None
                if self._stopping:
                    return
                if gen != self._requested_gen:
                    continue                      # stale: a newer request supersedes it
                if problem:
                    self._failed = (gen, problem)
                    self._cond.notify_all()
                else:
                    snapshot = self._snapshot_locked(result)
            if not problem:
                # Persist first: once a client has the library, a restart restores it.
                self._write(snapshot)
                with self._cond:
                    if self._stopping:
                        return
                    if gen != self._requested_gen:
                        continue                  # superseded while writing
                    self._publish_locked(result)
                    self._published_gen = gen
                    self._cond.notify_all()
            if not self._live():
                return
            if problem:
                self.get_logger().error(f'reconfiguration failed: {problem}; '
                                        f'previous library kept')
            elif result.success:
                self.get_logger().info(conv.summary(result))
            else:
                self.get_logger().warning(conv.summary(result))
            self._background(self._publish_diagnostics)

    def _typical_points(self, distortion_mm):
        """Return the library's typical points (they depend on the designed motions only)."""
        cached = self._typical_cache
        if cached is None or cached[0] != distortion_mm:
            cached = (distortion_mm, typical_points(self._robot, self._library, distortion_mm))
            self._typical_cache = cached
        return cached[1]

    def _compute(self, faults, measured, settings, cancel):
        for joint, fault in faults.items():
            if fault.measured is not None:
                measured[joint] = fault.measured   # where it stopped when it failed
        return recover(self._robot, self._library, {j: f.angle for j, f in faults.items()},
                       engine_settings(settings), seed=settings['seed'],
                       clock=Clock(settings['deadline'], cancel), measured=measured,
                       quantisations=self._typical_points(settings['distortion_mm']))

    def _check_result(self, result, faults=None):
        """Return None if ``result`` is safe to publish, else the reason it is not."""
        if result.names != self._library.names:
            return (f'library gestures {list(result.names)} do not match the configured '
                    f'{list(self._library.names)}')
        if faults is not None and set(result.locks) != set(faults):
            return (f'locked joints {sorted(result.locks)} do not match the fault set '
                    f'{sorted(faults)}')
        columns = {}
        for joint, angle in result.locks.items():
            try:
                side, index = self._robot.locate_joint(joint)
            except KeyError as exc:
                return exc.args[0]
            if not (math.isfinite(angle) and self._robot.within_limits(side, index, angle)):
                return f'lock angle {angle!r} of {joint} is not usable'
            columns[ARMS.index(side) * 7 + index] = angle
        for gesture in result.gestures:
            if len(gesture.times) != len(self._library[gesture.name].keyframes):
                return f'{gesture.name}: wrong number of keyframes'
            for q in gesture.positions:
                if len(q) != len(self._joint_names):
                    return f'{gesture.name}: expected {len(self._joint_names)} angles'
                for k, angle in enumerate(q):
                    side, index = self._robot.locate_joint(self._joint_names[k])
                    if not (math.isfinite(angle)
                            and self._robot.within_limits(side, index, angle)):
                        return (f'{gesture.name}: angle {angle!r} of {self._joint_names[k]} '
                                f'is not finite or outside its limits')
                    if k in columns and angle != columns[k]:
                        return (f'{gesture.name}: failed joint {self._joint_names[k]} at '
                                f'{angle!r}, not at its lock angle {columns[k]!r}')
        return None

    # --- publishing and persistence ---------------------------------------------------

    def _next_stamp(self):
        now = self.get_clock().now().nanoseconds
        stamp_ns = max(now, self._last_stamp_ns + 1)
        self._last_stamp_ns = stamp_ns
        return Time(nanoseconds=stamp_ns).to_msg()

    def _publish_locked(self, result):
        """Publish a library version (caller holds self._cond)."""
        stamp = self._next_stamp()
        for msg in conv.library_to_msgs(self._joint_names, result, stamp):
            self._library_pub.publish(msg)
        self._current = result
        self._library_version += 1
        self._background(self._publish_markers, result, stamp)

    def _background(self, func, *args):
        """Run housekeeping (persistence, markers, diagnostics) off the critical path."""
        try:
            self._housekeeping.submit(self._guarded, func, *args)
        except RuntimeError:          # shutting down: the pool no longer takes work
            pass

    def _guarded(self, func, *args):
        try:
            func(*args)
        except Exception as exc:  # noqa: B902 - housekeeping must never kill the node
            if self._live():
                self.get_logger().error(f'{func.__name__}: {type(exc).__name__}: {exc}')

    def _publish_markers(self, result, stamp):
        try:
            markers = conv.library_markers(
                self._robot, self._reference, result, stamp,
                self._settings['marker_frame_id'], self._settings['marker_spacing'])
            self._marker_pub.publish(MarkerArray(markers=markers))
        except Exception as exc:  # noqa: B902 - markers are a view; never fatal
            if self._live():
                self.get_logger().warning(f'could not publish /gesture_markers: {exc}')

    def _live(self):
        """Return True unless the node is stopping or ROS was shut down (e.g. SIGTERM)."""
        return not self._stopping and self.context.ok()

    def _snapshot_locked(self, library):
        """Return what to persist now, in order (the caller holds the lock)."""
        self._persist_seq += 1
        return self._persist_seq, dict(self._faults), library

    def _persist_locked(self, library):
        """Write the fault set and ``library`` to the state file (caller holds the lock)."""
        self._write(self._snapshot_locked(library))

    def _write(self, snapshot):
        """Write a snapshot atomically; a failure is reported, never fatal."""
        seq, faults, library = snapshot
        try:
            self._store.save(faults, library, self._fingerprint, seq)
            self._persist_problem = None
        except (OSError, ValueError) as exc:
            if self._persist_problem is None:
                self.get_logger().error(f'cannot write the state file {self._store.path}: '
                                        f'{exc}; the state will not survive a restart')
            self._persist_problem = f'cannot write {self._store.path}: {exc}'

    def _restore(self):
        """Restore the persisted fault set and library; publish them at once."""
        state, problem = self._store.load()
        if state is not None:
            problem = self._validate_faults(state.faults)
            if problem:
                problem = self._store.set_aside(problem)
                state = None
        if problem:
            self._state_problem = problem
            self.get_logger().error(problem + '; starting without faults')
        if state is None or not state.faults:
            return
        library = state.library
        reason = None
        if library is None:
            reason = 'no library was saved'
        elif state.fingerprint != self._fingerprint:
            reason = 'the robot or gesture file changed since it was saved'
        elif library.faults != {j: f.angle for j, f in state.faults.items()}:
            reason = 'the saved library was computed for another fault set'
        elif library.settings.get('lock_strategy') != self._settings['lock_strategy']:
            reason = 'the lock strategy changed since it was saved'
        elif _tool(library.tool_mm, library.tool_arm) != _tool(self._settings['tool_mm'],
                                                               self._settings['tool_arm']):
            reason = 'the tool (tool_length_mm, tool_arm) changed since it was saved'
        else:
            reason = self._check_result(library, state.faults)
        with self._cond:
            self._faults = dict(state.faults)
            self._fault_version += 1
            self._requested_gen += 1
            if reason is None:
                self._handled_gen = self._requested_gen
                self._published_gen = self._requested_gen
                self._publish_locked(library)
            self._cond.notify_all()
        joints = ', '.join(state.faults)
        if reason is None:
            self.get_logger().info(f'restored faults {joints} and their library from '
                                   f'{self._store.path}')
        else:
            self.get_logger().warning(f'restored faults {joints} from {self._store.path}; '
                                      f'{reason}: reconfiguring')

    def _validate_faults(self, faults):
        for joint, fault in faults.items():
            try:
                side, index = self._robot.locate_joint(joint)
            except KeyError as exc:
                return f'fault on {exc.args[0]}'
            for value in (fault.angle, fault.measured):
                if value is not None and not self._robot.within_limits(side, index, value):
                    return f'angle {value!r} of faulted joint {joint} is outside its limits'
        return None

    # --- diagnostics ----------------------------------------------------------------

    def _publish_diagnostics(self):
        try:
            msg = DiagnosticArray()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.status = self._diagnostic_statuses()
            self._diag_pub.publish(msg)
        except Exception as exc:  # noqa: B902 - e.g. publishing during shutdown
            if self._live():
                self.get_logger().warning(f'could not publish /diagnostics: {exc}')

    def _diagnostic_statuses(self):
        with self._cond:
            faults = dict(self._faults)
            current = self._current
            pending = self._requested_gen > self._published_gen
            running = self._running_gen is not None
            failed = self._failed
            fault_version = self._fault_version
            version = self._library_version
            stamp = self._last_stamp_ns
            rejections = list(self._rejections)
            rejected_total = self._rejected_total
            states_received = self._joint_states_received
            measured_joints = sorted(self._measured)
            last_accepted = self._last_accepted
            settings = dict(self._settings)
        hw = self._robot.name
        up_to_date = current is not None and not pending and (
            set(current.locks) == set(faults))
        out = []
        if faults:
            out.append(conv.status(
                'faults', 'ERROR', f'{len(faults)} failed joint(s): {", ".join(faults)}', hw,
                [('fault_version', fault_version), ('failed_joints', ' '.join(faults)),
                 ('lock_strategy', settings['lock_strategy'])]))
        else:
            out.append(conv.status('faults', 'OK', 'no faults', hw,
                                   [('fault_version', fault_version), ('failed_joints', ''),
                                    ('lock_strategy', settings['lock_strategy'])]))
        for joint, fault in faults.items():
            side, index = self._robot.locate_joint(joint)
            if up_to_date and joint in current.locks:
                lock = current.locks[joint]
                source = ('fault report' if fault.angle is not None
                          else f'{settings["lock_strategy"]} strategy')
                text = f'failed; locked at {conv.fmt_angle(lock)} ({source})'
                pairs = [('lock_angle_rad', repr(lock)),
                         ('lock_angle_deg', f'{math.degrees(lock):.4f}'),
                         ('lock_source', source)]
            else:
                text = 'failed; lock angle pending reconfiguration'
                pairs = [('lock_angle_rad', '' if fault.angle is None else repr(fault.angle)),
                         ('lock_source', 'pending')]
            out.append(conv.status(f'joint {joint}', 'ERROR', text, joint,
                                   [('joint', joint), ('arm', side), ('index', index + 1)]
                                   + pairs))
        for side in frozen_arms(self._robot, faults):
            out.append(conv.status(
                f'arm {side}', 'ERROR',
                f'all {len(self._robot.arms[side].joint_names)} joints of the {side} arm '
                f'failed: the arm is frozen at its lock angles; the other arm is still '
                f'reconfigured', hw, [('arm', side), ('frozen', 'true')]))
        out.append(self._reconfiguration_status(current, up_to_date, running, failed,
                                                version, stamp, settings))
        last = rejections[-1] if rejections else None
        recent = last is not None and last[0] >= last_accepted
        out.append(conv.status(
            'inputs', 'WARN' if recent else 'OK',
            (f'rejected {last[1]}: {last[2]}' if recent else
             f'last rejected input: {last[1]}: {last[2]}' if last else 'no rejected input'),
            hw, [('rejected_total', rejected_total),
                 ('joint_states_received', states_received),
                 ('measured_joints', ' '.join(measured_joints))]
            + ([('last_rejected_source', last[1]), ('last_rejected_reason', last[2])]
               if last else [])
            + [(f'rejected[{i}]', f'{time.strftime("%H:%M:%S", time.localtime(t))} '
                f'{src}: {why}') for i, (t, src, why) in enumerate(reversed(rejections))]))
        problem = self._state_problem or self._persist_problem
        out.append(conv.status('state', 'WARN' if problem else 'OK',
                               problem or f'state persisted in {self._store.path}', hw,
                               [('state_file', self._store.path)]))
        return out

    def _reconfiguration_status(self, current, up_to_date, running, failed, version, stamp,
                                settings):
        hw = self._robot.name
        pairs = [('library_version', version),
                 ('library_stamp', f'{stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d}'),
                 ('up_to_date', str(up_to_date).lower()),
                 ('running', str(running).lower()), ('optimizer', settings['algorithm']),
                 ('optimizer_preset', settings['preset']),
                 ('deadline_sec', settings['deadline'])]
        if current is None:
            return conv.status('reconfiguration', 'STALE', 'no library published yet', hw,
                               pairs)
        pairs += [('wall_time_sec', f'{current.wall_time:.4f}'),
                  ('deadline_met', str(current.deadline_met).lower()),
                  ('success', str(current.success).lower()),
                  ('frozen_arms', ' '.join(current.frozen_arms)),
                  ('seed', '' if current.seed is None else current.seed),
                  ('tool_length_mm', f'{current.tool_mm:g}'), ('tool_arm', current.tool_arm)]
        for g in current.gestures:
            pairs += [(f'{g.name}.score_before', f'{g.score_before:.6g}'),
                      (f'{g.name}.score_after', f'{g.score_after:.6g}'),
                      (f'{g.name}.time_sec', f'{g.wall_time:.4f}'),
                      (f'{g.name}.status', g.status),
                      (f'{g.name}.stage', g.stage),
                      (f'{g.name}.method', g.method),
                      (f'{g.name}.typical_points', g.typical_points),
                      (f'{g.name}.tip_error_mm', f'{g.tip_error_mm:.3f}'),
                      (f'{g.name}.max_jump_deg', f'{g.max_jump_deg:.3f}')]
            if current.settings.get('collision_check'):
                pairs.append((f'{g.name}.collides', str(g.collides).lower()))
                if g.colliding_pairs:
                    pairs.append((f'{g.name}.colliding_pairs', ' '.join(g.colliding_pairs)))
        for k, note in enumerate(current.notes):
            pairs.append((f'note[{k}]', note))
        level = 'OK'
        message = conv.summary(current)
        if failed and not up_to_date:
            level, message = 'ERROR', f'last run failed: {failed[1]}; {message}'
        elif not up_to_date:
            message = f'reconfiguring; last published: {message}'
        elif not current.success or any(g.collides for g in current.gestures):
            level = 'WARN'
        return conv.status('reconfiguration', level, message, hw, pairs)

    # --- shutdown -------------------------------------------------------------------

    def stop(self):
        """Stop the worker and wake every waiting service call."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        worker = getattr(self, '_worker', None)
        if worker is not None:
            worker.join(timeout=10.0)
        housekeeping = getattr(self, '_housekeeping', None)
        if housekeeping is not None:
            housekeeping.shutdown(wait=True)


def _tool(length_mm, arm):
    """Return a comparable structure change: no tool is the same on either arm."""
    return (float(length_mm), arm) if length_mm > 0 else (0.0, None)


def engine_settings(settings):
    """Return the engine's RecoverySettings for the node's settings dict."""
    return RecoverySettings(
        deadline_sec=settings['deadline'], lock_strategy=settings['lock_strategy'],
        optimizer=settings['algorithm'], optimizer_preset=settings['preset'],
        bimanual=settings['bimanual'], collision_check=settings['collision'],
        tool_length_mm=settings['tool_mm'], tool_arm=settings['tool_arm'],
        trajectory_method=settings['method'], vq_distortion_mm=settings['distortion_mm'],
        continuity_weight=settings['continuity'], weights=settings['weights'])


_SIGINTS = []


def _on_sigint(signum, frame):
    _SIGINTS.append(signum)
    if len(_SIGINTS) > 1:
        raise KeyboardInterrupt


def _one_line(exc):
    return ' '.join(str(exc).split())


def _params_file_problem(path):
    """Return why a --params-file cannot be used, or None (rcl parses it for real)."""
    try:
        text = Path(path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        return f'cannot read parameter file {path}: {exc}'
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark is not None else ''
        return (f'parameter file {path} is not valid YAML{where}: '
                f'{getattr(exc, "problem", None) or exc}')

    def has_parameters(node):
        return isinstance(node, dict) and node and (
            isinstance(node.get('ros__parameters'), dict)
            or all(has_parameters(v) for v in node.values()))

    if not has_parameters(doc):
        return (f"parameter file {path}: expected '<node name or /**>: ros__parameters: "
                f"{{name: value}}' mappings")
    return None


def _check_params_files(argv):
    """Return the first problem with a --params-file of ``argv``, or None."""
    argv = list(argv)
    for i, token in enumerate(argv[:-1]):
        if token == '--params-file':
            problem = _params_file_problem(argv[i + 1])
            if problem:
                return problem
    return None


def main(args=None):
    """Run the node until Ctrl-C or SIGTERM; return the exit code."""
    problem = _check_params_files(sys.argv if args is None else args)
    if problem:
        sys.stderr.write(f'{NODE_NAME}: error: {_one_line(problem)}\n')
        return EXIT_CONFIG
    # rclpy's signal handler shuts ROS down (spin then ends) and chains to the Python
    # handler it finds.  Python's default raises KeyboardInterrupt at an arbitrary point
    # of the main thread, which can leave a lock or a pool thread behind and hang the
    # exit; so the first Ctrl-C only lets rclpy do its work, and a second one insists.
    signal.signal(signal.SIGINT, _on_sigint)
    try:
        rclpy.init(args=args)
    except Exception as exc:  # noqa: B902 - e.g. a malformed --params-file
        sys.stderr.write(f'{NODE_NAME}: error: cannot initialise ROS: {_one_line(exc)}\n')
        return EXIT_CONFIG
    node = None
    executor = None
    code = 0
    try:
        executor = MultiThreadedExecutor(num_threads=4)
        node = RecoveryNode()
        executor.add_node(node)
        executor.spin()
    except StartupError as exc:
        sys.stderr.write(f'{NODE_NAME}: error: {exc}\n')
        code = EXIT_CONFIG
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # noqa: B902
        if rclpy.ok():
            raise          # a genuine error: let it be seen
        # Otherwise Ctrl-C or SIGTERM shut ROS down while the node was starting.
    finally:
        if node is not None:
            node.stop()
        if executor is not None:
            executor.shutdown(timeout_sec=2.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
