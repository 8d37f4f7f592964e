"""
A typed rclpy client of one running ``recovery_node``: what every ROS command uses.

:class:`RecoveryClient` is to ``recovery_node`` what nav2_simple_commander's
BasicNavigator is to Nav2: plain method calls (``publish_fault``, ``reconfigure``,
``clear_faults``, ``current_library``, ``next_library``) that hide topics, QoS and
futures.  It runs an rclpy node in its own Context, spun in a background thread, so it
can live beside other rclpy users in one process (the tests) and be closed cleanly.

The node uses relative names; the client resolves them in its ``namespace``, so a node
started with ``--ros-args -r __ns:=/robot1`` is reached with ``namespace='/robot1'``.
``/diagnostics`` is global: the client keeps only the statuses whose names carry the
prefix of the node in its namespace (:func:`.diagnostic_keys.status_prefix`).  The
domain is ``domain_id``, else ``ROS_DOMAIN_ID``, else 0.

Libraries come back as :class:`PublishedLibrary`: the header stamp, the joint order and
a :class:`~namo_fault_recovery.recovery.result.LibraryResult` rebuilt from the
``/gesture_library`` messages and the ``/diagnostics`` values of that very version
(matched by ``library_stamp``), so a caller reads scores and locks from the same result
type the engine returns.
"""

from collections import deque
from dataclasses import dataclass
import itertools
import math
import os
import threading
import time

from .messages import duration_seconds, stamp_key
from .spun_node import call_service, SpunClient, SpunNode, wait_on, wait_until
from .topic_listener import TopicListener
from ..recovery.result import GestureResult, LibraryResult
from ..runtime import diagnostic_keys as keys

# The node's names, relative: resolved in the client's namespace.
LIBRARY_TOPIC = 'gesture_library'
FAULT_TOPIC = 'actuator_fault'
RECONFIGURE_SERVICE = 'reconfigure_gestures'
CLEAR_SERVICE = 'clear_faults'
DIAGNOSTICS_TOPIC = '/diagnostics'
SETTLE_SEC = 0.3          # quiet time after which a late-joiner's library may be complete
DECLARATION_SEC = 1.5     # how long a version waits for the diagnostics that list it
DIAGNOSTICS_SEC = 3.0     # how long to wait for the /diagnostics of a library version
_MAX_DIAGNOSTICS = 200
_COUNTER = itertools.count()


class ClientError(Exception):
    """A failure of a call to the node, explained on one line."""


class NodeUnreachable(ClientError):
    """No ``recovery_node`` answered in the client's namespace and domain."""


class BadNamespace(ClientError, ValueError):
    """The namespace is not a valid ROS namespace."""


@dataclass(frozen=True)
class TriggerAnswer:
    """The answer of /reconfigure_gestures or /clear_faults."""

    success: bool
    message: str
    library_version: int = None     # from the '[library version N, stamp S]' tag
    library_stamp: int = None       # ns; None when the answer carries no tag

    @classmethod
    def from_response(cls, response):
        """Build from a std_srvs/Trigger response."""
        version, stamp = keys.parse_version_tag(response.message)
        return cls(bool(response.success), response.message, version, stamp)


@dataclass(frozen=True)
class NodeDiagnostics:
    """One /diagnostics message of the node: its statuses by name, without the prefix."""

    arrival: float          # time.monotonic() of reception
    values: dict            # status name -> {key: value}
    messages: dict          # status name -> message

    def get(self, status, key, default=None):
        """Return one value, or ``default`` if the status or key is missing."""
        return self.values.get(status, {}).get(key, default)

    def describes(self, stamp):
        """Return True if these statuses describe the up-to-date library ``stamp``."""
        return (self.get(keys.RECONFIGURATION, keys.LIBRARY_STAMP) == keys.format_stamp(stamp)
                and self.get(keys.RECONFIGURATION, keys.UP_TO_DATE) == keys.TRUE)

    def rejected_total(self):
        """Return how many inputs the node rejected so far, or None if unknown."""
        try:
            return int(self.get(keys.INPUTS, keys.REJECTED_TOTAL))
        except (TypeError, ValueError):
            return None


@dataclass(frozen=True)
class PublishedLibrary:
    """One complete library version received on gesture_library."""

    stamp: int               # header stamp, ns: the version key
    joint_names: tuple       # column order of every GestureResult.positions (the arms')
    result: LibraryResult
    received: float          # time.monotonic() when its last gesture arrived
    described: bool          # False: no /diagnostics of it, scores NaN, locks unknown
    library_version: int = None
    # the middleware's reception time of its last gesture (system clock, ns), before the
    # client's executor took it; None if the messages came without their info
    delivered_ns: int = None

    @property
    def names(self):
        """Gesture names in publication order."""
        return self.result.names


