"""
Deadline and latency of a running ``recovery_node`` while ``/joint_states`` streams.

The paper's 1 s deadline must hold on the robot, where the drivers stream joint states
at hundreds of Hz and other processes compete for the CPU.  For each condition (idle,
``/joint_states`` at each rate, the fastest rate plus a CPU burner on another core) and
each fault joint in turn (faults cleared between), the benchmark publishes the fault,
times the arrival of the new library on ``/gesture_library`` (client-observed latency),
calls ``/reconfigure_gestures`` and records the node's own figures for the library that
answer names (``wall_time_sec``, ``deadline_met``, ``success``, the summed
``<gesture>.score_after``) from ``/diagnostics``.

Everything goes over DDS to a real node process: the stream comes from a separate
publisher process (as a robot's drivers would), so it never shares the measuring
client's interpreter.  rclpy is imported only when the benchmark runs.
"""

import argparse
import contextlib
import json
import math
import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

from .spun_node import SpunNode

DEFAULT_RATES = (0, 100, 500)
DEFAULT_FAULTS = tuple(f'right_arm_joint{i}' for i in range(1, 8))
NODE_PREFIX = 'recovery_node: '
VERSION_RE = re.compile(r'\[library version (\d+), stamp (\d+)\.(\d+)\]')
SLACK_SEC = 0.020     # "within the deadline" allows this much over it (timer granularity)


class BenchError(Exception):
    """The benchmark could not run (node unreachable, a service failed to answer)."""


def reference_pose(robot=None, library=None):
    """
    Return ``(names, positions)``: the 14 arm joints at the library's first keyframe.

    That is the pose a robot standing ready to gesture reports on ``/joint_states``;
    names come from the robot model (right arm first).
    """
    from namo_fault_recovery import load_library, load_robot
    robot = robot or load_robot()
    library = library or load_library(robot)
    names = list(robot.joint_names)
    positions = [float(a) for a in library.gestures[0].keyframes[0].positions()]
    return names, positions


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
    parser = argparse.ArgumentParser(prog='namo_fault_recovery.ros.stream_bench')
    parser.add_argument('--rate', type=float, required=True)
    parser.add_argument('--domain-id', type=int, default=None)
    args = parser.parse_args(argv)
    import rclpy
    from rclpy.context import Context
    context = Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    node = rclpy.create_node(f'namo_joint_state_stream_{os.getpid()}', context=context)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGINT, lambda *_: done.set())
    names, positions = reference_pose()
    with JointStateStream(node, args.rate, names, positions) as stream:
        done.wait()
    sys.stdout.write(json.dumps({'sent': stream.sent,
                                 'rate_hz': round(stream.achieved_rate, 1)}) + '\n')
    node.destroy_node()
    rclpy.try_shutdown(context=context)
    return 0


class StreamProcess:
    """The stream publisher as a child process (a robot's drivers are other processes)."""

    def __init__(self, rate, domain_id):
        self.rate = rate
        cmd = [sys.executable, '-m', 'namo_fault_recovery.ros.stream_bench',
               '--rate', str(rate)]
        if domain_id is not None:
            cmd += ['--domain-id', str(domain_id)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     env=dict(os.environ, PYTHONUNBUFFERED='1'))
        self.report = {}

    def close(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            text, _ = self.proc.communicate(timeout=15)
            self.report = json.loads(text.decode().strip().splitlines()[-1])
        except (subprocess.TimeoutExpired, ValueError, IndexError):
            self.proc.kill()
            self.proc.wait()
        return self.report


class _Client:
    """An rclpy client of the node in its own context, spun in a background thread."""

    def __init__(self, domain_id):
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger
        from trajectory_msgs.msg import JointTrajectory

        self._joint_state = JointState
        self._trigger = Trigger
        self._spun = SpunNode(f'namo_stream_bench_{os.getpid()}', domain_id)
        self.node = self._spun.node
        self._cond = threading.Condition()
        self.versions = {}       # stamp ns -> {gesture: arrival time}
        self.diagnostics = []    # {status name: {key: value}}
        latched = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(JointTrajectory, '/gesture_library', self._on_library,
                                      latched)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 50)
        self.fault_pub = self.node.create_publisher(JointState, '/actuator_fault', 10)
        self._clients = {}
        self._spun.start()

    def close(self):
        """Stop spinning and shut the probe's context down."""
        self._spun.close()

    def _on_library(self, msg):
        now = time.monotonic()
        key = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self._cond:
            self.versions.setdefault(key, {})[msg.header.frame_id] = now
            self._cond.notify_all()

    def _on_diag(self, msg):
        statuses = {s.name[len(NODE_PREFIX):]: {kv.key: kv.value for kv in s.values}
                    for s in msg.status if s.name.startswith(NODE_PREFIX)}
        if statuses:
            with self._cond:
                self.diagnostics.append(statuses)
                self._cond.notify_all()

    def wait(self, predicate, timeout):
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

    def newest_complete(self, count, after=-1):
        """Return ``(stamp, arrival of its last gesture)`` of the newest full version."""
        for stamp in sorted(self.versions, reverse=True):
            if stamp <= after:
                return None
            if len(self.versions[stamp]) >= count:
                return stamp, max(self.versions[stamp].values())
        return None

    def diag_for(self, stamp_text):
        for statuses in reversed(self.diagnostics):
            values = statuses.get('reconfiguration', {})
            if values.get('library_stamp') == stamp_text:
                return values
        return None

    def publish_fault(self, joints, timeout):
        end = time.monotonic() + timeout
        while self.fault_pub.get_subscription_count() < 1:
            if time.monotonic() > end:
                raise BenchError('nobody subscribes to /actuator_fault; is the node running?')
            time.sleep(0.02)
        msg = self._joint_state(name=list(joints))
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.fault_pub.publish(msg)

    def trigger(self, service, timeout):
        client = self._clients.get(service)
        if client is None:
            client = self._clients[service] = self.node.create_client(self._trigger, service)
        if not client.wait_for_service(timeout_sec=timeout):
            raise BenchError(f'service {service} is not available within {timeout:g} s')
        done = threading.Event()
        future = client.call_async(self._trigger.Request())
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout):
            return None
        return future.result()


