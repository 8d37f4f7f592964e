"""
``RecoveryNode``: wires the ROS interfaces to the parts that do the work.

Messages come in, are validated (:mod:`.inputs`) and queued (:mod:`.fault_intake`); the
run book (:mod:`.run_book`) says which library is wanted; the dispatcher
(:mod:`.dispatcher`) runs the engine in its own process (:mod:`.engine_process`) and
publishes.  Nothing here blocks an executor thread: joint states are kept raw (parsed only
when needed), services answer from ``async`` callbacks that await the run book, and the
periodic work runs on a steady clock, independent of ``use_sim_time``.
``RecoveryNode(engine=...)`` takes an engine started early (``EngineProcess.early()``, as
``recovery_node`` does before its imports) and gives it its files; without one it starts
its own.  It stops it either way.

An idle node wakes only for what is due: ``/diagnostics`` once per
``diagnostics_period_sec`` (the heartbeat), and a 10 Hz tick only while it has work (a
joint state to parse, a change to publish); it stops itself when it finds none, and
whatever brings new work restarts it.
"""

from dataclasses import replace
import time

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rclpy.time import Time
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from . import diagnostics
from . import messages as conv
from .description_wait import wait_for_description
from .explored_intake import ExploredIntake
from .input_monitor import InputMonitor
from .parameters import (check_parameter, declare_parameters, DEFAULT_STATE_DIR, MARKER_PARAMS,
                         node_config, one_line, parameter_specs, RERUN_PARAMS, StartupError)
from .topic_listener import TopicListener
from ..errors import ConfigError, shorten
from ..recovery.result import reference_result, summary
from ..runtime import diagnostic_keys as dk
from ..runtime.answer_pacer import AnswerPacer
from ..runtime.contingency_keeper import ContingencyKeeper
from ..runtime.demand_tick import DemandTick
from ..runtime.dispatcher import Dispatcher
from ..runtime.engine_process import EngineError, EngineProcess
from ..runtime.fault_intake import After, Clear, FaultIntake, Report
from ..runtime.inputs import BadInput, parse_fault
from ..runtime.latest_worker import LatestWorker
from ..runtime.persistence import Persistence
from ..runtime.robot_source import load_models, robot_source
from ..runtime.run_book import Outcome, RunBook

NODE_NAME = 'recovery_node'
# The node's parts with threads or files, stopped in this order (after the engine).
PARTS = ('_faults', '_states', '_table', '_explored', '_state', '_answers', '_markers')
FAULT_QUEUE_DEPTH = 10_000        # reports the subscription holds while the intake catches up
STATES_PARSE_PERIOD = 0.1         # s: the latest raw joint state is parsed at most this often
STATES_TAKE_PERIOD = 0.02         # s: a /joint_states sample is taken at most this often
MARKER_DELAY = 0.05               # s: markers are drawn this long after a publication
RELIABLE = {'reliability': ReliabilityPolicy.RELIABLE, 'history': HistoryPolicy.KEEP_LAST}
LATCHED = dict(RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)     # late joiners too
LATEST = {'reliability': ReliabilityPolicy.BEST_EFFORT, 'history': HistoryPolicy.KEEP_LAST}
STATES_QOS = QoSProfile(depth=1, **LATEST)   # /joint_states: only the newest sample matters


def log_at(logger, level, text):
    """Log ``text`` at ``level`` ('error', 'warning', else info) with an rclpy logger."""
    # One call site per severity: rclpy refuses a call site whose severity changes.
    if level == 'error':
        logger.error(text)
    elif level == 'warning':
        logger.warning(text)
    else:
        logger.info(text)


def version_text(outcome):
    """Return the ``[...]`` tag of an answer: the library version and its stamp."""
    return dk.version_text(outcome.version, outcome.stamp_ns)


