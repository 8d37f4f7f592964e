"""
A ``/joint_states`` stream, as a robot's drivers publish it, for the node benchmarks.

:class:`JointStateStream` publishes from a thread of the caller's node (the stress
tests); :class:`StreamProcess` runs :func:`stream_main` as a child process, so that the
stream never shares the measuring client's interpreter (``bench stream``, ``bench
latency --joint-states-hz``).  :func:`reading_lateness` receives such a stream as the
gesture player does and measures how late each reading arrives (``bench
detection-suite``).
"""

import argparse
import json
import os
import select
import signal
import subprocess
import sys
import threading
import time

from .spun_node import SpunNode, wait_until
from ..runtime.realtime import leave_fifo

READY = 'streaming'     # the child's first stdout line: published, and a subscriber matched
MATCH_TIMEOUT = 30.0    # s: READY at the latest then, matched or not


def reference_pose(robot=None, library=None):
    """
    Return ``(names, positions)``: every arm joint (14 on Namo) at the library's first keyframe.

    That is the pose a robot standing ready to gesture reports on ``/joint_states``;
    names come from the robot model (right arm first).
    """
    from ..model.gestures import load_library
    from ..model.robot import load_robot
    robot = robot or load_robot()
    library = library or load_library(robot)
    names = list(robot.joint_names)
    positions = [float(a) for a in library.gestures[0].keyframes[0].positions()]
    return names, positions


def library_pose(library):
    """
    Return ``(names, positions)`` of a node's published library: its first gesture's start.

    ``library`` is a :class:`~.client.PublishedLibrary`.  Every joint the node plays (the
    arms', then a torso's where the gesture leans it), so that a stream for any robot
    carries that robot's joints, as its drivers would.
    """
    first = library.result.gestures[0]
    names = list(library.joint_names) + list(first.shared)
    positions = [float(a) for a in first.positions[0]] + [float(a) for a in
                                                          first.shared.values()]
    return names, positions


def library_stream(client, rate, timeout):
    """
    Start a :class:`StreamProcess` of the node's own joints; return ``(stream, started)``.

    ``client`` (a :class:`~.client.RecoveryClient`) reads the library the node serves
    (:func:`library_pose`), so that a stream for any robot carries that robot's names,
    as its drivers would.  ``started`` is :meth:`StreamProcess.wait_streaming`'s answer
    within ``timeout`` s: the stream publishes to a matched subscriber (the node).
    """
    pose = library_pose(client.current_library(timeout, diagnostics_timeout=0.0))
    stream = StreamProcess(rate, client.domain_id, pose=pose)
    return stream, stream.wait_streaming(timeout)


class JointStateStream:
    """
    Publish ``sensor_msgs/JointState`` on ``/joint_states`` at ``rate`` Hz in a thread.

    Sent at absolute times (``start + k / rate``) so that a late wake-up does not lower
    the rate; ``nan_every`` > 0 replaces one position by NaN in every n-th message (a
    driver glitch the node must reject without disturbing anything else).
    """

    def __init__(self, node, rate, names, positions, nan_every=0, topic='/joint_states',
                 qos=None):
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState
        self._type = JointState
        self._node = node
        self.rate = float(rate)
        self.names = list(names)
        self.positions = [float(p) for p in positions]
        self.nan_every = int(nan_every)
        qos = qos or QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                                reliability=ReliabilityPolicy.BEST_EFFORT)
        self.publisher = node.create_publisher(JointState, topic, qos)
        self.sent = 0
        self.sent_nan = 0
        self.started = None
        self.stopped = None
        self._stop = threading.Event()
        self._thread = None

    def start(self):
        """Start publishing (returns at once)."""
        self._thread = threading.Thread(target=self._run, name='joint_states', daemon=True)
        self._thread.start()
        return self

    def stop(self):
        """Stop publishing and wait for the thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
        return False

    @property
    def achieved_rate(self):
        """Return the messages per second actually sent so far."""
        if self.started is None:
            return 0.0
        end = self.stopped or time.monotonic()
        return self.sent / max(end - self.started, 1e-9)

    def _run(self):
        period = 1.0 / self.rate
        self.started = time.monotonic()
        k = 0
        while not self._stop.is_set():
            k += 1
            positions = list(self.positions)
            nan = self.nan_every > 0 and k % self.nan_every == 0
            if nan:
                positions[k % len(positions)] = float('nan')
            msg = self._type(name=self.names, position=positions)
            msg.header.stamp = self._node.get_clock().now().to_msg()
            try:
                self.publisher.publish(msg)
            except Exception:  # noqa: B902 - the context was shut down under us
                break
            self.sent += 1
            self.sent_nan += int(nan)
            delay = self.started + k * period - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
        self.stopped = time.monotonic()


def stream_main(argv=None):
    """Run a stand-alone ``/joint_states`` publisher until SIGTERM (the bench's driver)."""
    parser = argparse.ArgumentParser(prog='namo_fault_recovery.ros.joint_state_stream')
    parser.add_argument('--rate', type=float, required=True)
    parser.add_argument('--domain-id', type=int, default=None)
    parser.add_argument('--pose', default=None, metavar='JSON',
                        help='{"names": [...], "positions": [...]} (default: Namo at the '
                             'start of its first gesture)')
    args = parser.parse_args(argv)
    leave_fifo()             # a driver of its own: not the real-time client that started it
    if args.pose:
        pose = json.loads(args.pose)
        names, positions = pose['names'], pose['positions']
    else:
        names, positions = reference_pose()
    spun = SpunNode(f'namo_joint_state_stream_{os.getpid()}', args.domain_id)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGINT, lambda *_: done.set())
    with JointStateStream(spun.node, args.rate, names, positions) as stream:
        # Ready once a subscriber (the node) is matched: sent before that, readings are lost.
        wait_until(lambda: (stream.sent > 0 and stream.publisher.get_subscription_count() > 0)
                   or done.is_set(), MATCH_TIMEOUT, 0.01)
        sys.stdout.write(READY + '\n')
        sys.stdout.flush()
        done.wait()
    sys.stdout.write(json.dumps({'sent': stream.sent,
                                 'rate_hz': round(stream.achieved_rate, 1)}) + '\n')
    spun.close()
    return 0


