"""
``namo-recovery`` subcommands around the ``gesture_player`` node.

``play`` and ``demo-play`` talk to the nodes through
:class:`~namo_fault_recovery.ros.player_client.PlayerClient` and
:class:`~namo_fault_recovery.ros.client.RecoveryClient`, imported only when they run,
so the rest of the command line works without ROS; ``bench detection`` and ``bench
carry-on`` run :mod:`namo_fault_recovery.benchmarks.detection` and
:mod:`namo_fault_recovery.benchmarks.carry_on`.
"""

import json
import math
import os
from pathlib import Path
import shutil
import time

import numpy as np

from .bench import add_detector_options, monitor_of
from .common import UsageError
from ..errors import EXIT_FAILURE
from ..runtime.private_node import node_command, player_command, read_log, start_logged
from ..runtime.private_node import stop_process


def cmd_play(args, out):
    """Play one gesture on a running gesture_player; exit 1 when the play failed."""
    from ..ros.player_client import PlayerClient
    with PlayerClient(args.domain_id) as player:
        ok, message = player.play(args.gesture, args.timeout)
    out.write(f"{'success' if ok else 'FAILURE'}: {message}\n")
    return 0 if ok else EXIT_FAILURE


def _common(parser, timeout):
    parser.add_argument('--timeout', type=float, default=timeout, metavar='SEC',
                        help=f'how long to wait (default {timeout:g} s)')
    parser.add_argument('--domain-id', type=int, default=None, metavar='N',
                        help='ROS domain id (default: $ROS_DOMAIN_ID, else 0)')


def add_case_filters(p):
    """Add ``--gesture`` and ``--joint``: the cases of a stuck-joint bench to run."""
    p.add_argument('--gesture', action='append', metavar='G',
                   help='only this gesture (repeatable; default: all)')
    p.add_argument('--joint', action='append', metavar='JOINT',
                   help='only stick this joint (repeatable; default: all 14)')


def register(subparsers, bench_subparsers):
    """Add ``play`` and ``demo-play``, and the ``detection`` and ``carry-on`` benchmarks."""
    p = subparsers.add_parser('play', help='play a gesture on the running gesture_player')
    p.add_argument('gesture', help='gesture name, e.g. wai')
    _common(p, 60.0)
    p.set_defaults(func=cmd_play)

    p = subparsers.add_parser('demo-play', help='the whole loop with the simulator: stick a '
                              'joint, play, detect, reconfigure, carry on, play again')
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
    add_case_filters(p)
    p.add_argument('--recover', action='append', metavar='G',
                   help='gestures whose detected faults are recovered and replayed '
                        '(repeatable; default: wai)')
    add_detector_options(p)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--json', action='store_true', help='print one JSON document')
    p.set_defaults(func=bench_detection)

    p = bench_subparsers.add_parser(
        'carry-on', help='a joint sticks mid-gesture: the time until the arm is back on the '
                         'reconfigured trajectory (simulator, MuJoCo, in process)')
    add_case_filters(p)
    p.add_argument('--busy', action='store_true',
                   help='a second pass with a CPU burner on the other core')
    p.add_argument('--acceleration-deg', type=float, default=600.0, metavar='DEG_S2',
                   help="blend acceleration limit (the player's acceleration_limit_deg)")
    p.add_argument('--deadline', type=float, default=1.0, metavar='SEC',
                   help="the engine's deadline (recovery_node's deadline_sec)")
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--json', action='store_true', help='print one JSON document')
    p.set_defaults(func=bench_carry_on)


def bench_detection(args, out):
    """Run the detection benchmark on the simulator's physics; print the figures."""
    from ..benchmarks import detection
    from ..model.gestures import load_library
    from ..model.robot import load_robot
    robot = load_robot(args.robot_file)
    library = load_library(robot, args.gesture_file)
    for name in (args.gesture or []) + (args.recover or []):
        if name not in library.names:
            raise UsageError(f'unknown gesture {name!r}; expected one of '
                             f'{", ".join(library.names)}')
    for joint in args.joint or []:
        if joint not in robot.joint_names:
            raise UsageError(f'--joint: unknown joint {joint!r}')
    monitor = monitor_of(args)
    doc = detection.run_on_sim(robot, library, gestures=args.gesture, joints=args.joint,
                               recover_gestures=args.recover or ('wai',), seed=args.seed,
                               monitor=monitor,
                               progress=None if args.json else (lambda s: out.write(s + '\n')))
    if args.json:
        out.write(json.dumps(doc, indent=2) + '\n')
    else:
        detection.write_summary(out, doc)
    return 0