def reconfigure_answer(outcome):
    """Return the message of a ``reconfigure_gestures`` answer."""
    if outcome.published:
        return f'{summary(outcome.result)} [{version_text(outcome)}]'
    return outcome.reason + (f' [{version_text(outcome)}]' if outcome.version else '')


def cleared_text(gestures, tool_mm):
    """Return what ``clear_faults`` published: the reference, or the tool's library."""
    if tool_mm <= 0:
        return f'the reference library is published ({gestures} gestures)'
    return f'the library is adapted to the {tool_mm:g} mm tool alone (tool_length_mm)'


def describe_reports(reports, lock_strategy):
    """Return the accepted faults of ``reports`` as one text (each joint once, newest)."""
    joints = {}
    for report in reports:
        joints.update(report.joints)
    return ', '.join(f'{j} at {conv.fmt_angle(a)}' if a is not None else
                     f'{j} (lock angle: {lock_strategy} strategy)'
                     for j, a in joints.items())


def node_models(values, warning, wait):
    """
    Return ``(RobotSource, robot, library)`` of the node's parameters (StartupError).

    A profile that names no URDF, without ``robot_description``: ``wait(profile)``
    returns the URDF document (from the topic, :mod:`.description_wait`).
    """
    try:
        source = robot_source(values)
        if source.needs_description():
            source = robot_source(dict(values, robot_description=wait(source.profile)))
    except ValueError as exc:
        raise StartupError(f'invalid parameter {one_line(exc)}') from None
    try:
        return (source, *load_models(source, values['gesture_file'] or None, warning))
    except (ConfigError, FileNotFoundError) as exc:
        raise StartupError(f'invalid configuration: {one_line(exc)}') from None


def own_profile(robot):
    """Return the RobotProfile a robot was built from (robot_profile), else ''."""
    return getattr(robot, 'profile', None) or ''


