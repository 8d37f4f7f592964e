"""
End to end over DDS: exploration on the robot through the nodes (issue 18).

``namo_sim`` with a hidden 50 mm tool in the right hand (tracker sigma 1 mm, its ground
truth published for this test only), ``recovery_node`` and ``gesture_player`` with the
demo library (the circle) and ``on_structure_change:=adapt``.  The circle is played; the
player notices the change on ``/structure_change``; its exploration runs on its own
after the play (trials on the simulated robot, measured by the tracker); the circle is
played again, as explored.  The replay's true fingertip (the simulator's ground truth)
keeps to the designed path within the issue's target (mean <= 3 mm, max <= 10 mm), and
the recovery node's parameters never held the tool.  ``recovery_node`` adopts the
player's outcome: ``/gesture_library`` carries an ``explored`` version scored by the
measured error, with the arm's correction.  The player and the node are then restarted:
the node republishes the explored version from its state file, the player keeps its own
from ``explore_state_file``, and the circle stays on its path.
Last, an exploration is started and ended by ``~/stop_exploration``, another by a new
``/actuator_fault``, each within one trial (and a play asked for meanwhile is refused);
a joint fault on the changed arm then gives a library searched on the corrected model,
whose circle keeps to its path on the tooled arm.
The figures (trials, robot seconds, the error before and after) are printed.
"""

import threading
import time

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from namo_fault_recovery.model.kinematics import forward_kinematics
from namo_fault_recovery.resources import config_path, DEMO_MOTION_FILE
from namo_fault_recovery.ros.fingertip_topics import measurement, TRACKER_QOS
from namo_fault_recovery.ros.sim_node import sim_command
from namo_fault_recovery.ros.spun_node import wait_until
from namo_fault_recovery.runtime.diagnostic_keys import format_stamp
from namo_fault_recovery.runtime.private_node import player_command
from node_harness import explore_domain, NodeProcess, ros_env, TIMEOUT
import numpy as np
from player_harness import LIBRARY, Recorder, ROBOT
import pytest
from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.parameter import parameter_value_to_python
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

pytestmark = pytest.mark.slow

DOMAIN = explore_domain()
EXPLORATION = 'gesture_player: exploration'
LAG = 0.1              # s a fingertip may lag its designed path (the structure watch's)
DEMO = str(config_path(DEMO_MOTION_FILE))


class ExploreRecorder(Recorder):
    """Recorder plus the true right fingertip and the player's structure requests."""

    def setup(self):
        self.truth = []
        self.truth_lock = threading.Lock()
        self.node.create_subscription(PointStamped, '/namo_sim/ground_truth/right',
                                      self._on_truth, TRACKER_QOS)
        self.requests = []
        latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(DiagnosticStatus, '/structure_change',
                                      self.requests.append, latched)

    def _on_truth(self, msg):
        with self.truth_lock:
            self.truth.append(measurement(msg))

    def exploration(self, state=None):
        """Return the player's newest exploration status values (with ``state``), or {}."""
        for msg in reversed(list(self.diagnostics)):
            for status in msg.status:
                if status.name == EXPLORATION:
                    values = {kv.key: kv.value for kv in status.values}
                    if state is None or values['state'] == state:
                        return dict(values, message=status.message)
                    return {}
        return {}

    def parameters(self, node):
        """Return {name: value} of every parameter of ``node``."""
        names = self._call(ListParameters, f'{node}/list_parameters',
                           ListParameters.Request()).result.names
        values = self._call(GetParameters, f'{node}/get_parameters',
                            GetParameters.Request(names=list(names))).values
        return dict(zip(names, (parameter_value_to_python(v) for v in values)))

    def _call(self, kind, name, request):
        client = self.node.create_client(kind, name)
        assert client.wait_for_service(timeout_sec=TIMEOUT), name
        future = client.call_async(request)
        assert wait_until(future.done, TIMEOUT), name
        return future.result()

    def call_async(self, name):
        """Call a std_srvs/Trigger service without waiting; return its future."""
        client = self.node.create_client(Trigger, name)
        assert client.wait_for_service(timeout_sec=TIMEOUT), name
        return client.call_async(Trigger.Request())

    def stopped_within_one_trial(self, stop):
        """Start ~/explore, wait for its first trials, ``stop()`` it; check it ended at once."""
        answer = self.call_async('/gesture_player/explore')
        running = self.wait(lambda: self.exploration('running'), 30.0, 'a running exploration')
        refused = self.play('circle', timeout=10.0)
        assert not refused.success and 'busy exploring' in refused.message, refused.message
        seen = int(self.exploration('running')['trials'])
        stop()
        assert wait_until(answer.done, 10.0), 'no answer from ~/explore after the stop'
        assert not answer.result().success and 'stopped' in answer.result().message
        final = self.exploration()
        assert final['state'] == 'stopped', final
        assert int(final['trials']) <= seen + 1, (seen, final)      # within one trial
        return int(running['trials']), int(final['trials'])

    def play_window(self, since):
        """
        Return (start, end) stamps of the circle itself in the play commanded after ``since``.

        The play's command (stamped at its time 0) approaches the first keyframe, then
        runs the circle's keyframe times: the circle is its last ``duration`` seconds.
        """
        with self.lock:
            msg = next(m for c, m in self.commands[since:] if c == 'right_arm_controller')
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        end = stamp + msg.points[-1].time_from_start.sec \
            + msg.points[-1].time_from_start.nanosec * 1e-9
        keyframes = LIBRARY['circle'].keyframes
        return end - (keyframes[-1].time_from_start - keyframes[0].time_from_start), end

    def errors(self, window):
        """Return the true fingertip's distances (mm) to the designed circle over ``window``."""
        start, end = window
        circle = LIBRARY['circle']
        design = circle.joint_matrix()[:, :7]
        tips = forward_kinematics(ROBOT, design, 'right').tip
        times = np.array([kf.time_from_start for kf in circle.keyframes])
        times = times - times[0] + start
        with self.truth_lock:
            samples = [(s, p) for s, p in self.truth if start <= s <= end]
        out = []
        for stamp, point in samples:
            t = np.linspace(stamp - LAG, stamp, 11)
            path = np.stack([np.interp(t, times, tips[:, k]) for k in range(3)], axis=1)
            out.append(float(np.min(np.linalg.norm(path - np.asarray(point), axis=1))))
        return np.array(out)