def _stamp_text(stamp):
    return f'{stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d}'


def _percentile(values, q):
    if not values:
        return math.nan
    ordered = sorted(values)
    rank = (len(ordered) - 1) * q / 100.0
    lo, hi = math.floor(rank), math.ceil(rank)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (rank - lo)


def _one_run(client, joint, count, timeout, last):
    """
    Clear, publish one fault, call /reconfigure_gestures; return the run's record.

    ``last`` is the stamp of the newest library version seen before: the clear's
    reference library is the first complete version after it, and the fault's library
    the first after that (so a late part of an earlier version is never taken for it).
    The record's ``last_stamp`` is the newest stamp seen at the end of the run.
    """
    record = {'joint': joint, 'last_stamp': last, 'answered': False, 'success': False,
              'deadline_met': False}
    cleared = client.trigger('/clear_faults', timeout)
    if cleared is None or not cleared.success:
        record['error'] = (f'/clear_faults: {cleared.message}' if cleared else
                           f'/clear_faults: no answer within {timeout:g} s')
        return record
    base = client.wait(lambda: client.newest_complete(count, after=last), timeout)
    if base is None:
        record['error'] = f'no reference library within {timeout:g} s of /clear_faults'
        return record
    record['last_stamp'] = base[0]
    t0 = time.monotonic()
    client.publish_fault([joint], timeout)
    got = client.wait(lambda: client.newest_complete(count, after=base[0]), timeout)
    record['latency_sec'] = got[1] - t0 if got else None
    if got:
        record['last_stamp'] = got[0]
    t1 = time.monotonic()
    answer = client.trigger('/reconfigure_gestures', timeout)
    record['service_sec'] = time.monotonic() - t1
    if answer is None:
        record['error'] = f'/reconfigure_gestures: no answer within {timeout:g} s'
        return record
    record.update(answered=True, success=bool(answer.success), message=answer.message)
    match = VERSION_RE.search(answer.message)
    if match is None:
        record['deadline_met'] = False
        return record
    record['library_version'] = int(match.group(1))
    stamp_text = f'{match.group(2)}.{match.group(3)}'
    record['last_stamp'] = max(record['last_stamp'], got[0] if got else 0,
                               int(match.group(2)) * 1_000_000_000 + int(match.group(3)))
    values = client.wait(lambda: client.diag_for(stamp_text), timeout)
    if values is None:
        record['deadline_met'] = 'deadline' in answer.message and 'met' in answer.message
        return record
    record['wall_time_sec'] = float(values['wall_time_sec'])
    if values.get('request_to_publish_sec'):
        # The span the deadline covers: from the request to the publication.
        record['request_to_publish_sec'] = float(values['request_to_publish_sec'])
    record['deadline_sec'] = float(values['deadline_sec'])
    record['deadline_met'] = values['deadline_met'] == 'true'
    record['node_success'] = values['success'] == 'true'
    afters = {k[:-len('.score_after')]: float(v) for k, v in values.items()
              if k.endswith('.score_after')}
    befores = {k[:-len('.score_before')]: float(v) for k, v in values.items()
               if k.endswith('.score_before')}
    record['scores_after'] = afters
    record['total_score'] = sum(afters.values())
    record['total_score_before'] = sum(befores.get(g, math.nan) for g in afters)
    if got is not None:
        fault_values = client.diag_for(_stamp_text(got[0]))
        if fault_values is not None:
            record['fault_run_wall_time_sec'] = float(fault_values['wall_time_sec'])
    return record