class RecoveryNode(Node):
    """The fault-recovery node; see the module docstring and ``msg_docs/``."""

    def __init__(self, engine=None, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._ready = False
        self._last_param_reason = None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        values = declare_parameters(self, lambda: self._last_param_reason)
        self._config = node_config(values)
        self._source, self._robot, self._library = node_models(
            values, self.get_logger().warning, lambda profile: wait_for_description(
                self, profile, values['diagnostics_period_sec']))
        self._prefix = diagnostics.status_prefix(self.get_fully_qualified_name())
        self._tick = DemandTick(self._tick_work, lambda: (self._inputs.pending_state()
                                                          or self._inputs.log_pending()))
        self._inputs = InputMonitor(self._robot, self._log_rejection, self._tick.wake)
        self._last_stamp_ns = 0
        self._engine = self._start_engine(engine or EngineProcess(), values)
        self._book = RunBook(on_request=self._engine.cancel)
        self._state = Persistence(values['state_dir'] or DEFAULT_STATE_DIR, self._robot,
                                  self._library, self._book, self.get_logger().error)
        self._intake = FaultIntake(self._book, self._state.commit_faults, self._on_accepted,
                                   self._inputs.measured, on_error=self._intake_error)
        self._prepared = conv.PreparedMessages(self._robot.played_joints)
        self._table = ContingencyKeeper(self._robot, self._library, self._state.store.directory,
                                        self._log, values['contingency_file'] or None,
                                        hold=self._intake.busy, prepare=self._prepared.prepare)
        self._dispatcher = Dispatcher(self._book, self._engine, self._robot, self._library,
                                      lambda: self._config, self._publish_and_persist,
                                      self._log, self._publish_refined, self._table)
        self._markers = LatestWorker(self._publish_markers, MARKER_DELAY, name='markers',
                                     hold=self._intake.busy)
        self._explored = ExploredIntake(self, (self._robot, self._library), self._book,
                                        self._state, self._publish_library, self._log,
                                        values['profile_file'] or own_profile(self._robot),
                                        values['explored_topic'])
        try:
            self._create_interfaces()
            self._restore()
        except BaseException:
            self.stop()
            raise
        self._answers = AnswerPacer(self._wake.trigger)
        for part in (self._answers, self._markers, self._state, self._intake, self._dispatcher,
                     self._explored):
            part.start()
        if self._config.contingency_table:
            self._table.configure(self._config.settings,
                                  active={j: f.angle for j, f in self._book.faults.items()})
        self._ready = True
        where = self._source.describe() if self._source.profile else self._robot.source
        self.get_logger().info(
            f'robot {self._robot.name} ({where}), {len(self._library)} gestures '
            f'({self._library.source}); state in {self._state.store.directory}; engine process '
            f'started')

    def _start_engine(self, engine, values):
        """Give ``engine`` its files; wait until it has warmed up (a signal ends the wait)."""
        engine.load(self._source, values['gesture_file'] or None,
                    values['engine_start_timeout_sec'], values['engine_nice'])
        try:
            engine.wait_ready(timeout=values['engine_start_timeout_sec'],
                              keep_waiting=self.context.ok)
        except EngineError as exc:
            engine.stop()
            raise StartupError(f'the engine process did not start: {exc}') from None
        if engine.nice_refused:
            self.get_logger().warning(f'{engine.nice_refused}; its runs compute at its own')
        return engine

    # --- interfaces -----------------------------------------------------------------

    def _create_interfaces(self):
        self._library_pub = self.create_publisher(
            JointTrajectory, 'gesture_library', QoSProfile(depth=len(self._library), **LATCHED))
        self._marker_pub = self.create_publisher(MarkerArray, 'gesture_markers',
                                                 QoSProfile(depth=1, **LATCHED))
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._faults = TopicListener(self, JointState, 'actuator_fault', self._on_fault,
                                     QoSProfile(depth=FAULT_QUEUE_DEPTH, **RELIABLE))
        self._states = TopicListener(self, JointState, 'joint_states', self._inputs.joint_state,
                                     STATES_QOS, raw=True, period=STATES_TAKE_PERIOD)
        services = ReentrantCallbackGroup()
        service_qos = QoSProfile(depth=1000, **RELIABLE)
        self.create_service(Trigger, 'reconfigure_gestures', self._on_reconfigure,
                            qos_profile=service_qos, callback_group=services)
        self.create_service(Trigger, 'clear_faults', self._on_clear,
                            qos_profile=service_qos, callback_group=services)
        # Wakes the executor when a run completes a service call's future.
        self._wake = self.create_guard_condition(lambda: None,
                                                 callback_group=MutuallyExclusiveCallbackGroup())
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        periodic = MutuallyExclusiveCallbackGroup()
        self._diag_period = self.get_parameter('diagnostics_period_sec').value
        self.create_timer(self._diag_period, self.publish_diagnostics, callback_group=periodic,
                          clock=steady)
        self._tick.attach(self.create_timer(STATES_PARSE_PERIOD, self._tick.tick,
                                            callback_group=periodic, clock=steady),
                          self._wake.trigger)

    # --- parameters -----------------------------------------------------------------

    def _on_set_parameters(self, parameters):
        current = {name: self.get_parameter(name).value for name, _, _ in parameter_specs()
                   if self.has_parameter(name)}
        current.update({p.name: p.value for p in parameters})
        for param in parameters:
            reason = check_parameter(param.name, param.value, current)
            if reason:
                self._last_param_reason = reason
                if self._ready:
                    self._inputs.reject('parameter', reason)
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, parameters):
        if not self._ready:
            return
        names = {p.name for p in parameters}
        self._config = node_config({n: self.get_parameter(n).value
                                    for n, _, _ in parameter_specs()})
        tool = self._config.settings.tool_length_mm > 0
        rerun = bool(names & RERUN_PARAMS) and (
            bool(self._book.faults) or tool or 'tool_length_mm' in names)
        if rerun:
            self._book.request()
        elif (names & RERUN_PARAMS or 'contingency_table' in names) \
                and self._config.contingency_table:
            self._table.configure(self._config.settings)    # a new fingerprint: rebuild
        changed = ', '.join(f'{p.name}={shorten(repr(p.value))}' for p in parameters)
        self.get_logger().info(f'parameters set: {changed}'
                               + ('; reconfiguring the library' if rerun else ''))
        current = self._book.current
        if names & MARKER_PARAMS and current is not None:
            self._publish_markers(current, self.get_clock().now().to_msg())
        self._tick.change()

    # --- inputs ---------------------------------------------------------------------

    def _intake_error(self, exc):
        self.get_logger().error(f'fault intake: {type(exc).__name__}: {shorten(exc)}; '
                                f'the batch of reports was not applied')

    def _log_rejection(self, line):
        if line is not None:             # None: held back, counted in a later line
            self.get_logger().warning(line)
        self._tick.change()

    def _on_fault(self, msg):
        received = time.monotonic()
        try:
            parsed = parse_fault(self._robot, msg.name, msg.position, msg.velocity, msg.effort)
        except BadInput as exc:
            self._inputs.reject('/actuator_fault', str(exc))
            return
        if not self._intake.submit(Report(parsed, received)):
            self._inputs.reject('/actuator_fault', 'the fault queue is full; report dropped')
            return
        # Hand the interpreter lock to the intake thread now: the executor's own work
        # after a callback (its next wait set) would hold it for up to a switch interval.
        time.sleep(0)

    def _on_accepted(self, reports, cleared, faults):
        self._inputs.accepted()
        self._tick.change()
        if reports:
            described = describe_reports(reports, self._config.settings.lock_strategy)
            self.get_logger().info(f'fault accepted: {shorten(described, 400)} '
                                   f'({len(reports)} report(s)); reconfiguring the library')

    # --- services -------------------------------------------------------------------

    def _await_outcome(self, register):
        future = Future()

        def done(outcome):
            self._answers.submit(lambda: future.set_result(outcome))

        register(done)
        return future

    async def _on_reconfigure(self, request, response):
        # Ordered after every fault report already received: the answer includes them.
        outcome = await self._await_outcome(
            lambda done: self._after_intake(lambda: self._book.call(done)))
        response.success = bool(outcome.published and outcome.result.success)
        response.message = reconfigure_answer(outcome)
        self._answers.sent()        # rclpy sends the response as this returns
        return response

    async def _on_clear(self, request, response):
        counted = []

        def register(done):
            def persisted(count):
                counted.append(count)
                self._book.call(done)
            if not self._intake.submit(Clear(persisted)):
                done(Outcome(False, reason='the fault queue is full; try again'))

        outcome = await self._await_outcome(register)
        count = counted[0] if counted else 0
        done = cleared_text(len(self._library), self._config.settings.tool_length_mm)
        response.success = bool(outcome.published)
        response.message = (f'cleared {count} fault(s); {done} [{version_text(outcome)}]'
                            if outcome.published else f'cleared {count} fault(s); '
                                                      f'{outcome.reason}')
        self.get_logger().info(f'cleared {count} fault(s); {done}')
        self._answers.sent()
        return response

    def _after_intake(self, then):
        """Run ``then()`` after every queued fault report (at once if the queue is full)."""
        if not self._intake.submit(After(then)):
            then()

    # --- outputs, persistence, restore ----------------------------------------------

    def _publish_and_persist(self, generation, faults, result, in_hand=None):
        return self._state.publish_and_queue(generation, faults, result,
                                             self._publish_library, in_hand)

    def _publish_refined(self, generation, faults, result):
        return self._state.publish_refined_and_queue(generation, faults, result,
                                                     self._publish_library)

    def _publish_library(self, result):
        """Publish a library version; return its stamp (ns, strictly increasing)."""
        stamp_ns = max(self.get_clock().now().nanoseconds, self._last_stamp_ns + 1)
        self._last_stamp_ns = stamp_ns
        stamp = Time(nanoseconds=stamp_ns).to_msg()
        for msg in self._prepared.messages(result, stamp):     # a table hit's: ready
            self._library_pub.publish(msg)
        self._tick.change()
        self._markers.submit(result, stamp)        # drawn a moment later, off this path
        return stamp_ns

    def _publish_markers(self, result, stamp):
        try:
            markers = conv.library_markers(
                self._robot, reference_result(self._library), result, stamp,
                self._config.marker_frame_id, self._config.marker_spacing)
            self._marker_pub.publish(MarkerArray(markers=markers))
        except Exception as exc:  # noqa: B902 - markers are a view; never fatal
            if self._live():
                self.get_logger().warning(f'could not publish /gesture_markers: {exc}')

    def _restore(self):
        """Publish the reference, then restore the persisted state (see :func:`restore`)."""
        reference = reference_result(self._library)
        self._book.mark_published_without_run(reference, self._publish_library(reference))
        restore(self, self._state.plan_restart(self._config.settings))

    # --- periodic work and diagnostics ---------------------------------------------

    def _tick_work(self):
        """Steady 10 Hz while needed: parse the latest joint state, publish a change."""
        if self._inputs.pending_state():
            self._inputs.measured()
        self._inputs.flush_log()         # the rejections held back after a flood
        if self._tick.take_change():
            self.publish_diagnostics()

    def publish_diagnostics(self):
        """Publish /diagnostics from a snapshot of the state (the heartbeat, and changes)."""
        snap = diagnostics.snapshot(self._book, self._inputs, self._config.settings,
                                    self._state.problem, self._state.store.path,
                                    self._engine.restarts, diagnostics.table_state(
                                        self._config.contingency_table, self._table))
        try:
            msg = DiagnosticArray()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.status = diagnostics.statuses(self._robot, snap, self._prefix)
            self._diag_pub.publish(msg)
        except Exception as exc:  # noqa: B902 - e.g. publishing during shutdown
            if self._live():
                self.get_logger().warning(f'could not publish /diagnostics: {exc}')

    def _log(self, level, text):
        if self._live():
            log_at(self.get_logger(), level, text)

    def _live(self):
        """Return True unless ROS was shut down (e.g. SIGTERM)."""
        return not self._book.stopping and self.context.ok()

    def stop(self):
        """Stop the threads and the engine process; tell every waiting caller."""
        self._book.stop()
        self._engine.cancel()
        self._intake.stop()
        self._dispatcher.join()
        self._engine.stop()
        for name in PARTS:   # those built so far
            part = getattr(self, name, None)
            if part is not None:
                part.stop()


def restore(node, plan):
    """
    Restore a RecoveryNode's persisted state: corrections, fault set and library.

    Measured corrections are compiled again (a profile that no longer fits is logged
    and they are dropped); the saved library is republished if it is still the one
    for that state, else a run is requested.
    """
    logger, book = node.get_logger(), node._book
    if plan.problem:
        logger.error(f'{node._state.problem}; starting without faults')
    if plan.corrections:
        try:
            book.set_learned(node._explored.learned(plan.corrections))
            node._state.corrections = plan.corrections
        except ValueError as exc:
            logger.error(f'measured corrections not restored: {exc}')
            plan = replace(plan, library=None)
    if not plan.faults:
        if plan.library is not None and book.learned:
            book.mark_published_without_run(plan.library, node._publish_library(plan.library))
            logger.info(plan.message)
        elif book.learned or node._config.settings.tool_length_mm > 0:
            book.request()      # a tool from the start, or a measured arm: a structure change
            if book.learned:
                logger.warning(plan.message)
        return
    book.set_faults(plan.faults, request=plan.library is None)
    if plan.library is not None:
        book.mark_published_without_run(plan.library, node._publish_library(plan.library))
    log = logger.info if plan.library is not None else logger.warning
    log(plan.message)
