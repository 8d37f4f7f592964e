"""
``namo-recovery`` subcommands around the ``gesture_player`` node.

rclpy is imported only when one of them runs, so the rest of the command line works
without ROS.
"""

import json
import math
from pathlib import Path
import shutil
import sys
import time

import numpy as np

from .common import UsageError

EXIT_FAILURE = 1


def player_command():
    """Return the command that starts the ``gesture_player`` executable."""
    beside = Path(sys.executable).parent / 'gesture_player'
    if beside.is_file():
        return [str(beside)]
    found = shutil.which('gesture_player')
    if found:
        return [found]
    return [sys.executable, '-m', 'namo_fault_recovery.ros.player_node']


def call_play(node, gesture, timeout, player='/gesture_player', spin=None):
    """
    Call ``<player>/play/<gesture>`` from an rclpy node; return (success, message).

    ``spin(timeout_sec)`` spins the node's executor; None when another thread spins it.
    """
    from std_srvs.srv import Trigger
    client = node.create_client(Trigger, f'{player}/play/{gesture}')
    try:
        end = time.monotonic() + timeout
        if not client.wait_for_service(timeout_sec=min(timeout, 10.0)):
            return False, f'no service {player}/play/{gesture}; is gesture_player running?'
        future = client.call_async(Trigger.Request())
        while not future.done() and time.monotonic() < end:
            if spin is None:
                time.sleep(0.02)
            else:
                spin(0.05)
        if not future.done():
            return False, f'no answer within {timeout:g} s'
        return future.result().success, future.result().message
    finally:
        node.destroy_client(client)


def cmd_play(args, out):
    """Play one gesture on a running gesture_player; exit 1 when the play failed."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    context = Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    node = rclpy.create_node('namo_recovery_play', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        ok, message = call_play(node, args.gesture, args.timeout,
                                spin=lambda t: executor.spin_once(timeout_sec=t))
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    out.write(f"{'success' if ok else 'FAILURE'}: {message}\n")
    return 0 if ok else EXIT_FAILURE


def _common(parser, timeout):
    parser.add_argument('--timeout', type=float, default=timeout, metavar='SEC',
                        help=f'how long to wait (default {timeout:g} s)')
    parser.add_argument('--domain-id', type=int, default=None, metavar='N',
                        help='ROS domain id (default: $ROS_DOMAIN_ID, else 0)')


def register(subparsers, bench_subparsers):
    """Add ``play`` and ``demo-play`` to the subcommands, ``detection`` to the benchmarks."""
    p = subparsers.add_parser('play', help='play a gesture on the running gesture_player')
    p.add_argument('gesture', help='gesture name, e.g. wai')
    _common(p, 60.0)
    p.set_defaults(func=cmd_play)

    p = subparsers.add_parser('demo-play', help='the whole loop with the simulator: stick a '
                              'joint, play, detect, reconfigure, play again')
    p.add_argument('--gesture', default='wai', help='gesture to play (default wai)')
    p.add_argument('--stuck', action='append', metavar='JOINT:DEG',
                   help='joint stuck in the simulator (repeatable; default '
                        'right_arm_joint2:-20.0)')
    p.add_argument('--plot', metavar='DIR', help='draw commanded and measured angles of '
                   'both plays into DIR (needs matplotlib)')
    _common(p, 60.0)
    p.set_defaults(func=cmd_demo_play, stuck=None)

    p = bench_subparsers.add_parser(
        'detection', help='stuck-joint detection, false alarms and recovery on the '
                          'simulator (MuJoCo, in process)')
    p.add_argument('--gesture', action='append', metavar='G',
                   help='only this gesture (repeatable; default: all)')
    p.add_argument('--joint', action='append', metavar='JOINT',
                   help='only stick this joint (repeatable; default: all 14)')
    p.add_argument('--recover', action='append', metavar='G',
                   help='gestures whose detected faults are recovered and replayed '
                        '(repeatable; default: wai)')
    p.add_argument('--threshold-deg', type=float, default=5.0)
    p.add_argument('--hold-sec', type=float, default=0.3)
    p.add_argument('--lag-sec', type=float, default=0.25)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--json', action='store_true', help='print one JSON document')
    p.set_defaults(func=bench_detection)


def bench_detection(args, out):
    """Run the detection benchmark on the simulator's physics; print the figures."""
    from ..benchmarks import detection
    from ..model.gestures import load_library
    from ..model.robot import load_robot
    from ..playback.monitor import MonitorSettings
    from ..sim.physics import designed_allowances, NamoSim
    robot = load_robot(args.robot_file)
    library = load_library(robot, args.gesture_file)
    for name in (args.gesture or []) + (args.recover or []):
        if name not in library.names:
            raise UsageError(f'unknown gesture {name!r}; expected one of '
                             f'{", ".join(library.names)}')
    for joint in args.joint or []:
        if joint not in robot.joint_names:
            raise UsageError(f'--joint: unknown joint {joint!r}')
    monitor = MonitorSettings(fault_threshold=math.radians(args.threshold_deg),
                              fault_hold=args.hold_sec, tracking_lag=args.lag_sec)
    allowances = designed_allowances(robot, library)
    began = time.monotonic()
    doc = detection.run(robot, library, lambda: NamoSim(robot, allowances=allowances),
                        gestures=args.gesture, joints=args.joint,
                        recover_gestures=args.recover or ('wai',), seed=args.seed,
                        monitor=monitor,
                        progress=None if args.json else (lambda s: out.write(s + '\n')))
    doc['summary'] = detection.summary(doc)
    doc['wall_time_s'] = time.monotonic() - began
    if args.json:
        out.write(json.dumps(doc, indent=2) + '\n')
        return 0
    s = doc['summary']
    out.write(f"\nthreshold {doc['threshold_deg']:g} deg for {doc['hold_sec']:g} s, lag "
              f"window {doc['tracking_lag_sec']:g} s, {doc['rate_hz']:g} Hz\n")
    out.write(f"normal plays: {s['normal_plays']}, finished {s['normal_finished']}, false "
              f"alarms {s['false_alarms']}, executed-vs-planned score gap max "
              f"{s['normal_score_gap_max']:.4f}\n")
    out.write(f"stuck joints: {s['stuck_runs']} runs, {s['exercised_runs']} where the "
              f"gesture moves the joint by > 1.5 x threshold: {s['exercised_detected']} "
              f"detected; detected in all {s['detected_total']}; wrong joint reported "
              f"{s['wrong_joint_reports']}\n")
    d = s['detection_after_departure_s']
    if d:
        out.write('detection time after the command leaves the stuck angle: median '
                  f"{d['median']:.2f} s, min {d['min']:.2f} s, max {d['max']:.2f} s "
                  f"(n={d['n']})\n")
    r = s['stuck_to_correct_play_s']
    out.write(f"recoveries: {s['recoveries']}, correct replays {s['replays_ok']}"
              + (f"; stuck joint -> first correct play: median {r['median']:.2f} s, max "
                 f"{r['max']:.2f} s" if r else '') + '\n')
    if s['recovered_score_gap_max'] is not None:
        out.write('replay executed-vs-library score gap max '
                  f"{s['recovered_score_gap_max']:.4f}; lock commanded elsewhere "
                  f"{s['lock_commanded_elsewhere']} times; self-contact events in "
                  f"replays {s['replay_contact_events']}\n")
    out.write(f"wall time {doc['wall_time_s']:.1f} s\n")
    return 0