def bench_carry_on(args, out):
    """Run the carry-on benchmark on the simulator's physics; print the figures."""
    from ..benchmarks import carry_on
    from ..model.gestures import load_library
    from ..model.robot import load_robot
    robot = load_robot(args.robot_file)
    library = load_library(robot, args.gesture_file)
    for name in args.gesture or []:
        if name not in library.names:
            raise UsageError(f'--gesture: unknown gesture {name!r}; expected one of '
                             f'{", ".join(library.names)}')
    for joint in args.joint or []:
        if joint not in robot.joint_names:
            raise UsageError(f'--joint: unknown joint {joint!r}')
    for option, value in (('--acceleration-deg', args.acceleration_deg),
                          ('--deadline', args.deadline)):
        if not (math.isfinite(value) and value > 0):
            raise UsageError(f'{option}: expected a number > 0, got {value}')
    progress = None if args.json else (lambda s: out.write(s + '\n'))
    docs = [carry_on.run_on_sim(robot, library, args.gesture, args.joint, busy, args.deadline,
                                args.seed, progress,
                                acceleration=math.radians(args.acceleration_deg))
            for busy in ((False, True) if args.busy else (False,))]
    for doc in docs:
        if not args.json:
            carry_on.write_summary(out, doc)
    if args.json:
        out.write(json.dumps(docs if args.busy else docs[0], indent=2) + '\n')
    return 0


# --- demo-play: the whole loop with the simulator -------------------------------------


def sim_command():
    """Return the command that starts ``namo_sim`` (imported lazily: no ROS at start)."""
    from ..ros.sim_node import sim_command as command
    return command()


def _start(name, command, ros_args, domain_id, workdir, out):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    cmd = list(command) + (['--ros-args'] + ros_args if ros_args else [])
    out.write(f'  starting {name}: {" ".join(cmd)}\n')
    return start_logged(command, ros_args, domain_id, Path(workdir) / f'{name}.log', env)


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


def _play_step(loop, gesture, timeout, label, out):
    since = time.monotonic()
    ok, message = loop.player.play(gesture, timeout)
    out.write(f'{label} /gesture_player/play/{gesture} -> '
              f"{'success' if ok else 'FAILURE'} after {time.monotonic() - since:.2f} s: "
              f'{message}\n')
    return ok, since


class _Loop:
    """What demo-play watches: the player and the arms, and the recovery node."""

    def __init__(self, domain_id, controllers):
        from ..ros.client import RecoveryClient
        from ..ros.player_client import PlayerClient
        self.player = PlayerClient(domain_id, controllers=controllers)
        self.recovery = RecoveryClient('/', domain_id)

    def close(self):
        self.recovery.close()
        self.player.close()

    def wait(self, predicate, timeout):
        from ..ros.spun_node import wait_until
        return wait_until(predicate, timeout, 0.05)

    def newest(self, gesture):
        """Return the newest library version (a PublishedLibrary) if it has ``gesture``."""
        library = self.recovery.newest_library()
        return library if library is not None and gesture in library.names else None

    def reconfiguration(self):
        """Return the values of recovery_node's newest ``reconfiguration`` status."""
        found = self.recovery.latest_diagnostics()
        return {} if found is None else found.values.get('reconfiguration', {})


def _angles(library, gesture, joint_names, k=-1):
    """Return keyframe ``k`` of ``gesture`` in a PublishedLibrary, in ``joint_names`` order."""
    q = library.result[gesture].positions[k]
    return np.array([q[library.joint_names.index(j)] for j in joint_names])