class StreamProcess:
    """The stream publisher as a child process (a robot's drivers are other processes)."""

    def __init__(self, rate, domain_id, pose=None):
        """
        Start publishing at ``rate`` Hz in ``domain_id`` (None: ``$ROS_DOMAIN_ID``).

        ``pose`` is ``(names, positions)`` (None: :func:`reference_pose`, Namo's).
        """
        self.rate = rate
        cmd = [sys.executable, '-m', 'namo_fault_recovery.ros.joint_state_stream',
               '--rate', str(rate)]
        if domain_id is not None:
            cmd += ['--domain-id', str(domain_id)]
        if pose is not None:
            names, positions = pose
            cmd += ['--pose', json.dumps({'names': list(names),
                                          'positions': [float(a) for a in positions]})]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     env=dict(os.environ, PYTHONUNBUFFERED='1'))
        self.report = {}

    def wait_streaming(self, timeout=30.0):
        """
        Return True once the child publishes to a matched subscriber, False at timeout.

        Its start-up (an interpreter importing rclpy) is over then, and the readings reach
        the node.
        """
        end = time.monotonic() + timeout
        while self.proc.poll() is None:
            left = end - time.monotonic()
            if left <= 0 or not select.select([self.proc.stdout], [], [], left)[0]:
                return False
            if self.proc.stdout.readline().decode().strip() == READY:
                return True
        return False

    def close(self):
        """Stop the stream; return its report (``sent``, ``rate_hz``), {} if it gave none."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            text, _ = self.proc.communicate(timeout=15)
            self.report = json.loads(text.decode().strip().splitlines()[-1])
        except (subprocess.TimeoutExpired, ValueError, IndexError):
            self.proc.kill()
            self.proc.wait()
        return self.report


def reading_lateness(seconds, domain_id=None, rate=100.0):
    """
    Return how late (s) each reading of a ``rate`` Hz stream reaches a subscriber.

    A :class:`StreamProcess` publishes, a :class:`SpunNode` in this process subscribes
    as ``gesture_player`` does (best effort, depth 10, one executor thread).  Lateness
    is the receipt time (ROS clock) minus the time the reading was due: the stream is
    sent on absolute times, so reading ``k`` was due at ``first + k / rate``, where
    ``first`` is the earliest that fits every stamp (a late sender counts as late).
    In arrival order; the first second (discovery) is left out.
    """
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    received = []
    lock = threading.Lock()
    spun = SpunNode(f'namo_reading_lateness_{os.getpid()}', domain_id)

    def on_state(msg):
        now = spun.node.get_clock().now().nanoseconds * 1e-9
        with lock:
            received.append((msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, now))
    spun.node.create_subscription(JointState, '/joint_states', on_state, QoSProfile(
        depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
    spun.start()
    stream = StreamProcess(rate, domain_id)
    try:
        wait_until(lambda: len(received) > rate, 30.0, 0.05, lock)
        time.sleep(seconds)
    finally:
        stream.close()
        spun.close()
    with lock:
        pairs = received[int(rate):]
    if not pairs:
        return []
    stamps = [s for s, _ in pairs]
    period = 1.0 / rate
    index = [round((s - stamps[0]) / period) for s in stamps]
    first = min(s - k * period for s, k in zip(stamps, index))
    return [r - (first + k * period) for (_, r), k in zip(pairs, index)]


if __name__ == '__main__':
    sys.exit(stream_main())
