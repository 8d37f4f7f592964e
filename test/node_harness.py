"""
Drive the real ``recovery_node`` process over DDS from the tests.

Every test module gets its own ROS domain (the test session's slot, reserved host-wide
with a lock file, and a per-module offset) so parallel sessions and modules never see
each other; the node subprocess and the rclpy client of the test share it.
"""

import atexit
import json
import math
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.ros.client import RecoveryClient
from namo_fault_recovery.ros.spun_node import call_service, SpunNode, wait_on
from namo_fault_recovery.runtime.private_node import node_command, stop_process
from rcl_interfaces.srv import GetParameters, SetParameters, SetParametersAtomically
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

ROOT = Path(__file__).resolve().parent.parent
NODE_PREFIX = 'recovery_node: '
TIMEOUT = 20.0
NODE = '/recovery_node'
# rcl writes a log file per process: keep the tests' out of ~/.ros/log (and tidy up).
if 'ROS_LOG_DIR' not in os.environ:
    os.environ['ROS_LOG_DIR'] = tempfile.mkdtemp(prefix='namo_test_roslog_')
    atexit.register(shutil.rmtree, os.environ['ROS_LOG_DIR'], ignore_errors=True)


SLOTS = 20                     # test sessions that can run at once on one host
_SLOT_DIR = Path(tempfile.gettempdir()) / 'namo_test_domains'
_slot = []                     # [slot number, its open lock file], once reserved


def session_slot():
    """
    Return this session's slot (0..SLOTS-1): held, host-wide, until the process ends.

    Two test sessions on one host (a CI runner, a developer's two terminals) must never
    share a ROS domain: their nodes would answer each other's clients.  A pid-derived
    guess collides one time in SLOTS; an exclusive ``flock`` on a slot file cannot.  The
    search starts at ``pid % SLOTS`` and takes the first free slot (all taken: the first
    guess, as before).
    """
    if not _slot:
        import fcntl
        _SLOT_DIR.mkdir(exist_ok=True)
        first = os.getpid() % SLOTS
        for k in range(SLOTS):
            slot = (first + k) % SLOTS
            handle = open(_SLOT_DIR / f'slot{slot}.lock', 'w')
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                handle.close()
                continue
            _slot.extend((slot, handle))
            break
        else:
            _slot.extend((first, None))
    return _slot[0]


def session_domain(offset):
    """Return this test session's ROS domain id for a module (offset 0..4)."""
    base = int(os.environ.get('NAMO_TEST_DOMAIN_BASE', 1 + session_slot() * 5))
    return base + offset


def stress_domain(index):
    """
    Return a ROS domain id (index 0..4) for one stress test, apart from the modules' ones.

    The stress tests start a node per test and flood it; a range of their own (102 and
    up, still below the ids whose ports reach past the ephemeral range) keeps that
    traffic away from the other modules of this and of parallel sessions.
    """
    base = int(os.environ.get('NAMO_TEST_STRESS_DOMAIN_BASE', 102 + session_slot() * 5))
    return base + index


def explore_domain():
    """
    Return a ROS domain id for the exploration test module, apart from all the others.

    202 and up (to 221, below ROS 2's highest usable id, 232): no other module and no
    stress test uses them, whatever the session's slot (:func:`session_slot`).
    """
    return int(os.environ.get('NAMO_TEST_EXPLORE_DOMAIN', 202 + session_slot()))


def proc_status_kb(pid, field='VmRSS'):
    """Return one ``kB`` figure of /proc/<pid>/status (e.g. VmRSS, VmHWM)."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith(field + ':'):
            return int(line.split()[1])
    raise KeyError(f'{field} not in /proc/{pid}/status')


def ros_env(domain, extra=None):
    """Return an environment for a ROS process in ``domain`` (localhost discovery)."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    env['PYTHONUNBUFFERED'] = '1'
    env.update(extra or {})
    return env