def cmd_demo_play(args, out):
    """Run recovery_node, namo_sim and gesture_player; stick a joint; play; recover."""
    import tempfile
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
    procs = [(name,) + _start(name, command, ros_args, domain, workdir, out)
             for name, command, ros_args in (
                 ('recovery_node', node_command(), ['-p', f'state_dir:={workdir}']),
                 ('namo_sim', sim_command(), ['-p', f'stuck_joints:=[{spec}]']),
                 ('gesture_player', player_command(), []))]
    loop = _Loop(domain, ('right_arm_controller', 'left_arm_controller'))
    code = 0
    try:
        code = _demo_steps(args, out, loop, robot, library, stuck)
    finally:
        loop.close()
        for name, proc, log in reversed(procs):
            rc, text = stop_process(proc), read_log(log)
            if rc != 0 or code:
                out.write(f'{name} exited with code {rc}; its log:\n{text}\n')
                code = code or EXIT_FAILURE
        shutil.rmtree(workdir, ignore_errors=True)
    return code


def _first_play(args, out, loop, stuck):
    """Run steps 2-5: the library and the stick; the first play; the faults it reported."""
    gesture, timeout = args.gesture, args.timeout
    first = loop.wait(lambda: loop.newest(gesture), timeout)
    if first is None:
        out.write(f'no /gesture_library within {timeout:g} s\n')
        return None
    out.write(f'2. library received from recovery_node ({loop.recovery.inbox.version_count()} '
              f'version)\n')
    measured = loop.wait(loop.player.latest_state, timeout)
    if measured is None:
        out.write(f'no /joint_states from namo_sim within {timeout:g} s\n')
        return None
    out.write('3. namo_sim publishes /joint_states; stuck: ' + ', '.join(
        f'{j} commanded to stay at {math.degrees(a):.1f} deg (measured '
        f'{math.degrees(measured.get(j, float("nan"))):.1f} deg)'
        for j, a in stuck.items()) + '\n')
    ok1, since1 = _play_step(loop, gesture, timeout, '4. play:', out)
    time.sleep(0.5)      # the arm coming to rest
    trace1 = loop.player.play_trace(since1)
    with loop.player.lock:
        faults = list(loop.player.faults)
    for _, msg in faults:
        out.write('5. /actuator_fault from the player: ' + ', '.join(
            f'{j} held at {math.degrees(a):.2f} deg' for j, a in zip(msg.name, msg.position))
            + '\n')
    if not faults:
        out.write('5. no fault reported (the gesture does not move the stuck joint '
                  'beyond the threshold)\n')
    return first, since1, trace1, loop.player.reported_locks()


def _await_reconfiguration(out, loop, gesture, first, locks, timeout):
    """Wait for the library that holds the reported locks (step 6); print its scores."""
    def reconfigured():
        found = loop.newest(gesture)
        if not found or found.stamp <= first.stamp or not locks:
            return None
        index = {j: found.joint_names.index(j) for j in locks}
        return all(abs(q[index[j]] - a) < 1e-9 for q in found.result[gesture].positions
                   for j, a in locks.items()) and found
    if not (locks and loop.wait(reconfigured, timeout)):
        return
    values = loop.wait(lambda: loop.reconfiguration().get('up_to_date') == 'true'
                       and loop.reconfiguration(), timeout) or {}
    version, wall = values.get('library_version', '?'), values.get('wall_time_sec', '?')
    before = values.get(f'{gesture}.score_before', '?')
    after = values.get(f'{gesture}.score_after', '?')
    out.write(f'6. recovery_node reconfigured the library (version {version}, {wall} s):'
              f' {gesture} score {before} -> {after}\n')


def _demo_steps(args, out, loop, robot, library, stuck):
    gesture, timeout, names = args.gesture, args.timeout, list(robot.joint_names)
    played = _first_play(args, out, loop, stuck)
    if played is None:
        return EXIT_FAILURE
    first, since1, trace1, locks = played
    _await_reconfiguration(out, loop, gesture, first, locks, timeout)
    ok2, since2 = _play_step(loop, gesture, timeout, '7. play again:', out)
    commands2, measured2 = loop.player.play_trace(since2)
    for joint, angle in locks.items():
        values = [c[joint] for _, c in commands2 if joint in c]
        elsewhere = sum(1 for v in values if v != angle)
        out.write(f'8. {joint}: {len(values)} commanded points, {elsewhere} away from '
                  f'{math.degrees(angle):.2f} deg\n')
    if measured2:
        q = np.array([measured2[-1][1].get(j, 0.0) for j in names])
        planned = _angles(loop.newest(gesture), gesture, names)
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