# --- demo-play: the whole loop with the simulator -------------------------------------


def sim_command():
    """Return the command that starts ``namo_sim`` (imported lazily: no ROS at start)."""
    from ..ros.sim_node import sim_command as command
    return command()


class _LoopWatcher:
    """An rclpy node that records what the loop does (commands, states, faults, library)."""

    def __init__(self, domain_id, controllers):
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory
        import threading

        from ..ros.spun_node import SpunNode
        self._spun = SpunNode('namo_recovery_demo_play', domain_id)
        self.node = self._spun.node
        self.lock = threading.Lock()
        self.commands, self.states, self.faults = [], [], []
        self.versions, self.diagnostics = {}, []
        for controller in controllers:
            self.node.create_subscription(
                JointTrajectory, f'/{controller}/joint_trajectory',
                lambda msg, c=controller: self._add(self.commands, (c, msg)), 100)
        self.node.create_subscription(JointState, '/joint_states',
                                      lambda m: self._add(self.states, m), 100)
        self.node.create_subscription(JointState, '/actuator_fault',
                                      lambda m: self._add(self.faults, m), 10)
        latched = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(JointTrajectory, '/gesture_library',
                                      self._on_library, latched)
        self.node.create_subscription(DiagnosticArray, '/diagnostics',
                                      lambda m: self._add(self.diagnostics, m), 50)
        self._spun.start()

    def _add(self, where, item):
        with self.lock:
            where.append((time.monotonic(), item))

    def _on_library(self, msg):
        key = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self.lock:
            self.versions.setdefault(key, {})[msg.header.frame_id] = (time.monotonic(), msg)

    def close(self):
        """Shut the watcher down."""
        self._spun.close()

    def wait(self, predicate, timeout):
        """Wait until ``predicate()`` is truthy; return it, or None on timeout."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.lock:
                value = predicate()
            if value:
                return value
            time.sleep(0.05)
        return None

    def newest(self, gesture):
        """Return (stamp, msg) of ``gesture`` in the newest library version, or None."""
        for stamp in sorted(self.versions, reverse=True):
            if gesture in self.versions[stamp]:
                return stamp, self.versions[stamp][gesture][1]
        return None

    def recovery_values(self, status_name):
        """Return the key/values of recovery_node's newest status ``status_name``."""
        for _, msg in reversed(self.diagnostics):
            for status in msg.status:
                if status.name == f'recovery_node: {status_name}':
                    return {kv.key: kv.value for kv in status.values}
        return {}

    def play_trace(self, since):
        """
        Return (commands, measured) as lists of (t, {joint: angle}) after ``since``.

        A controller follows its latest trajectory: the points of one that a newer one
        replaced (the hold after a failed play) end where the newer one arrived.
        """
        commands, measured = [], []
        with self.lock:
            sent = [(t, c, m) for t, (c, m) in self.commands if t >= since]
            states = [(t, m) for t, m in self.states if t >= since]
        for i, (t, controller, msg) in enumerate(sent):
            ends = [t2 for t2, c2, _ in sent[i + 1:] if c2 == controller]
            end = (ends[0] if ends else float('inf')) - since
            for p in msg.points:
                tp = t - since + p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                if tp <= end:
                    commands.append((tp, dict(zip(msg.joint_names, p.positions))))
        for t, msg in states:
            measured.append((t - since, dict(zip(msg.name, msg.position))))
        return sorted(commands, key=lambda c: c[0]), measured


