"""
``namo-recovery`` subcommands that talk to a running ``recovery_node`` over ROS 2.

For machines without the ``ros2`` tool: ``fault``, ``clear``, ``reconfigure``,
``library``, ``demo`` and the ``latency`` benchmark are real rclpy clients of the node
(publishers, subscribers and service clients in the current ``ROS_DOMAIN_ID``); nothing
is faked in-process.  rclpy is imported only when one of them runs, so the rest of the
command line works without ROS.

Exit codes: 0 on success, 1 when the node is unreachable, rejects the input or reports
a failure, 2 for bad arguments.
"""

import importlib.util
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

import numpy as np

EXIT_FAILURE = 1
EXIT_USAGE = 2
DEFAULT_FAULT = 'right_arm_joint2'
NODE_PREFIX = 'recovery_node: '
_SETTLE = 0.3


class RosCliError(Exception):
    """A failure reported on one line; ``code`` is the exit code."""

    def __init__(self, message, code=EXIT_FAILURE):
        super().__init__(message)
        self.code = code


def node_command():
    """Return the command that starts the ``recovery_node`` executable."""
    beside = Path(sys.executable).parent / 'recovery_node'
    if beside.is_file():
        return [str(beside)]
    found = shutil.which('recovery_node')
    if found:
        return [found]
    return [sys.executable, '-m', 'namo_fault_recovery.ros.recovery_node']


def _private_domain():
    """Return a domain id for a private node (demo, bench --start-node)."""
    return 70 + os.getpid() % 30


class _Session:
    """An rclpy node in its own context, spun in a background thread."""

    def __init__(self, domain_id=None):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        self._rclpy = rclpy
        self.domain_id = domain_id
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(f'namo_recovery_cli_{os.getpid()}', context=self.context)
        self._cond = threading.Condition()
        self.versions = {}        # stamp (ns) -> {gesture: JointTrajectory}
        self.last_arrival = None
        self.diagnostics = []     # (arrival time, {name: DiagnosticStatus})
        latched = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(JointTrajectory, '/gesture_library', self._on_library,
                                      latched)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 50)
        self.fault_pub = self.node.create_publisher(JointState, '/actuator_fault', 10)
        self._joint_state_type = JointState
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        try:
            self.executor.spin()
        except Exception:  # noqa: B902 - the context is shut down when the command ends
            pass

    def close(self):
        """Shut the session down."""
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=5.0)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _on_library(self, msg):
        key = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self._cond:
            self.versions.setdefault(key, {})[msg.header.frame_id] = msg
            self.last_arrival = time.monotonic()
            self._cond.notify_all()

    def _on_diag(self, msg):
        statuses = {s.name[len(NODE_PREFIX):]: s for s in msg.status
                    if s.name.startswith(NODE_PREFIX)}
        if statuses:
            with self._cond:
                self.diagnostics.append((time.monotonic(), statuses))
                self._cond.notify_all()

    def wait(self, predicate, timeout):
        """Wait until ``predicate()`` (called under the lock) is truthy; return it or None."""
        end = time.monotonic() + timeout
        with self._cond:
            while True:
                value = predicate()
                if value:
                    return value
                remaining = end - time.monotonic()
                if remaining <= 0:
                    return None
                self._cond.wait(min(remaining, 0.05))

    def current_library(self, timeout):
        """
        Return ``(stamp, {gesture: msg})`` of the library the node publishes now.

        Transient local delivers the whole current version to a late subscriber; the
        version is taken once no message has arrived for a short while.
        """
        def settled():
            if self.last_arrival is None:
                return None
            if time.monotonic() - self.last_arrival < _SETTLE:
                return None
            stamp = max(self.versions)
            return stamp, dict(self.versions[stamp])
        found = self.wait(settled, timeout)
        if found is None:
            domain = self.domain_id
            if domain is None:
                domain = os.environ.get('ROS_DOMAIN_ID', 0)
            raise RosCliError(f'no recovery_node found: nothing received on /gesture_library '
                              f'within {timeout:g} s (ROS_DOMAIN_ID={domain}); is the node '
                              f'running?')
        return found

    def next_library(self, after, count, timeout):
        """Wait for a complete library version newer than ``after``; return it or None."""
        def newer():
            for stamp in sorted(self.versions, reverse=True):
                if stamp <= after:
                    return None
                if len(self.versions[stamp]) >= count:
                    return stamp, dict(self.versions[stamp])
            return None
        return self.wait(newer, timeout)

    def latest_diag(self, predicate=lambda s: True, since=None, timeout=0.0):
        """Return the newest node diagnostics (arrived after ``since``) matching predicate."""
        def find():
            for arrival, statuses in reversed(self.diagnostics):
                if since is not None and arrival < since:
                    return None
                if predicate(statuses):
                    return statuses
            return None
        return self.wait(find, timeout)

    def publish_fault(self, joints, angles, timeout):
        """Publish a fault report once the node's subscription is matched."""
        end = time.monotonic() + timeout
        while self.fault_pub.get_subscription_count() < 1:
            if time.monotonic() > end:
                raise RosCliError('nobody subscribes to /actuator_fault; is the node running?')
            time.sleep(0.02)
        msg = self._joint_state_type(name=list(joints),
                                     position=[float(a) for a in angles or ()])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.fault_pub.publish(msg)

    def trigger(self, service, timeout):
        """Call a std_srvs/Trigger service; return the response."""
        from std_srvs.srv import Trigger
        client = self.node.create_client(Trigger, service)
        try:
            if not client.wait_for_service(timeout_sec=timeout):
                raise RosCliError(f'service {service} is not available within {timeout:g} s; '
                                  f'is the node running?')
            done = threading.Event()
            future = client.call_async(Trigger.Request())
            future.add_done_callback(lambda _: done.set())
            if not done.wait(timeout):
                raise RosCliError(f'no answer from {service} within {timeout:g} s')
            return future.result()
        finally:
            self.node.destroy_client(client)