@dataclass(frozen=True)
class FaultOutcome:
    """What followed a fault report: a new library, or the node's rejection."""

    library: PublishedLibrary = None
    rejected: str = None     # the node's reason, when it rejected the report
    elapsed: float = 0.0     # seconds from publication to the library (or rejection)


def node_diagnostics(array, prefix, arrival):
    """Return the statuses of one DiagnosticArray named with ``prefix``, or None."""
    n = len(prefix)
    mine = [s for s in array.status if s.name.startswith(prefix)]
    if not mine:
        return None
    return NodeDiagnostics(arrival, {s.name[n:]: {kv.key: kv.value for kv in s.values}
                                     for s in mine},
                           {s.name[n:]: s.message for s in mine})


def normalise_namespace(namespace):
    """Return ``namespace`` as an absolute ROS namespace ('' and None are the root)."""
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace
    text = '/' + (namespace or '').strip().strip('/')
    try:
        validate_namespace(text)
    except InvalidNamespaceException as exc:
        reason = str(exc).splitlines()[0].rstrip(':').replace('Invalid namespace: ', '')
        raise BadNamespace(f'invalid namespace {namespace!r}: {reason}') from None
    return text


def _number(values, key):
    try:
        return float(values[key])
    except (KeyError, TypeError, ValueError):
        return math.nan


def _count(value, width):
    """Return a described column count from 0 to ``width``; 0 (not known) otherwise."""
    try:
        count = int(value)
    except (TypeError, ValueError):
        return 0
    return count if 0 <= count <= width else 0


def _gesture(name, msg, values):
    """
    Return one GestureResult from its trajectory and the 'reconfiguration' values.

    The trailing columns the values name ``shared_joints`` (a torso) become the
    gesture's ``shared`` angles (their first point's; empty if upright), the others
    its positions.
    """
    def field(key, default=None):
        return values.get(keys.gesture_key(name, key), default)
    times = tuple(duration_seconds(p.time_from_start) for p in msg.points)
    arms = _arm_columns(msg, values)
    positions = tuple(tuple(float(a) for a in p.positions[:arms]) for p in msg.points)
    lean = {n: float(a) for n, a in zip(msg.joint_names[arms:], msg.points[0].positions[arms:])
            } if msg.points else {}
    pairs = field(keys.COLLIDING_PAIRS, '')
    return GestureResult(
        name=name, times=times, positions=positions,
        score_before=_number(values, keys.gesture_key(name, keys.SCORE_BEFORE)),
        score_after=_number(values, keys.gesture_key(name, keys.SCORE_AFTER)),
        wall_time=_number(values, keys.gesture_key(name, keys.TIME_SEC)),
        status=field(keys.STATUS, 'unknown'),
        collides=field(keys.COLLIDES) == keys.TRUE,
        stage=int(field(keys.STAGE, 1)),
        colliding_pairs=tuple(pairs.split()),
        method=field(keys.METHOD, 'keyframes'),
        typical_points=int(field(keys.TYPICAL_POINTS, 0)),
        tip_error_mm=_number(values, keys.gesture_key(name, keys.TIP_ERROR_MM)),
        max_jump_deg=_number(values, keys.gesture_key(name, keys.MAX_JUMP_DEG)),
        right_joints=_count(field(keys.RIGHT_JOINTS, 0), len(positions[0]) if positions else 0),
        shared=lean if any(lean.values()) else {})


def _arm_columns(msg, values):
    """Return how many leading columns of a gesture's trajectory are the arms'."""
    shared = set(values.get(keys.SHARED_JOINTS, '').split())
    names = list(msg.joint_names)
    while names and names[-1] in shared:
        names.pop()
    return len(names)