class NodeProcess:
    """The node as a subprocess, with its output captured to files."""

    def __init__(self, domain, state_dir=None, args=(), command=None, env=None):
        self.domain = domain
        self.state_dir = state_dir
        self._logdir = tempfile.mkdtemp(prefix='namo_node_log_')
        self._out = open(os.path.join(self._logdir, 'out'), 'w+b')
        self._err = open(os.path.join(self._logdir, 'err'), 'w+b')
        ros_args = list(args)
        if state_dir is not None:
            ros_args += ['-p', f'state_dir:={state_dir}']
        cmd = list(command or node_command())
        if ros_args:
            cmd += ['--ros-args'] + ros_args
        self.proc = subprocess.Popen(cmd, stdout=self._out, stderr=self._err,
                                     env=env or ros_env(domain))

    def _read(self, index):
        stream = (self._out, self._err)[index]
        if stream.closed:
            return self._text[index]
        stream.flush()
        return Path(stream.name).read_text(errors='replace')

    @property
    def stdout(self):
        """Return everything the node wrote on stdout so far."""
        return self._read(0)

    @property
    def stderr(self):
        """Return everything the node wrote on stderr so far."""
        return self._read(1)

    def tail(self, lines):
        """Return the last ``lines`` lines of the node's output (stdout, then stderr)."""
        return (self.stdout + self.stderr).splitlines()[-lines:]

    def alive(self):
        """Return True while the process runs."""
        return self.proc.poll() is None

    def send(self, sig):
        """Send a signal to the process."""
        self.proc.send_signal(sig)

    def wait(self, timeout=TIMEOUT):
        """Wait for the process to exit; return its exit code."""
        return self.proc.wait(timeout=timeout)

    def describe(self):
        """Return the exit code and output, for assertion messages."""
        return (f'exit code {self.proc.returncode}\n--- stdout\n{self.stdout}'
                f'\n--- stderr\n{self.stderr}')

    def wait_output(self, text, timeout=TIMEOUT, poll=0.0005):
        """
        Return as soon as ``text`` appears in the node's stdout or stderr.

        Reads only what was appended since the last poll, so the caller can act (e.g.
        SIGKILL) within about a millisecond of the node writing the line.  Raises
        AssertionError (with the output) on timeout or if the node exits first.
        """
        end = time.monotonic() + timeout
        tails = {}
        with open(self._out.name, 'rb') as out, open(self._err.name, 'rb') as err:
            while True:
                for stream in (out, err):
                    chunk = stream.read()
                    if chunk:
                        tail = tails.get(stream.name, b'') + chunk
                        if text.encode() in tail:
                            return
                        tails[stream.name] = tail[-len(text) - 4096:]
                if not self.alive():
                    raise AssertionError(f'the node exited before writing {text!r}\n'
                                         + self.describe())
                if time.monotonic() > end:
                    raise AssertionError(f'the node did not write {text!r} within '
                                         f'{timeout:.0f} s\n' + self.describe())
                time.sleep(poll)

    def memory_kb(self, field='VmRSS'):
        """Return a memory figure of the node process in kB (``VmRSS``, ``VmHWM``...)."""
        return proc_status_kb(self.proc.pid, field)

    def stop(self, sig=signal.SIGTERM, timeout=TIMEOUT):
        """Stop the process with ``sig`` (SIGKILL if it does not exit); return the code."""
        stop_process(self.proc, sig, timeout)
        if not self._out.closed:
            self._text = (self.stdout, self.stderr)
            self._out.close()
            self._err.close()
            shutil.rmtree(self._logdir, ignore_errors=True)
        return self.proc.returncode


class ForkedStart:
    """The outcome of one start-up run by ``node_refusals.py``: exit code and output."""

    def __init__(self, argv, code, stdout, stderr):
        self.argv, self.code, self.stdout, self.stderr = argv, code, stdout, stderr

    def describe(self):
        """Return the command line, exit code and output, for assertion messages."""
        return (f'{" ".join(self.argv)}: exit code {self.code}\n--- stdout\n{self.stdout}'
                f'\n--- stderr\n{self.stderr}')


def forked_starts(domain, arg_lists, timeout=120.0):
    """
    Run ``recovery_node``'s ``main()`` once per ROS argument list; return ForkedStart each.

    One process imports the node's modules, then forks a child per list that runs what
    the console script runs (see ``node_refusals.py``): the same start-up and the same
    refusal as a node process of its own, without paying its interpreter start and
    imports each time.  For start-ups that end before the network (bad configurations).
    """
    folder = Path(tempfile.mkdtemp(prefix='namo_forked_'))
    try:
        argvs = [[node_command()[-1], '--ros-args', *args] for args in arg_lists]
        cases = [[argv, str(folder / f'{i}.out'), str(folder / f'{i}.err')]
                 for i, argv in enumerate(argvs)]
        run = subprocess.run([sys.executable, str(Path(__file__).with_name('node_refusals.py'))],
                             input=json.dumps(cases), capture_output=True, text=True,
                             env=ros_env(domain), timeout=timeout)
        assert run.returncode == 0, run.stdout + run.stderr
        codes = json.loads(run.stdout.splitlines()[-1])
        return [ForkedStart(argv, code, Path(out).read_text(errors='replace'),
                            Path(err).read_text(errors='replace'))
                for (argv, out, err), code in zip(cases, codes)]
    finally:
        shutil.rmtree(folder, ignore_errors=True)