def _values(status):
    return {kv.key: kv.value for kv in status.values}


def _angles(msg):
    """Return the positions of a trajectory, per point, keyed by joint name."""
    return [dict(zip(msg.joint_names, p.positions)) for p in msg.points]


def _locks_from_diag(statuses):
    locks = {}
    for name, st in (statuses or {}).items():
        if name.startswith('joint '):
            values = _values(st)
            try:
                locks[values['joint']] = float(values['lock_angle_rad'])
            except (KeyError, ValueError):
                locks[name[len('joint '):]] = None
    return locks


def _rejected_total(statuses):
    try:
        return int(_values(statuses['inputs'])['rejected_total'])
    except (KeyError, ValueError, TypeError):
        return None


def _gesture_table(statuses, names):
    """Return the score table from a 'reconfiguration' diagnostics status."""
    values = _values(statuses['reconfiguration'])
    lines = [f"{'gesture':<14}{'before':>10}{'after':>10}{'time (s)':>10}  status"]
    for name in names:
        lines.append(f"{name:<14}{float(values.get(f'{name}.score_before', 'nan')):>10.2f}"
                     f"{float(values.get(f'{name}.score_after', 'nan')):>10.2f}"
                     f"{float(values.get(f'{name}.time_sec', 'nan')):>10.3f}  "
                     f"{values.get(f'{name}.status', '?')}")
    deadline = values.get('deadline_sec', '?')
    met = values.get('deadline_met', '?')
    lines.append(f"library time {values.get('wall_time_sec', '?')} s, deadline {deadline} s "
                 f"{'met' if met == 'true' else 'MISSED'}")
    frozen = values.get('frozen_arms')
    if frozen:
        lines.append(f'frozen arm(s): {frozen}')
    return '\n'.join(lines) + '\n'


def _fault_angles(args):
    if args.angle is None:
        return None
    if len(args.angle) != len(args.joints):
        raise RosCliError(f'--angle: expected one angle (deg) per joint ({len(args.joints)}), '
                          f'got {len(args.angle)}', EXIT_USAGE)
    if not all(math.isfinite(a) for a in args.angle):
        raise RosCliError('--angle: angles must be finite', EXIT_USAGE)
    return [math.radians(a) for a in args.angle]