def rebuild_library(stamp, msgs, diagnostics, received, delivered_ns=None):
    """
    Return a PublishedLibrary from one version's messages and its /diagnostics.

    ``msgs`` maps gesture names to JointTrajectory messages (publication order);
    ``diagnostics`` is the NodeDiagnostics that describes this version, or None.
    """
    values = diagnostics.values.get(keys.RECONFIGURATION, {}) if diagnostics else {}
    gestures = tuple(_gesture(name, msg, values) for name, msg in msgs.items())
    faults, locks = {}, {}
    for name, joint_values in (diagnostics.values.items() if diagnostics else ()):
        if not name.startswith(keys.JOINT_STATUS):
            continue
        joint = joint_values.get(keys.JOINT, name[len(keys.JOINT_STATUS):])
        lock = _number(joint_values, keys.LOCK_ANGLE_RAD)
        if math.isfinite(lock):
            locks[joint] = lock
        reported = joint_values.get(keys.LOCK_SOURCE) == keys.LOCK_SOURCE_REPORT
        faults[joint] = lock if reported and math.isfinite(lock) else None
    settings = {k: values[k] for k in (keys.OPTIMIZER, keys.OPTIMIZER_PRESET, keys.SEED)
                if k in values}
    result = LibraryResult(
        gestures=gestures, faults=faults, locks=locks,
        frozen_arms=tuple(values.get(keys.FROZEN_ARMS, '').split()),
        wall_time=_number(values, keys.WALL_TIME_SEC),
        deadline=_number(values, keys.DEADLINE_SEC),
        deadline_met=values.get(keys.DEADLINE_MET, keys.TRUE) == keys.TRUE,
        success=values.get(keys.SUCCESS, keys.TRUE) == keys.TRUE,
        settings=settings,
        tool_mm=_number(values, keys.TOOL_LENGTH_MM) if keys.TOOL_LENGTH_MM in values else 0.0,
        tool_arm=values.get(keys.TOOL_ARM, 'right'),
        origin=values.get(keys.LIBRARY_ORIGIN, 'deadline'),
        refined_after=(_number(values, keys.REFINED_AFTER_SEC)
                       if keys.REFINED_AFTER_SEC in values else None))
    first = next(iter(msgs.values()))
    version = values.get(keys.LIBRARY_VERSION)
    arms = _arm_columns(first, values)
    return PublishedLibrary(stamp=stamp, joint_names=tuple(first.joint_names[:arms]),
                            result=result,
                            received=received, described=diagnostics is not None,
                            library_version=int(version) if version else None,
                            delivered_ns=delivered_ns)