class LibraryVersion:
    """One version of the library received on /gesture_library (same header stamp)."""

    def __init__(self, stamp):
        self.stamp = stamp
        self.msgs = {}
        self.received = None

    @property
    def names(self):
        """Return the gesture names in arrival order."""
        return list(self.msgs)

    def positions(self, gesture):
        """Return the points' positions of one gesture, as lists."""
        return [list(p.positions) for p in self.msgs[gesture].points]

    def column(self, joint):
        """Return every angle of ``joint`` over every point of every gesture."""
        out = []
        for msg in self.msgs.values():
            index = list(msg.joint_names).index(joint)
            out += [p.positions[index] for p in msg.points]
        return out


class RosClient:
    """
    An rclpy client of the node in its own context and domain, spun in a thread.

    Built on :class:`RecoveryClient` (its node, its one ``/gesture_library``
    subscription); the test's own view of every version is kept here.
    """

    def __init__(self, domain, name='namo_test_client', gestures=None):
        os.environ['ROS_DOMAIN_ID'] = str(domain)
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        if gestures is None:   # the node's default: the packaged library
            gestures = len(load_library(load_robot()))
        self.gestures = gestures
        self._lock = threading.Condition()
        self.versions = {}            # stamp ns -> LibraryVersion
        self.order = []               # stamps in order of first arrival
        self.diagnostics = []         # node's DiagnosticArray messages
        self.markers = []
        self.recovery = RecoveryClient('/', domain, on_library=self._on_library,
                                       client_name=name)
        self.node = self.recovery.node
        latched = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 50)
        self.node.create_subscription(MarkerArray, '/gesture_markers', self._on_markers,
                                      latched)
        self.fault_pub = self.node.create_publisher(JointState, '/actuator_fault', 10)
        self.state_pub = self.node.create_publisher(JointState, '/joint_states', 10)
        self._clients = {}

    def close(self):
        """Shut the client down."""
        self.recovery.close()

    # --- callbacks ---

    def _on_library(self, key, msg):
        with self._lock:
            version = self.versions.get(key)
            if version is None:
                version = self.versions[key] = LibraryVersion(key)
                self.order.append(key)
            version.msgs[msg.header.frame_id] = msg
            if len(version.msgs) == self.gestures and version.received is None:
                version.received = time.monotonic()
            self._lock.notify_all()

    def _on_diag(self, msg):
        if not any(s.name.startswith(NODE_PREFIX) for s in msg.status):
            return
        with self._lock:
            self.diagnostics.append(msg)
            self._lock.notify_all()

    def _on_markers(self, msg):
        with self._lock:
            self.markers.append(msg)
            self._lock.notify_all()

    # --- waiting ---

    def wait_for(self, predicate, timeout=TIMEOUT, what='condition'):
        """Wait until ``predicate()`` (called under the lock) is truthy; return it."""
        value = wait_on(self._lock, predicate, timeout, 0.1)
        if not value:
            raise AssertionError(f'timed out after {timeout:.0f} s waiting for {what}')
        return value

    def complete_versions(self):
        """Return the complete library versions in order of arrival."""
        with self._lock:
            return [self.versions[k] for k in self.order
                    if len(self.versions[k].msgs) == self.gestures]

    def latest(self):
        """Return the newest complete library version (by stamp), or None."""
        versions = self.complete_versions()
        return max(versions, key=lambda v: v.stamp) if versions else None

    def wait_library(self, predicate=lambda v: True, after=None, timeout=TIMEOUT,
                     what='a library version'):
        """Wait for a complete version newer than ``after`` (a stamp) matching predicate."""
        def find():
            for key in sorted(self.versions, reverse=True):
                version = self.versions[key]
                if after is not None and key <= after:
                    break
                if len(version.msgs) == self.gestures and predicate(version):
                    return version
            return None
        return self.wait_for(find, timeout, what)

    def wait_diag(self, predicate, timeout=TIMEOUT, what='a diagnostics message',
                  since=0):
        """Wait for a node diagnostics message (index >= since) matching ``predicate``."""
        def find():
            for msg in reversed(self.diagnostics[since:]):
                statuses = {s.name[len(NODE_PREFIX):]: s for s in msg.status
                            if s.name.startswith(NODE_PREFIX)}
                if predicate(statuses):
                    return statuses
            return None
        return self.wait_for(find, timeout, what)

    def diag_count(self):
        """Return how many node diagnostics messages were received."""
        with self._lock:
            return len(self.diagnostics)

    # --- actions ---

    def wait_subscribers(self, publisher, timeout=TIMEOUT):
        """Wait until ``publisher`` is matched by at least one subscription."""
        end = time.monotonic() + timeout
        while publisher.get_subscription_count() < 1:
            if time.monotonic() > end:
                raise AssertionError('no subscriber matched ' + publisher.topic_name)
            time.sleep(0.02)

    def publish_fault(self, names, positions=(), velocity=(), effort=()):
        """Publish a fault report on /actuator_fault (once a subscriber is matched)."""
        self.wait_subscribers(self.fault_pub)
        msg = JointState(name=list(names), position=[float(p) for p in positions],
                         velocity=[float(v) for v in velocity],
                         effort=[float(e) for e in effort])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.fault_pub.publish(msg)

    def publish_joint_state(self, names, positions):
        """Publish a measured joint state on /joint_states."""
        self.wait_subscribers(self.state_pub)
        msg = JointState(name=list(names), position=[float(p) for p in positions])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.state_pub.publish(msg)

    def client(self, srv_type, name):
        """Return a (cached) service client."""
        if name not in self._clients:
            self._clients[name] = self.node.create_client(srv_type, name)
        return self._clients[name]

    def call(self, srv_type, name, request=None, timeout=TIMEOUT):
        """Call a service and return the response (AssertionError on timeout)."""
        client = self.client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise AssertionError(f'service {name} is not available')
        response = call_service(client, request if request is not None else srv_type.Request(),
                                timeout)
        if response is None:
            raise AssertionError(f'no answer from {name} within {timeout:.0f} s')
        return response

    def trigger(self, name, timeout=TIMEOUT):
        """Call a std_srvs/Trigger service."""
        return self.call(Trigger, name, timeout=timeout)

    def set_parameters(self, **values):
        """Set node parameters at run time; return the list of SetParametersResult."""
        request = SetParameters.Request(
            parameters=[Parameter(name.replace('__', '.'), value=v).to_parameter_msg()
                        for name, v in values.items()])
        return self.call(SetParameters, f'{NODE}/set_parameters', request).results

    def set_parameters_atomically(self, **values):
        """Set several parameters all at once or not at all; return the result."""
        request = SetParametersAtomically.Request(
            parameters=[Parameter(name.replace('__', '.'), value=v).to_parameter_msg()
                        for name, v in values.items()])
        return self.call(SetParametersAtomically, f'{NODE}/set_parameters_atomically',
                         request).result

    def get_parameters(self, *names):
        """Return the node's values of ``names`` as Python values."""
        response = self.call(GetParameters, f'{NODE}/get_parameters',
                             GetParameters.Request(names=list(names)))
        return [parameter_value_to_python(v) for v in response.values]