def _inject_fault(session, joints, angles, timeout, out):
    """Publish a fault and wait for the resulting library; return (library, statuses)."""
    stamp, current = session.current_library(timeout)
    baseline_diag = session.latest_diag(timeout=1.5)
    baseline = _rejected_total(baseline_diag)
    t0 = time.monotonic()
    session.publish_fault(joints, angles, timeout)
    described = ', '.join(
        f'{j} at {math.degrees(a):.2f} deg' for j, a in zip(joints, angles)) if angles else (
        ', '.join(joints) + " (lock angle chosen by the node's lock strategy)")
    out.write(f'fault reported on /actuator_fault: {described}\n')

    def outcome():
        for key in sorted(session.versions, reverse=True):
            if key <= stamp:
                break
            if len(session.versions[key]) >= len(current):
                return ('library', key)
        if baseline is not None:
            for arrival, statuses in reversed(session.diagnostics):
                if arrival < t0:
                    break
                total = _rejected_total(statuses)
                if total is not None and total > baseline:
                    return ('rejected', statuses)
        return None
    result = session.wait(outcome, timeout)
    if result is None:
        raise RosCliError(f'no new library within {timeout:g} s of the fault report')
    if result[0] == 'rejected':
        reason = _values(result[1]['inputs']).get('last_rejected_reason', '?')
        raise RosCliError(f'the node rejected the fault report: {reason}')
    key = result[1]
    elapsed = time.monotonic() - t0
    library = dict(session.versions[key])
    out.write(f'new library received {elapsed:.3f} s after the report '
              f'({len(library)} gestures)\n')
    statuses = session.latest_diag(
        lambda s: ('reconfiguration' in s and _values(s['reconfiguration']).get('up_to_date')
                   == 'true' and all(f'joint {j}' in s for j in joints)),
        since=t0, timeout=3.0)
    return key, library, statuses


def cmd_fault(args, out):
    """Report failed joints to the node and print the reconfigured library's scores."""
    angles = _fault_angles(args)
    with _Session(args.domain_id) as session:
        _, library, statuses = _inject_fault(session, args.joints, angles, args.timeout, out)
        if statuses is not None:
            out.write(_gesture_table(statuses, list(library)))
            for joint, lock in _locks_from_diag(statuses).items():
                if lock is not None:
                    out.write(f'locked: {joint} at {math.degrees(lock):.2f} deg\n')
    return 0


def cmd_clear(args, out):
    """Call /clear_faults."""
    with _Session(args.domain_id) as session:
        response = session.trigger('/clear_faults', args.timeout)
    out.write(response.message + '\n')
    return 0 if response.success else EXIT_FAILURE


def cmd_reconfigure(args, out):
    """Call /reconfigure_gestures (what the gesture player does) and print its answer."""
    with _Session(args.domain_id) as session:
        t0 = time.monotonic()
        response = session.trigger('/reconfigure_gestures', args.timeout)
        elapsed = time.monotonic() - t0
    out.write(f"{'success' if response.success else 'FAILURE'} ({elapsed:.3f} s): "
              f'{response.message}\n')
    return 0 if response.success else EXIT_FAILURE


def _format_library(stamp, library, locks, out):
    when = time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(stamp / 1e9))
    out.write(f'library of {when}.{stamp % 1_000_000_000 // 1_000_000:03d} '
              f'({len(library)} gestures); angles in degrees')
    if locks is None:
        out.write('; locked joints unknown (no /diagnostics received)\n')
    elif locks:
        out.write('; * = locked joint: ' + ', '.join(
            f'{j} at {math.degrees(a):.2f}' if a is not None else j
            for j, a in locks.items()) + '\n')
    else:
        out.write('; no locked joint (reference library)\n')
    for name, msg in library.items():
        out.write(f'\n{name}\n')
        joints = list(msg.joint_names)
        for point in msg.points:
            t = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
            out.write(f'  t = {t:.3f} s\n')
            for side in ('right', 'left'):
                cols = [(j, a) for j, a in zip(joints, point.positions) if j.startswith(side)]
                if not cols:
                    continue
                cells = ' '.join(f"{math.degrees(a):8.2f}{'*' if locks and j in locks else ' '}"
                                 for j, a in cols)
                out.write(f'    {side:<5} {cells}\n')
        others = [(j, a) for j, a in zip(joints, msg.points[0].positions)
                  if not j.startswith(('right', 'left'))] if msg.points else []
        if others:
            out.write(f'    other joints: {", ".join(j for j, _ in others)}\n')


def cmd_library(args, out):
    """Print the current library received from /gesture_library."""
    with _Session(args.domain_id) as session:
        stamp, library = session.current_library(args.timeout)
        statuses = session.latest_diag(lambda s: 'faults' in s, timeout=min(args.timeout, 3.0))
    locks = None if statuses is None else _locks_from_diag(statuses)
    if args.json:
        doc = {'stamp_ns': stamp, 'locked_joints': locks, 'gestures': {
            name: [{'time_from_start': p.time_from_start.sec
                    + p.time_from_start.nanosec * 1e-9,
                    'positions_rad': dict(zip(msg.joint_names, p.positions))}
                   for p in msg.points]
            for name, msg in library.items()}}
        out.write(json.dumps(doc, indent=2) + '\n')
        return 0
    _format_library(stamp, library, locks, out)
    return 0