def _start(name, command, ros_args, domain_id, workdir, out):
    import os
    import subprocess
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1',
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    log = open(Path(workdir) / f'{name}.log', 'w+b')
    cmd = list(command) + (['--ros-args'] + ros_args if ros_args else [])
    out.write(f'  starting {name}: {" ".join(cmd)}\n')
    return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env), log


def _stop(name, proc, log):
    import signal
    import subprocess
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    log.seek(0)
    text = log.read().decode(errors='replace')
    log.close()
    return proc.returncode, text


def _score_of(robot, library, gesture, q14):
    from ..objective.score import ScoreWeights, SimilarityScore
    g = library[gesture]
    scorer = SimilarityScore.for_gesture(robot, g, len(g.keyframes) - 1, ScoreWeights())
    return float(scorer(np.asarray(q14[:7]), np.asarray(q14[7:]))[0])


def _parse_stuck(robot, specs):
    stuck = {}
    for spec in specs:
        joint, sep, value = spec.partition(':')
        if joint not in robot.joint_names or not sep:
            raise UsageError(f'--stuck {spec}: expected JOINT:DEG with a joint of the robot, '
                             f'e.g. right_arm_joint2:-20.0')
        try:
            stuck[joint] = math.radians(float(value))
        except ValueError:
            raise UsageError(f'--stuck {spec}: DEG must be a number') from None
    return stuck


def _play_step(watcher, gesture, timeout, label, out):
    since = time.monotonic()
    ok, message = call_play(watcher.node, gesture, timeout)
    out.write(f'{label} /gesture_player/play/{gesture} -> '
              f"{'success' if ok else 'FAILURE'} after {time.monotonic() - since:.2f} s: "
              f'{message}\n')
    return ok, since


def cmd_demo_play(args, out):
    """Run recovery_node, namo_sim and gesture_player; stick a joint; play; recover."""
    import os
    import tempfile

    from .private_node import node_command
    from ..model.gestures import load_library
    from ..model.robot import load_robot
    robot = load_robot(args.robot_file)
    library = load_library(robot, args.gesture_file)
    if args.gesture not in library.names:
        raise UsageError(f'unknown gesture {args.gesture!r}; expected one of '
                         f'{", ".join(library.names)}')
    stuck = _parse_stuck(robot, args.stuck or ['right_arm_joint2:-20.0'])
    domain = args.domain_id if args.domain_id is not None else 40 + os.getpid() % 30
    workdir = tempfile.mkdtemp(prefix='namo_demo_play_')
    out.write(f'1. the loop, in ROS_DOMAIN_ID={domain} (logs in {workdir}):\n')
    spec = ', '.join(f"'{j}:{math.degrees(a):.1f}'" for j, a in stuck.items())
    procs = [('recovery_node',) + _start('recovery_node', node_command(),
                                         ['-p', f'state_dir:={workdir}'], domain, workdir,
                                         out),
             ('namo_sim',) + _start('namo_sim', sim_command(),
                                    ['-p', f'stuck_joints:=[{spec}]'], domain, workdir, out),
             ('gesture_player',) + _start('gesture_player', player_command(), [], domain,
                                          workdir, out)]
    watcher = _LoopWatcher(domain, ('right_arm_controller', 'left_arm_controller'))
    code = 0
    try:
        code = _demo_steps(args, out, watcher, robot, library, stuck)
    finally:
        watcher.close()
        for name, proc, log in reversed(procs):
            rc, text = _stop(name, proc, log)
            if rc != 0 or code:
                out.write(f'{name} exited with code {rc}; its log:\n{text}\n')
                code = code or EXIT_FAILURE
        shutil.rmtree(workdir, ignore_errors=True)
    return code