def summarise(runs, idle_score=None):
    """Return the figures of one condition's runs (see the module docstring)."""
    walls = [r['wall_time_sec'] for r in runs if 'wall_time_sec' in r]
    spans = [r['request_to_publish_sec'] for r in runs if 'request_to_publish_sec' in r]

    def span(r):
        return r.get('request_to_publish_sec', r['wall_time_sec'])

    within = sum(1 for r in runs if 'wall_time_sec' in r
                 and span(r) <= r['deadline_sec'] + SLACK_SEC)
    latencies = [r['latency_sec'] for r in runs if r.get('latency_sec') is not None]
    scores = [r['total_score'] for r in runs if 'total_score' in r]
    mean_score = sum(scores) / len(scores) if scores else math.nan
    return {
        'runs': len(runs),
        'answered': sum(1 for r in runs if r.get('answered')),
        'errors': sum(1 for r in runs if 'error' in r),
        'success': sum(1 for r in runs if r.get('success')),
        'deadline_met': sum(1 for r in runs if r.get('deadline_met') is True),
        'within_deadline_plus_20ms': within,
        'wall_worst_sec': max(walls) if walls else math.nan,
        'wall_p95_sec': _percentile(walls, 95),
        'span_worst_sec': max(spans) if spans else math.nan,
        'span_p95_sec': _percentile(spans, 95),
        'latency_p50_sec': _percentile(latencies, 50),
        'latency_p95_sec': _percentile(latencies, 95),
        'latency_lost': len(runs) - len(latencies),
        'mean_total_score': mean_score,
        'score_vs_idle_pct': (100.0 * (mean_score - idle_score) / idle_score
                              if idle_score else math.nan),
    }


def _conditions(rates, burner):
    conditions = [(('idle' if rate == 0 else f'{rate:g} Hz'), rate, False) for rate in rates]
    if burner:
        fastest = max(rates)
        conditions.append((f'{fastest:g} Hz + burner' if fastest else 'idle + burner',
                           fastest, True))
    return conditions


def _start_node(domain_id, state_dir, gesture_file, robot_file, out, node_params=()):
    from namo_fault_recovery.cli.private_node import node_command
    ros_args = ['-p', f'state_dir:={state_dir}']
    for param in node_params:
        ros_args += ['-p', param]
    if gesture_file:
        ros_args += ['-p', f'gesture_file:={os.path.abspath(gesture_file)}']
    if robot_file:
        ros_args += ['-p', f'robot_file:={os.path.abspath(robot_file)}']
    log = open(os.path.join(state_dir, 'node.log'), 'w+b')
    cmd = node_command() + ['--ros-args'] + ros_args
    out.write(f"starting the node: {' '.join(cmd)} (ROS_DOMAIN_ID={domain_id})\n")
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1')
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
    return proc, log


def _stop_node(proc, log):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    log.close()
    return proc.returncode


def _table(name, summary, deadline, out):
    out.write(f'\n== {name} ==\n')
    s = summary
    out.write(f"  runs within deadline + 20 ms : {s['within_deadline_plus_20ms']}/{s['runs']}"
              f"  (node's deadline_met {s['deadline_met']}/{s['runs']}, success "
              f"{s['success']}/{s['runs']}, answered {s['answered']}/{s['runs']}"
              + (f", {s['errors']} with a service or library missing" if s['errors'] else '')
              + ')\n')
    out.write(f"  engine wall time             : worst {s['wall_worst_sec'] * 1000:7.1f} ms"
              f"   p95 {s['wall_p95_sec'] * 1000:7.1f} ms   (deadline "
              f'{deadline * 1000:.0f} ms)\n')
    out.write(f"  request -> publish (node)    : worst {s['span_worst_sec'] * 1000:7.1f} ms"
              f"   p95 {s['span_p95_sec'] * 1000:7.1f} ms\n")
    out.write(f"  fault -> library latency     : p50 {s['latency_p50_sec'] * 1000:7.1f} ms"
              f"   p95 {s['latency_p95_sec'] * 1000:7.1f} ms"
              + (f"   ({s['latency_lost']} never arrived)" if s['latency_lost'] else '')
              + '\n')
    out.write(f"  mean total score (sum after) : {s['mean_total_score']:.3f}"
              + (f"   ({s['score_vs_idle_pct']:+.1f} % vs idle)"
                 if not math.isnan(s['score_vs_idle_pct']) else '') + '\n')