def explored_version(arms):
    """Return recovery_node's reconfiguration values if it publishes an explored version."""
    values = arms.reconfiguration()
    return values if values.get('library_origin') == 'explored' else {}


def faulted_version(arms):
    """Return the reconfiguration values once both joint 7 are locked in the newest version."""
    library, values = arms.client.newest_library(), arms.reconfiguration()
    if library is None or values.get('library_stamp') != format_stamp(library.stamp):
        return {}
    # The diagnostics can name a version before its last gesture (the circle, the
    # largest message) has reached the client (ci98): not there yet.
    q = (arms.newest_library() or {}).get('circle')
    if q is None:
        return {}
    locked = np.allclose(q[:, 6], 0.2) and np.allclose(q[:, 13], 0.0)
    return values if locked and values.get('up_to_date') == 'true' else {}


def start_recovery(state_dir):
    """Start recovery_node on the demo library, its state in ``state_dir``."""
    return NodeProcess(DOMAIN, state_dir=state_dir, env=ros_env(DOMAIN),
                       args=['-p', f'gesture_file:={DEMO}', '-p', 'contingency_table:=false'])


def start_player(kept):
    """Start gesture_player: the demo library's design, adapt on a change, kept in ``kept``."""
    return NodeProcess(DOMAIN, command=player_command(), env=ros_env(DOMAIN),
                       args=['-p', 'on_structure_change:=adapt', '-p', f'gesture_file:={DEMO}',
                             '-p', f'explore_state_file:={kept}'])


@pytest.fixture(scope='module')
def world(tmp_path_factory):
    env = ros_env(DOMAIN)
    kept = tmp_path_factory.mktemp('player') / 'explored.json'
    procs = {'sim': NodeProcess(DOMAIN, command=sim_command(), env=env, args=[
        '-p', 'hidden_tool_right_mm:=50.0', '-p', 'publish_ground_truth:=true',
        '-p', 'tracker_sigma_mm:=1.0']),
        'recovery': start_recovery(tmp_path_factory.mktemp('state')),
        'player': start_player(kept)}
    arms = ExploreRecorder(DOMAIN)
    try:
        arms.wait(lambda: (arms.newest_library() or {}).get('circle') is not None, TIMEOUT,
                  'the demo library')
        arms.wait(lambda: arms.states > 10 and arms.truth, TIMEOUT, 'the simulator')
        yield arms, procs, kept
    finally:
        arms.close()
        order = [procs[k] for k in ('player', 'recovery', 'sim')]
        codes = [proc.stop() for proc in order]
        for proc, code in zip(order, codes):
            assert code == 0, proc.describe()
        for proc in order[:2]:
            assert 'Traceback' not in proc.stderr + proc.stdout, proc.describe()