def _start_node(args, domain_id, state_dir, out):
    ros_args = ['-p', f'state_dir:={state_dir}']
    for option, param in (('robot_file', 'robot_file'), ('gesture_file', 'gesture_file')):
        value = getattr(args, option, None)
        if value:
            ros_args += ['-p', f'{param}:={os.path.abspath(value)}']
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1')
    log = open(os.path.join(state_dir, 'node.log'), 'w+b')
    cmd = node_command() + ['--ros-args'] + ros_args
    out.write(f"starting the node: {' '.join(cmd)} (ROS_DOMAIN_ID={domain_id})\n")
    return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env), log


def _stop_node(proc, log, out):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    log.flush()
    log.seek(0)
    text = log.read().decode(errors='replace')
    log.close()
    return proc.returncode, text


class _ReceivedReport:
    """The library received over ROS, shaped like a LibraryResult for plotting."""

    def __init__(self, robot, library_msgs, statuses, locks):
        from types import SimpleNamespace

        from ..model.gestures import Keyframe
        values = _values(statuses['reconfiguration'])
        self.locks = dict(locks)
        self.settings = {'optimizer': values.get('optimizer', '?')}
        self._gestures = {}
        names = list(robot.joint_names)
        for name, msg in library_msgs.items():
            order = [list(msg.joint_names).index(j) for j in names]
            frames = []
            for p in msg.points:
                q = [p.positions[i] for i in order]
                t = p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                frames.append(Keyframe(t, np.asarray(q[:7]), np.asarray(q[7:])))
            self._gestures[name] = SimpleNamespace(
                name=name, keyframes=tuple(frames),
                score_before=float(values.get(f'{name}.score_before', 'nan')),
                score_after=float(values.get(f'{name}.score_after', 'nan')),
                status=values.get(f'{name}.status', '?'),
                wall_time=float(values.get(f'{name}.time_sec', 'nan')))

    def __getitem__(self, name):
        return self._gestures[name]


def _save_pngs(args, library_msgs, statuses, locks, out_dir, out):
    """Save one stick figure per gesture (needs matplotlib)."""
    if importlib.util.find_spec('matplotlib') is None:
        out.write('stick-figure PNG skipped: matplotlib is not installed '
                  "(pip install -e '.[plot]')\n")
        return []
    from ..benchmarks import plotting
    from ..model.gestures import load_library
    from ..model.robot import load_robot
    robot = load_robot(getattr(args, 'robot_file', None))
    library = load_library(robot, getattr(args, 'gesture_file', None))
    report = _ReceivedReport(robot, library_msgs, statuses, locks)
    paths = []
    for name in library.names:
        path = Path(out_dir) / f'{name}.png'
        plotting.plot_reconfiguration(robot, library, report, name, path)
        out.write(f'stick figure saved: {path}\n')
        paths.append(path)
    return paths


def cmd_demo(args, out):
    """Start the node, inject a fault, print scores before/after, save a PNG, shut down."""
    angles = _fault_angles(args)
    domain_id = args.domain_id if args.domain_id is not None else _private_domain()
    workdir = tempfile.mkdtemp(prefix='namo_demo_')
    proc, log = _start_node(args, domain_id, workdir, out)
    code = 0
    try:
        with _Session(domain_id) as session:
            stamp, reference = session.current_library(args.timeout)
            out.write(f'reference library received on /gesture_library: '
                      f'{", ".join(reference)}\n')
            _, library, statuses = _inject_fault(session, args.joints, angles, args.timeout,
                                                 out)
            if statuses is None:
                raise RosCliError('no /diagnostics describing the new library')
            out.write('\n' + _gesture_table(statuses, list(library)))
            locks = {j: a for j, a in _locks_from_diag(statuses).items() if a is not None}
            for joint, lock in locks.items():
                out.write(f'locked: {joint} at {math.degrees(lock):.2f} deg\n')
            out.write('\ncalling /reconfigure_gestures, as the gesture player does...\n')
            t0 = time.monotonic()
            response = session.trigger('/reconfigure_gestures', args.timeout)
            out.write(f"{'success' if response.success else 'FAILURE'} "
                      f'({time.monotonic() - t0:.3f} s): {response.message}\n')
            _, after = session.current_library(args.timeout)
            statuses = session.latest_diag(
                lambda s: ('reconfiguration' in s and _values(s['reconfiguration']).get(
                    'up_to_date') == 'true'), timeout=3.0) or statuses
            try:
                _save_pngs(args, after, statuses, locks, args.out_dir, out)
            except Exception as exc:  # noqa: B902 - the figure is a bonus; report it
                out.write(f'stick-figure PNG not saved: {type(exc).__name__}: {exc}\n')
    except RosCliError:
        code = EXIT_FAILURE
        raise
    finally:
        rc, text = _stop_node(proc, log, out)
        if rc != 0 or code:
            out.write(f'node exited with code {rc}; its log:\n{text}')
        else:
            out.write(f'node stopped cleanly (exit code {rc})\n')
        shutil.rmtree(workdir, ignore_errors=True)
    return 0 if rc == 0 else EXIT_FAILURE