def run_stream_bench(out, rates=DEFAULT_RATES, burner=True, faults=DEFAULT_FAULTS, reps=1,
                     start_node=False, gesture_file=None, robot_file=None, domain_id=None,
                     node_params=(),
                     out_dir=None, timeout=60.0, verbose=False):
    """
    Run every condition against the node; print one table each; return the report dict.

    With ``start_node`` a private node (fresh state directory, ``gesture_file``) is
    started for the run and stopped at the end; otherwise the node already running in
    ``domain_id`` (default ``$ROS_DOMAIN_ID``) is measured.  ``out_dir`` receives
    ``stream_bench.json``.
    """
    from namo_fault_recovery.benchmarks.common import machine_info
    from namo_fault_recovery.benchmarks.deadline import CpuBurner
    rates = [float(r) for r in rates]
    if any(r < 0 for r in rates) or not rates:
        raise BenchError('--rates: expected one or more rates >= 0 (Hz)')
    proc = log = workdir = None
    if start_node:
        if domain_id is None:
            domain_id = 70 + os.getpid() % 30
        workdir = tempfile.mkdtemp(prefix='namo_stream_bench_')
        proc, log = _start_node(domain_id, workdir, gesture_file, robot_file, out,
                                node_params)
    report = {'machine': machine_info(), 'gesture_file': gesture_file or '(node default)',
              'faults': list(faults), 'reps': reps, 'slack_sec': SLACK_SEC,
              'conditions': {}}
    info = report['machine']
    out.write(f"machine: {info['cpus']} CPUs, load average {info['loadavg']}; gesture file "
              f"{report['gesture_file']}; faults {', '.join(faults)} x {reps}\n")
    client = None
    try:
        client = _Client(domain_id)
        first = client.wait(lambda: client.newest_complete(1), timeout)
        if first is None:
            raise BenchError(f'no recovery_node found: nothing on /gesture_library within '
                             f'{timeout:g} s')
        time.sleep(0.5)   # let the whole transient-local version arrive
        count = max(len(v) for v in client.versions.values())
        last = max(client.versions)
        idle_score = None
        for name, rate, burning in _conditions(rates, burner):
            stream = StreamProcess(rate, domain_id) if rate > 0 else None
            runs = []
            try:
                with (CpuBurner() if burning else contextlib.nullcontext()) as ctx:
                    time.sleep(1.0 if stream else 0.0)   # let the stream get matched
                    for _ in range(reps):
                        for joint in faults:
                            record = _one_run(client, joint, count, timeout, last)
                            last = record.pop('last_stamp')
                            runs.append(record)
                            if 'error' in record:
                                out.write(f"  {name}: {joint}: {record['error']}\n")
                            elif verbose:
                                wall = record.get('wall_time_sec', math.nan)
                                latency = record.get('latency_sec') or math.nan
                                out.write(f'  {name:<18} {joint:<18} wall {wall:.3f} s  '
                                          f'latency {latency:.3f} s  met '
                                          f"{record.get('deadline_met')}\n")
                    burner_cpu = ctx.cpu if burning else None
            finally:
                stream_report = stream.close() if stream else {}
            _ = client.trigger('/clear_faults', timeout)
            cleared = client.wait(lambda: client.newest_complete(count, after=last), timeout)
            last = cleared[0] if cleared else max(client.versions)
            summary = summarise(runs, idle_score)
            if name == 'idle':
                idle_score = summary['mean_total_score']
            deadline = next((r['deadline_sec'] for r in runs if 'deadline_sec' in r), 1.0)
            report['conditions'][name] = {'rate_hz': rate, 'burner': burning,
                                          'burner_cpu': burner_cpu, 'stream': stream_report,
                                          'summary': summary, 'runs': runs}
            _table(name + (f" (stream sent {stream_report.get('sent', '?')} msgs, "
                           f"{stream_report.get('rate_hz', '?')} Hz achieved)"
                           if stream else ''), summary, deadline, out)
    finally:
        if client is not None:
            client.close()
        if proc is not None:
            rc = _stop_node(proc, log)
            report['node_exit_code'] = rc
            shutil.rmtree(workdir, ignore_errors=True)
        if out_dir:   # also what was measured before an error
            path = Path(out_dir)
            path.mkdir(parents=True, exist_ok=True)
            target = path / 'stream_bench.json'
            target.write_text(json.dumps(report, indent=2, default=str))
            out.write(f'\nwrote {target}\n')
    return report


if __name__ == '__main__':
    sys.exit(stream_main())