class Inbox:
    """
    What a client received: library versions and its node's diagnostics.

    Thread-safe and free of rclpy (the subscriptions' callbacks feed it; the tests can
    too).  Every ``wait``-style predicate is called under the lock.  ``on_library``, if
    given, is called with ``(stamp, msg)`` after each library message is stored (outside
    the lock): the test harness keeps its own view of the versions that way.
    """

    def __init__(self, prefix, on_library=None):
        self.prefix = prefix
        self._on_library = on_library
        self._cond = threading.Condition()
        self._versions = {}       # stamp ns -> {gesture: JointTrajectory}
        self._arrivals = {}       # stamp ns -> monotonic time of its latest message
        self._firsts = {}         # stamp ns -> monotonic time of its first message
        self._delivered = {}      # stamp ns -> the middleware's latest reception time, ns
        self._last_arrival = None
        self._gesture_count = None
        self._diagnostics = deque(maxlen=_MAX_DIAGNOSTICS)

    def add_library(self, msg):
        """Take one gesture_library message (a gesture of the version its stamp names)."""
        key = stamp_key(msg.header.stamp)
        with self._cond:
            version = self._versions.setdefault(key, {})
            version[msg.header.frame_id] = msg
            self._last_arrival = self._arrivals[key] = time.monotonic()
            self._firsts.setdefault(key, self._last_arrival)
            # Waiters want complete versions (a settled one is polled): wake them once,
            # not once per gesture, while the executor thread still takes the others.
            if self.complete(key):
                self._cond.notify_all()
        if self._on_library is not None:
            self._on_library(key, msg)

    def add_delivered(self, msg, info):
        """
        Take a gesture_library message with its MessageInfo (the subscription's callback).

        Keeps the middleware's ``received_timestamp`` too: when the message reached this
        process, before the executor took it (the client's own delay is not the node's).
        """
        received = info.get('received_timestamp') if isinstance(info, dict) else None
        if received:
            key = stamp_key(msg.header.stamp)
            with self._cond:
                self._delivered[key] = max(self._delivered.get(key, 0), int(received))
        self.add_library(msg)

    def add_diagnostics(self, array):
        """Take one DiagnosticArray; keep it if it holds statuses of our node."""
        entry = node_diagnostics(array, self.prefix, time.monotonic())
        if entry is not None:
            with self._cond:
                self._diagnostics.append(entry)
                self._cond.notify_all()

    def wait(self, predicate, timeout):
        """Return ``predicate()`` (called under the lock) once truthy, or None at timeout."""
        return wait_on(self._cond, predicate, timeout)

    def declared(self, stamp):
        """
        Return the gesture names the node's diagnostics list for version ``stamp``, or None.

        The node's ``reconfiguration`` status names every gesture of the version it
        published (key ``gestures``): that, not a quiet time, says when a version is
        whole.  Reliable DDS may repair a lost fragment of a large message seconds after
        the rest arrived.  Called under the lock.
        """
        text = keys.format_stamp(stamp)
        for entry in reversed(self._diagnostics):
            if entry.get(keys.RECONFIGURATION, keys.LIBRARY_STAMP) == text:
                names = entry.get(keys.RECONFIGURATION, keys.GESTURES)
                if names is not None:
                    return tuple(names.split())
        return None

    def complete(self, stamp):
        """
        Return True if version ``stamp`` holds all its gestures (called under the lock).

        All that its diagnostics list (:meth:`declared`); without them, as many as the
        first settled version held.
        """
        names = self.declared(stamp)
        if names is not None:
            return set(names) <= set(self._versions[stamp])
        return len(self._versions[stamp]) >= (self._gesture_count or 1)

    def settled(self, quiet=SETTLE_SEC, declaration=DECLARATION_SEC):
        """
        Return a predicate: ``(stamp,)`` of the newest version once it is whole.

        Transient local hands a late subscriber the whole current version.  It is whole
        once every gesture its diagnostics list arrived (:meth:`declared`).  From a node
        that lists none (an older node, a test double), it is taken as whole after
        ``quiet`` s with nothing arriving and ``declaration`` s after its first gesture.
        Its size becomes the size every later version must reach (see :meth:`newer`).
        """
        def find():
            if not self._versions:
                return None
            stamp = max(self._versions)
            names = self.declared(stamp)
            if names is not None:
                if not set(names) <= set(self._versions[stamp]):
                    return None
            else:
                now = time.monotonic()
                if (now - self._last_arrival < quiet
                        or now - self._firsts[stamp] < declaration):
                    return None
            self._gesture_count = max(self._gesture_count or 0, len(self._versions[stamp]))
            return stamp,
        return find

    def newer(self, after):
        """Return a predicate: ``(stamp,)`` of the first complete version after ``after``."""
        def find():
            for stamp in sorted(self._versions):
                if stamp > after and self.complete(stamp):
                    return stamp,
            return None
        return find

    def version_count(self):
        """Return how many library versions (distinct stamps) were received so far."""
        with self._cond:
            return len(self._versions)

    def newest_stamp(self):
        """Return the stamp of the newest version received so far (complete or not), or 0."""
        with self._cond:
            return max(self._versions, default=0)

    def rejection(self, since, rejected_before):
        """Return a predicate: diagnostics after ``since`` counting a new rejected input."""
        def find():
            if rejected_before is None:
                return None
            for entry in reversed(self._diagnostics):
                if entry.arrival < since:
                    return None
                total = entry.rejected_total()
                if total is not None and total > rejected_before:
                    return entry
            return None
        return find

    def latest_diagnostics(self, predicate=None, since=None, timeout=0.0):
        """
        Return the newest NodeDiagnostics (received after ``since``) matching predicate.

        Waits up to ``timeout`` seconds; returns None if none arrives.
        """
        def find():
            for entry in reversed(self._diagnostics):
                if since is not None and entry.arrival < since:
                    return None
                if predicate is None or predicate(entry):
                    return entry
            return None
        return self.wait(find, timeout)

    def library(self, stamp: int, diagnostics_timeout: float) -> PublishedLibrary:
        """Return version ``stamp`` as a PublishedLibrary, described if diagnostics come."""
        diagnostics = self.latest_diagnostics(lambda d: d.describes(stamp),
                                              timeout=diagnostics_timeout)
        with self._cond:
            msgs = dict(self._versions[stamp])
            received = self._arrivals[stamp]
            delivered = self._delivered.get(stamp)
        return rebuild_library(stamp, msgs, diagnostics, received, delivered)