def _percentiles(values):
    arr = np.asarray(values, dtype=float) * 1000.0
    return {'n': int(arr.size), 'p50_ms': float(np.percentile(arr, 50)),
            'p95_ms': float(np.percentile(arr, 95)), 'max_ms': float(arr.max()),
            'mean_ms': float(arr.mean())}


def bench_latency(args, out):
    """
    Measure fault-publish -> full-library-received latency against a running node.

    For each of ``args.count`` single-joint faults (cycling over the 14 joints): clear
    the faults, publish the fault, time the arrival of the complete new library, then
    time a /reconfigure_gestures round trip.  Prints p50/p95/max.
    """
    proc = log = workdir = None
    domain_id = args.domain_id
    if args.start_node:
        domain_id = domain_id if domain_id is not None else _private_domain()
        workdir = tempfile.mkdtemp(prefix='namo_bench_')
        proc, log = _start_node(args, domain_id, workdir, out)
    latencies, round_trips, engine, overhead, failures = [], [], [], [], []
    try:
        with _Session(domain_id) as session:
            stamp, current = session.current_library(args.timeout)
            joints = list(next(iter(current.values())).joint_names)
            if args.joints:
                unknown = [j for j in args.joints if j not in joints]
                if unknown:
                    raise RosCliError(f'--joints: unknown joint {unknown[0]!r}', EXIT_USAGE)
                joints = list(args.joints)
            count = len(current)
            for i in range(args.count):
                joint = joints[i % len(joints)]
                response = session.trigger('/clear_faults', args.timeout)
                if not response.success:
                    raise RosCliError(f'/clear_faults failed: {response.message}')
                cleared = session.next_library(stamp, count, args.timeout)
                if cleared is None:
                    raise RosCliError('the reference library did not arrive after a clear')
                stamp = cleared[0]
                t0 = time.monotonic()
                session.publish_fault([joint], None, args.timeout)
                got = session.next_library(stamp, count, args.timeout)
                if got is None:
                    failures.append(f'{joint}: no library within {args.timeout:g} s')
                    continue
                latencies.append(time.monotonic() - t0)
                stamp = got[0]
                text = f'{stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d}'
                statuses = session.latest_diag(
                    lambda s: ('reconfiguration' in s and _values(s['reconfiguration']).get(
                        'library_stamp') == text), timeout=3.0)
                if statuses is not None:
                    wall = float(_values(statuses['reconfiguration'])['wall_time_sec'])
                    engine.append(wall)
                    overhead.append(latencies[-1] - wall)
                t1 = time.monotonic()
                response = session.trigger('/reconfigure_gestures', args.timeout)
                round_trips.append(time.monotonic() - t1)
                if not response.success:
                    failures.append(f'{joint}: {response.message}')
                newer = session.next_library(stamp, count, args.timeout)
                if newer is not None:
                    stamp = newer[0]
                if args.verbose:
                    out.write(f'{i + 1:3d} {joint:<18} fault->library '
                              f'{latencies[-1] * 1000:8.1f} ms   service '
                              f'{round_trips[-1] * 1000:8.1f} ms\n')
            session.trigger('/clear_faults', args.timeout)
    finally:
        if proc is not None:
            _stop_node(proc, log, out)
            shutil.rmtree(workdir, ignore_errors=True)
    if not latencies:
        raise RosCliError('no measurement succeeded: ' + '; '.join(failures[:3]))
    report = {'faults': args.count, 'fault_to_library': _percentiles(latencies),
              'reconfigure_service': _percentiles(round_trips), 'failures': failures}
    if engine:
        report['engine_wall_time'] = _percentiles(engine)
        report['node_and_dds_overhead'] = _percentiles(overhead)
    if args.json:
        out.write(json.dumps(report, indent=2) + '\n')
        return 0 if not failures else EXIT_FAILURE
    for label, key in (('fault publish -> full library received', 'fault_to_library'),
                       ('/reconfigure_gestures round trip', 'reconfigure_service'),
                       ('  of which optimisation (engine wall time)', 'engine_wall_time'),
                       ('  of which node + DDS (latency - engine)', 'node_and_dds_overhead')):
        if key not in report:
            continue
        s = report[key]
        out.write(f"{label:<42} n={s['n']:<3} p50 {s['p50_ms']:7.1f} ms  "
                  f"p95 {s['p95_ms']:7.1f} ms  max {s['max_ms']:7.1f} ms\n")
    for failure in failures:
        out.write(f'failure: {failure}\n')
    return 0 if not failures else EXIT_FAILURE