def test_the_circle_is_explored_on_the_robot_and_replayed_on_its_path(world):
    arms, procs, kept = world
    player = procs['player']
    began = time.monotonic()
    since = len(arms.commands)
    first = arms.play('circle', timeout=30.0)
    assert first.success, first.message
    before = arms.errors(arms.play_window(since))
    request = arms.wait(lambda: arms.requests, 5.0, '/structure_change\n' + player.describe())
    assert {kv.key: kv.value for kv in request[0].values}['arm'] == 'right'
    done = arms.wait(lambda: arms.exploration('done') or arms.exploration('failed'), 90.0,
                     'the exploration\n' + player.describe())
    explored_at = time.monotonic()
    assert done['state'] == 'done', done
    assert done['origin'] == 'explored' and done['arm'] == 'right', done
    # recovery_node adopts it: /gesture_library carries the explored version, scored as
    # the tracker measured it, and the arm's correction.
    adopted = arms.wait(lambda: explored_version(arms), 10.0,
                        'an explored version\n' + procs['recovery'].describe())
    assert abs(float(adopted['circle.score_after'])
               - float(done['measured_error_max_mm'])) <= 0.005, (adopted, done)
    assert adopted['corrections'].startswith('right: tip_offset'), adopted
    print(f'\nrecovery_node published the explored version {time.monotonic() - explored_at:.1f} s '
          f'after the exploration: circle {adopted["circle.score_before"]} -> '
          f'{adopted["circle.score_after"]} mm as measured; {adopted["corrections"]}')
    since = len(arms.commands)
    replay = arms.play('circle', timeout=30.0)
    assert replay.success, replay.message
    after = arms.errors(arms.play_window(since))
    print(f'\nexploration on the robot: {done["trials"]} trials at {done["typical_points"]} '
          f'typical points ({done["trials_per_point"]}), {done["robot_seconds"]} robot s; '
          f'measured {done["measured_error_mm"]} mm mean, {done["measured_error_max_mm"]} mm '
          f'max; true fingertip on the circle before: {before.mean():.2f} mm mean, '
          f'{before.max():.2f} max ({len(before)} samples); after: {after.mean():.2f} mm mean, '
          f'{after.max():.2f} max ({len(after)} samples); '
          f'{explored_at - began:.1f} s to explored, {time.monotonic() - began:.1f} s in all')
    assert before.mean() > 35.0, before.mean()          # the tool, unexplored
    assert len(after) > 100, len(after)
    assert after.mean() <= 3.0, after
    assert after.max() <= 10.0, after
    params = arms.parameters('/recovery_node')
    assert params['tool_length_mm'] == 0.0
    assert not [n for n, v in params.items() if 'hidden' in n or v == 50.0], params
    assert not [s for s in (player.stdout + player.stderr).splitlines()
                if 'structure change suspected' in s][1:], player.describe()   # once only
    # A restarted player and a restarted recovery_node (both at once) keep what was
    # learned: the node republishes the explored version and keeps the correction.
    assert kept.exists()
    for name in ('player', 'recovery'):
        assert procs[name].stop() == 0 and 'Traceback' not in procs[name].stderr, \
            procs[name].describe()
    arms.diagnostics.clear()
    procs['recovery'] = recovery = start_recovery(procs['recovery'].state_dir)
    procs['player'] = player = start_player(kept)
    player.wait_output('circle: explored version restored from')
    recovery.wait_output('and their library from')
    assert 'restored the measured right arm (tip_offset' in recovery.stderr, recovery.describe()
    arms.wait(lambda: explored_version(arms), 10.0, 'the explored version republished')
    since = len(arms.commands)
    again = arms.play('circle', timeout=30.0)
    assert again.success, again.message
    restarted = arms.errors(arms.play_window(since))
    print(f'after a restart of the player: {restarted.mean():.2f} mm mean, '
          f'{restarted.max():.2f} max ({len(restarted)} samples)')
    assert restarted.mean() <= 3.0 and restarted.max() <= 10.0, restarted
    assert not arms.exploration('running') and 'structure change' not in player.stderr
    # A stop request, then a new fault, each end an exploration within one trial; no play
    # while it runs.
    stop = arms.trigger('/gesture_player/stop_exploration')
    assert not stop.success and 'no exploration is running' in stop.message
    arms.stopped_within_one_trial(
        lambda: arms.trigger('/gesture_player/stop_exploration').success or pytest.fail())
    fault = arms.node.create_publisher(JointState, '/actuator_fault', 10)
    arms.stopped_within_one_trial(lambda: fault.publish(
        JointState(name=['left_arm_joint7'], position=[0.0])))
    # A joint fault that comes later on the changed arm: its library is searched on the
    # corrected model, so the circle stays on its path on the real (tooled) arm.
    fault.publish(JointState(name=['right_arm_joint7'], position=[0.2]))
    faulted = arms.wait(lambda: faulted_version(arms), 30.0, 'the library of both faults')
    assert faulted['corrections'].startswith('right: tip_offset'), faulted
    assert faulted['library_origin'] in ('deadline', 'refined'), faulted
    q = arms.newest_library()['circle'][:, :7]
    design = LIBRARY['circle'].joint_matrix()[:, :7]
    true = ROBOT.with_tool(50.0, 'right')            # the simulator's hidden tool
    off = np.linalg.norm(forward_kinematics(true, q, 'right').tip
                         - forward_kinematics(ROBOT, design, 'right').tip, axis=1)
    print(f'faulted library (right_arm_joint7 at 0.2 rad) on the tooled arm: '
          f'{off.mean():.2f} mm mean, {off.max():.2f} max')
    assert off.mean() <= 3.0 and off.max() <= 10.0, off