def _demo_steps(args, out, watcher, robot, library, stuck):
    gesture, timeout, names = args.gesture, args.timeout, list(robot.joint_names)
    first = watcher.wait(lambda: watcher.newest(gesture), timeout)
    if first is None:
        out.write(f'no /gesture_library within {timeout:g} s\n')
        return EXIT_FAILURE
    out.write(f'2. library received from recovery_node ({len(watcher.versions)} version)\n')
    if watcher.wait(lambda: watcher.states, timeout) is None:
        out.write(f'no /joint_states from namo_sim within {timeout:g} s\n')
        return EXIT_FAILURE
    measured = dict(zip(watcher.states[-1][1].name, watcher.states[-1][1].position))
    out.write('3. namo_sim publishes /joint_states; stuck: ' + ', '.join(
        f'{j} commanded to stay at {math.degrees(a):.1f} deg (measured '
        f'{math.degrees(measured.get(j, float("nan"))):.1f} deg)'
        for j, a in stuck.items()) + '\n')
    ok1, since1 = _play_step(watcher, gesture, timeout, '4. play:', out)
    time.sleep(0.5)      # the hold after a failed play, and the arm coming to rest
    trace1 = watcher.play_trace(since1)
    for _, msg in watcher.faults:
        out.write('5. /actuator_fault from the player: ' + ', '.join(
            f'{j} held at {math.degrees(a):.2f} deg' for j, a in zip(msg.name, msg.position))
            + '\n')
    if not watcher.faults:
        out.write('5. no fault reported (the gesture does not move the stuck joint '
                  'beyond the threshold)\n')
    locks = {j: a for _, m in watcher.faults for j, a in zip(m.name, m.position)}

    def reconfigured():
        found = watcher.newest(gesture)
        if not found or found[0] <= first[0] or not locks:
            return None
        msg = found[1]
        return all(abs(p.positions[list(msg.joint_names).index(j)] - a) < 1e-9
                   for p in msg.points for j, a in locks.items()) and found
    if locks and watcher.wait(reconfigured, timeout):
        values = watcher.wait(lambda: watcher.recovery_values('reconfiguration').get(
            'up_to_date') == 'true' and watcher.recovery_values('reconfiguration'), timeout)
        values = values or {}
        version, wall = values.get('library_version', '?'), values.get('wall_time_sec', '?')
        before = values.get(f'{gesture}.score_before', '?')
        after = values.get(f'{gesture}.score_after', '?')
        out.write(f'6. recovery_node reconfigured the library (version {version}, {wall} s):'
                  f' {gesture} score {before} -> {after}\n')
    ok2, since2 = _play_step(watcher, gesture, timeout, '7. play again:', out)
    commands2, measured2 = watcher.play_trace(since2)
    for joint, angle in locks.items():
        values = [c[joint] for _, c in commands2 if joint in c]
        elsewhere = sum(1 for v in values if v != angle)
        out.write(f'8. {joint}: {len(values)} commanded points, {elsewhere} away from '
                  f'{math.degrees(angle):.2f} deg\n')
    if measured2:
        q = np.array([measured2[-1][1].get(j, 0.0) for j in names])
        found = watcher.newest(gesture)[1]
        order = [list(found.joint_names).index(j) for j in names]
        planned = np.array([found.points[-1].positions[i] for i in order])
        executed = _score_of(robot, library, gesture, q)
        designed = _score_of(robot, library, gesture, planned)
        out.write(f'9. executed final pose scores {executed:.4f}; the library keyframe '
                  f'{designed:.4f}\n')
    if ok2:
        out.write(f'10. from the first play request to the end of the first correct play: '
                  f'{time.monotonic() - since1:.2f} s\n')
    if args.plot:
        _demo_plots(args, out, names, gesture, trace1, (commands2, measured2), locks)
    return 0 if ok2 else EXIT_FAILURE


def _demo_plots(args, out, names, gesture, first, second, locks):
    import importlib.util
    if importlib.util.find_spec('matplotlib') is None:
        out.write("plots skipped: matplotlib is not installed (pip install -e '.[plot]')\n")
        return
    from ..playback.plot import plot_play
    Path(args.plot).mkdir(parents=True, exist_ok=True)
    for (commands, measured), suffix, title in (
            (first, '1_fault', 'first play (stuck joint)'),
            (second, '2_replay', 'after reconfiguration')):
        path = Path(args.plot) / f'{gesture}_{suffix}.png'
        plot_play(path, names, commands, measured, f'{gesture}: {title}', locks)
        out.write(f'figure saved: {path}\n')