class RecoveryClient(SpunClient):
    """A client of the ``recovery_node`` in ``namespace``, in its own rclpy Context."""

    def __init__(self, namespace: str = '/', domain_id: int = None,
                 node_name: str = keys.NODE_NAME, on_library=None, client_name: str = None):
        """
        Connect to the node ``node_name`` in ``namespace`` and ``domain_id``.

        ``on_library(stamp, msg)`` is called for every gesture_library message (see
        :class:`Inbox`): the client's one subscription serves every reader.
        ``client_name`` names the client's own rclpy node (default: unique per client).
        """
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        self.namespace = normalise_namespace(namespace)
        self.node_fqn = keys.node_fqn(self.namespace, node_name)
        self.inbox = Inbox(keys.status_prefix(self.node_fqn), on_library)
        self.domain_id = domain_id
        self._joint_state = JointState
        client_name = client_name or f'namo_recovery_client_{os.getpid()}_{next(_COUNTER)}'
        self._spun = SpunNode(client_name, domain_id, self.namespace)
        self.context, self.node = self._spun.context, self._spun.node
        latched = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._library_listener = TopicListener(self.node, JointTrajectory, LIBRARY_TOPIC,
                                               self.inbox.add_delivered, latched, info=True)
        self.node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC,
                                      self.inbox.add_diagnostics, 50)
        self._fault_pub = self.node.create_publisher(JointState, FAULT_TOPIC, 10)
        self._service_clients = {}             # service name -> rclpy client, kept
        self._spun.start()

    # --- life cycle and names ---------------------------------------------------------

    def close(self) -> None:
        """Stop the library's listener, then spinning, and shut the context down."""
        self._library_listener.stop()
        super().close()

    @property
    def fault_topic(self) -> str:
        """Return the resolved name of the fault topic, e.g. '/robot1/actuator_fault'."""
        return self._fault_pub.topic_name

    @property
    def library_topic(self) -> str:
        """Return the resolved name of the library topic."""
        return self._library_listener.topic

    def resolve_service(self, name: str) -> str:
        """Return a service name resolved in the client's namespace."""
        return self.node.resolve_service_name(name)

    def where(self) -> str:
        """Return 'namespace N, ROS_DOMAIN_ID=D' for messages."""
        domain = self.domain_id
        if domain is None:
            domain = os.environ.get('ROS_DOMAIN_ID', '0')
        return f'namespace {self.namespace}, ROS_DOMAIN_ID={domain}'

    # --- reading ------------------------------------------------------------------------

    def latest_diagnostics(self, predicate=None, since: float = None,
                           timeout: float = 0.0) -> NodeDiagnostics:
        """Return the newest diagnostics of the node matching ``predicate`` (or None)."""
        return self.inbox.latest_diagnostics(predicate, since, timeout)

    def current_library(self, timeout: float,
                        diagnostics_timeout: float = DIAGNOSTICS_SEC) -> PublishedLibrary:
        """
        Return the library the node publishes now, as a PublishedLibrary.

        Raises NodeUnreachable when nothing arrives within ``timeout``.  The library is
        described (scores, locks) if its diagnostics come within ``diagnostics_timeout``.
        """
        found = self.inbox.wait(self.inbox.settled(), timeout)
        if found is None:
            raise NodeUnreachable(
                f'no recovery_node found: nothing received on {self.library_topic} '
                f'within {timeout:g} s ({self.where()}); is the node running?')
        return self.inbox.library(found[0], diagnostics_timeout)

    def next_library(self, after: int, timeout: float,
                     diagnostics_timeout: float = DIAGNOSTICS_SEC) -> PublishedLibrary:
        """
        Return the first complete version newer than stamp ``after``, or None.

        Complete means every gesture its diagnostics list, or else as many gestures as
        the library current_library() saw, so call that first.
        """
        found = self.inbox.wait(self.inbox.newer(after), timeout)
        return None if found is None else self.inbox.library(found[0], diagnostics_timeout)

    def newest_library(self, diagnostics_timeout: float = 0.0) -> PublishedLibrary:
        """Return the newest version received so far (complete or not), or None."""
        stamp = self.inbox.newest_stamp()
        return self.inbox.library(stamp, diagnostics_timeout) if stamp else None

    # --- acting -------------------------------------------------------------------------

    def publish_fault(self, joints, angles=None, timeout: float = 5.0) -> None:
        """
        Publish one fault report (``angles`` in rad, one per joint, or None).

        Waits until the node's subscription is matched, so the report is not lost;
        raises NodeUnreachable if it is not within ``timeout``.
        """
        end = time.monotonic() + timeout
        while self._fault_pub.get_subscription_count() < 1:
            if time.monotonic() > end:
                raise NodeUnreachable(f'nobody subscribes to {self.fault_topic} '
                                      f'({self.where()}); is the node running?')
            time.sleep(0.02)
        msg = self._joint_state(name=list(joints), position=[float(a) for a in angles or ()])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self._fault_pub.publish(msg)

    def report_fault(self, joints, angles=None, timeout: float = 15.0,
                     diagnostics_timeout: float = DIAGNOSTICS_SEC) -> FaultOutcome:
        """
        Publish a fault and wait for its outcome: a new library or the node's rejection.

        Raises NodeUnreachable if the node is not there, ClientError if neither a library
        nor a rejection follows within ``timeout``.
        """
        self.current_library(timeout, diagnostics_timeout=0.0)
        baseline = self.latest_diagnostics(timeout=1.5)
        stamp = self.inbox.newest_stamp()
        t0 = time.monotonic()
        end = t0 + timeout
        self.publish_fault(joints, angles, timeout)
        rejection = self.inbox.rejection(t0, baseline and baseline.rejected_total())
        while True:
            newer = self.inbox.newer(stamp)
            found = self.inbox.wait(lambda: newer() or rejection(), end - time.monotonic())
            if found is None:
                raise ClientError(f'no new library within {timeout:g} s of the fault report')
            if isinstance(found, NodeDiagnostics):
                reason = found.get(keys.INPUTS, keys.LAST_REJECTED_REASON, '?')
                return FaultOutcome(rejected=reason, elapsed=found.arrival - t0)
            library = self.inbox.library(found[0], diagnostics_timeout)
            # A version already on its way (e.g. an earlier run) is not this fault's.
            if not library.described or set(joints) <= set(library.result.locks):
                return FaultOutcome(library=library, elapsed=library.received - t0)
            stamp = library.stamp

    def _trigger(self, service, timeout):
        from std_srvs.srv import Trigger
        # One service client per service, kept: a call then costs one round trip, not a
        # discovery of the service each time.
        client = self._service_clients.get(service)
        if client is None:
            client = self._service_clients[service] = self.node.create_client(Trigger,
                                                                              service)
        if not client.wait_for_service(timeout_sec=timeout):
            raise NodeUnreachable(
                f'no recovery_node found: service {client.service_name} is not available '
                f'within {timeout:g} s ({self.where()}); is the node running?')
        response = call_service(client, Trigger.Request(), timeout)
        if response is None:
            raise ClientError(f'no answer from {client.service_name} within {timeout:g} s')
        return TriggerAnswer.from_response(response)

    def reconfigure(self, timeout: float = 15.0) -> TriggerAnswer:
        """Call reconfigure_gestures (what the gesture player does); return the answer."""
        return self._trigger(RECONFIGURE_SERVICE, timeout)

    def clear_faults(self, timeout: float = 15.0) -> TriggerAnswer:
        """Call clear_faults; return the answer."""
        return self._trigger(CLEAR_SERVICE, timeout)

    def crowd_call(self, clients: int, calls: int = 1, timeout: float = 30.0,
                   service: str = RECONFIGURE_SERVICE, answered_once: bool = False) -> list:
        """
        Call ``service`` from ``clients`` new clients, ``calls`` each, all at once.

        What a crowd of callers does: each client has rclpy's default service QoS (depth
        10, as ``ros2 service call``), and all of them share this client's executor.
        ``answered_once``: each client first makes one call and waits for its answer, so
        that the node has discovered it (a new client's first calls wait in its request
        writer, of that depth, until the node matched it).  Returns, per call in order,
        the seconds from the sending of the first call to its answer, or None if none
        came within ``timeout`` s.  The clients are destroyed.
        """
        from std_srvs.srv import Trigger
        made = [self.node.create_client(Trigger, service) for _ in range(clients)]
        try:
            for client in made:
                if not client.wait_for_service(timeout_sec=timeout):
                    raise NodeUnreachable(f'service {client.service_name} is not available '
                                          f'within {timeout:g} s ({self.where()})')
                if answered_once and call_service(client, Trigger.Request(), timeout) is None:
                    raise ClientError(f'no answer from {client.service_name} within '
                                      f'{timeout:g} s')
            answered = {}
            lock = threading.Lock()

            def note(index):
                with lock:
                    answered[index] = time.monotonic()
            futures = []
            start = time.monotonic()
            for client in made:
                for _ in range(calls):
                    futures.append(client.call_async(Trigger.Request()))
                    futures[-1].add_done_callback(lambda _, i=len(futures) - 1: note(i))
            wait_until(lambda: len(answered) == len(futures), timeout, period=0.005,
                       lock=lock)
            with lock:
                return [answered[i] - start if i in answered else None
                        for i in range(len(futures))]
        finally:
            for client in made:
                self.node.destroy_client(client)
