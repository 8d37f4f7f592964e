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
    """Add ``play`` to the subcommands and ``detection`` to the benchmarks."""
    p = subparsers.add_parser('play', help='play a gesture on the running gesture_player')
    p.add_argument('gesture', help='gesture name, e.g. wai')
    _common(p, 60.0)
    p.set_defaults(func=cmd_play)

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