def statuses_values(status):
    """Return a DiagnosticStatus' values as a dict."""
    return {kv.key: kv.value for kv in status.values}


def close_to(a, b, tol=1e-12):
    """Return True if two angles agree to ``tol``."""
    return math.isclose(a, b, rel_tol=0.0, abs_tol=tol)


class DiagnosticsProbe:
    """
    A lean client for flooding tests: raw ``/diagnostics`` sizes, faults, Trigger calls.

    It takes ``/diagnostics`` as serialized bytes (``raw=True``) and keeps only each
    message's size and its node statuses with every value cut to ``value_chars``, so a
    node that publishes huge diagnostics is measured without the probe holding them.
    Its fault publisher is reliable with KEEP_ALL history, so it never drops its own
    samples however fast they are published.
    """

    def __init__(self, domain, name='namo_test_probe', value_chars=1000):
        from rclpy.serialization import deserialize_message
        self._deserialize = deserialize_message
        self.value_chars = value_chars
        self._spun = SpunNode(name, domain)
        self.node = self._spun.node
        self._lock = threading.Condition()
        self.sizes = []           # byte size of every /diagnostics message, in arrival order
        self.statuses = []        # (index, {name: {key: value cut at value_chars}})
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 50,
                                      raw=True)
        keep_all = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL,
                              reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
        self.fault_pub = self.node.create_publisher(JointState, '/actuator_fault', keep_all)
        self._trigger_clients = {}
        self._spun.start()

    def close(self):
        """Shut the probe down."""
        self._spun.close()

    def _on_diag(self, data):
        msg = self._deserialize(data, DiagnosticArray)
        cut = self.value_chars
        decoded = {s.name[len(NODE_PREFIX):]: {kv.key[:cut]: kv.value[:cut] for kv in s.values}
                   for s in msg.status if s.name.startswith(NODE_PREFIX)}
        del msg
        with self._lock:
            self.sizes.append(len(data))
            if decoded:
                self.statuses.append((len(self.sizes) - 1, decoded))
            self._lock.notify_all()

    def wait_statuses(self, predicate, timeout=TIMEOUT, since=0, what='diagnostics'):
        """Wait for a node diagnostics message (index >= since) matching ``predicate``."""
        def find():
            for index, statuses in reversed(self.statuses):
                if index >= since and predicate(statuses):
                    return statuses
            return None
        found = wait_on(self._lock, find, timeout, 0.1)
        if found is None:
            raise AssertionError(f'timed out after {timeout:.0f} s waiting for {what}')
        return found

    def count(self):
        """Return how many /diagnostics messages arrived so far."""
        with self._lock:
            return len(self.sizes)

    def wait_count(self, count, timeout=TIMEOUT):
        """Wait until at least ``count`` /diagnostics messages arrived; return the count."""
        end = time.monotonic() + timeout
        with self._lock:
            while len(self.sizes) < count:
                remaining = end - time.monotonic()
                if remaining <= 0:
                    break
                self._lock.wait(min(remaining, 0.1))
            return len(self.sizes)

    def latest(self):
        """Return the (cut) statuses of the newest node diagnostics message, or {}."""
        with self._lock:
            return self.statuses[-1][1] if self.statuses else {}

    def trigger(self, name, timeout=TIMEOUT):
        """Call a std_srvs/Trigger service; return the response, or None without answer."""
        client = self._trigger_clients.get(name)
        if client is None:
            client = self._trigger_clients[name] = self.node.create_client(Trigger, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise AssertionError(f'service {name} is not available')
        return call_service(client, Trigger.Request(), timeout)


_BARE_SUBSCRIBER = """
import signal, sys, threading
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
rclpy.init()
node = rclpy.create_node('namo_test_bare_subscriber')
count = [0]
qos = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL,
                 reliability=ReliabilityPolicy.RELIABLE)
node.create_subscription(JointState, sys.argv[1], lambda msg: count.__setitem__(0, count[0] + 1),
                         qos)
stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
executor = SingleThreadedExecutor()
executor.add_node(node)
print('ready', flush=True)
while not stop.is_set():
    executor.spin_once(timeout_sec=0.05)
print(count[0], flush=True)
"""


class BareSubscriber:
    """
    A control process: a plain rclpy subscription (reliable, KEEP_ALL) that does nothing.

    Its resident memory shows what DDS and rclpy themselves keep after receiving some
    traffic (receive buffers, payload pools), so a test can tell the node's own growth
    from the transport's.  ``count()`` stops it and returns how many messages it took.
    """

    def __init__(self, domain, topic='/actuator_fault'):
        self.proc = subprocess.Popen([sys.executable, '-c', _BARE_SUBSCRIBER, topic],
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     env=ros_env(domain))
        line = self.proc.stdout.readline()
        if line.strip() != b'ready':
            self.proc.kill()
            raise AssertionError('the bare subscriber did not start')

    def memory_kb(self, field='VmRSS'):
        """Return a memory figure of the control process in kB."""
        return proc_status_kb(self.proc.pid, field)

    def count(self):
        """Stop the process; return how many messages it received."""
        self.proc.send_signal(signal.SIGTERM)
        try:
            out, _ = self.proc.communicate(timeout=TIMEOUT)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()
            return None
        return int(out.split()[-1])