# --- argparse wiring -----------------------------------------------------------------


def _common(parser, timeout=15.0):
    parser.add_argument('--timeout', type=float, default=timeout, metavar='SEC',
                        help=f'how long to wait for the node (default {timeout:g} s)')
    parser.add_argument('--domain-id', type=int, default=None, metavar='N',
                        help='ROS domain id (default: $ROS_DOMAIN_ID, else 0)')


def _wrap(func):
    def run(args, out):
        try:
            return func(args, out)
        except RosCliError as exc:
            sys.stderr.write(f'namo-recovery: error: {exc}\n')
            return exc.code
        except KeyboardInterrupt:
            sys.stderr.write('namo-recovery: interrupted\n')
            return 130
    run.__doc__ = func.__doc__
    return run


def add_latency_arguments(parser):
    """Add the options of ``bench latency`` to ``parser``."""
    parser.add_argument('-n', '--count', type=int, default=50, metavar='N',
                        help='number of single-joint faults (default 50)')
    parser.add_argument('--joints', nargs='+', metavar='JOINT',
                        help='joints to fault in turn (default: all 14)')
    parser.add_argument('--start-node', action='store_true',
                        help='start a private recovery_node for the benchmark')
    parser.add_argument('--json', action='store_true', help='print one JSON document')
    parser.add_argument('-v', '--verbose', action='store_true', help='print every sample')
    _common(parser, timeout=30.0)
    parser.set_defaults(func=_wrap(bench_latency))


def register_bench(bench_subparsers):
    """Add ``latency`` to the subparsers of a ``bench`` command."""
    p = bench_subparsers.add_parser(
        'latency', help='fault -> library latency against a running recovery_node')
    add_latency_arguments(p)
    return p


def register(subparsers):
    """Add the ROS subcommands (fault, clear, reconfigure, library, demo)."""
    p = subparsers.add_parser('fault', help='report failed joints to the running node')
    p.add_argument('joints', nargs='+', metavar='JOINT', help='failed joint, e.g. '
                   'right_arm_joint2')
    p.add_argument('--angle', type=float, nargs='+', metavar='DEG',
                   help="lock angle(s) in degrees, one per joint (default: the node's lock "
                        'strategy chooses)')
    _common(p)
    p.set_defaults(func=_wrap(cmd_fault))

    p = subparsers.add_parser('clear', help='forget every fault (/clear_faults)')
    _common(p)
    p.set_defaults(func=_wrap(cmd_clear))

    p = subparsers.add_parser('reconfigure',
                              help='call /reconfigure_gestures and print its summary')
    _common(p)
    p.set_defaults(func=_wrap(cmd_reconfigure))

    p = subparsers.add_parser('library', help='print the library received from '
                              '/gesture_library (degrees, locked joints marked)')
    p.add_argument('--json', action='store_true', help='print one JSON document (radians)')
    _common(p)
    p.set_defaults(func=_wrap(cmd_library))

    p = subparsers.add_parser('demo', help='start the node, inject a fault, show the '
                              'result, shut down')
    p.add_argument('joints', nargs='*', metavar='JOINT', default=[DEFAULT_FAULT],
                   help=f'failed joint(s) (default {DEFAULT_FAULT})')
    p.add_argument('--angle', type=float, nargs='+', metavar='DEG',
                   help='lock angle(s) in degrees (default: the lock strategy chooses)')
    p.add_argument('--out-dir', metavar='DIR', default='namo_demo',
                   help='where the stick figures go, one <gesture>.png each '
                        '(default ./namo_demo)')
    _common(p, timeout=30.0)
    p.set_defaults(func=_wrap(cmd_demo))
