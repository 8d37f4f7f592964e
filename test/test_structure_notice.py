"""
Over DDS: ``namo_sim`` with a hidden 50 mm tool in the right hand, ``gesture_player``.

The test publishes the demo library itself (no recovery_node: nothing here may know the
tool).  It plays bye (the right hand waves) and checks the tracker's messages (frame,
capture stamps at the rate, noise against the opt-in ground truth) and the player's
``structure change suspected`` status, on the right arm and not on the unchanged left,
with its request on ``/structure_change`` (``on_structure_change:=adapt``).
"""

import threading

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from namo_fault_recovery.ros.fingertip_topics import measurement, TRACKER_QOS
from namo_fault_recovery.ros.sim_node import sim_command
from namo_fault_recovery.runtime.private_node import player_command
from node_harness import NodeProcess, ros_env, session_domain, TIMEOUT
import numpy as np
from player_harness import Recorder
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

pytestmark = pytest.mark.slow

DOMAIN = session_domain(1)       # modules run one after the other: the ids are reused
STATUS = 'gesture_player: structure change'


class TrackerRecorder(Recorder):
    """Recorder plus the tracker's and the simulator's ground-truth fingertips."""

    def setup(self):
        self.points = {}
        self.points_lock = threading.Lock()
        for side in ('right', 'left'):
            for kind, name in (('measured', f'/fingertip_tracker/{side}'),
                               ('truth', f'/namo_sim/ground_truth/{side}')):
                self.points[(kind, side)] = []
                self.node.create_subscription(
                    PointStamped, name, lambda msg, k=(kind, side): self._on_point(k, msg),
                    TRACKER_QOS)
        self.requests = []
        latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(DiagnosticStatus, '/structure_change',
                                      self.requests.append, latched)

    def _on_point(self, key, msg):
        with self.points_lock:
            self.points[key].append((msg.header.frame_id, *measurement(msg)))

    def suspicions(self):
        return [{kv.key: kv.value for kv in s.values} | {'message': s.message}
                for msg in list(self.diagnostics) for s in msg.status if s.name == STATUS]


@pytest.fixture(scope='module')
def world():
    env = ros_env(DOMAIN)
    sim = NodeProcess(DOMAIN, command=sim_command(), env=env,
                      args=['-p', 'hidden_tool_right_mm:=50.0',
                            '-p', 'publish_ground_truth:=true'])
    player = NodeProcess(DOMAIN, command=player_command(), env=env,
                         args=['-p', 'on_structure_change:=adapt'])
    arms = TrackerRecorder(DOMAIN)
    try:
        arms.wait(lambda: arms.states > 10 and arms.points[('measured', 'right')],
                  TIMEOUT, 'the simulator and its tracker')
        arms.publish_library(1)
        yield arms, sim, player
    finally:
        arms.close()
        codes = [proc.stop() for proc in (player, sim)]
        for proc, code in zip((player, sim), codes):
            assert code == 0, proc.describe()
        assert 'Traceback' not in player.stderr + player.stdout, player.describe()


def test_a_hidden_tool_is_tracked_and_noticed(world):
    arms, sim, player = world
    sim.wait_output('hidden from the planner: tool 50 mm at right_arm_fingertip_joint')
    # The play's own outcome is not the subject here: on a loaded machine the physics
    # may fall behind real time and the player then names a lagging joint.
    arms.play('bye', timeout=30.0)
    found = arms.wait(arms.suspicions, 5.0, 'a structure change status\n' + player.describe())
    assert [s['arm'] for s in found] == ['right'], found      # not the unchanged left arm
    assert 'structure change suspected: right arm' in found[0]['message']
    assert 35.0 < float(found[0]['error_mm']) < 55.0, found
    assert found[0]['on_structure_change'] == 'adapt' and found[0]['adapt'] == 'true'
    request = arms.wait(lambda: arms.requests, 5.0, 'the request on /structure_change')[0]
    assert {kv.key: kv.value for kv in request.values}['arm'] == 'right'
    with arms.points_lock:
        measured = list(arms.points[('measured', 'right')])
        truth = {stamp: p for _, stamp, p in arms.points[('truth', 'right')]}
    assert {frame for frame, _, _ in measured} == {'base_link'}
    stamps = np.array([stamp for _, stamp, _ in measured])
    assert np.median(np.diff(stamps)) == pytest.approx(1 / 30, abs=0.003)
    err = np.array([np.subtract(p, truth[s]) for _, s, p in measured if s in truth])
    assert len(err) > 100
    assert 0.7 < float(np.std(err)) < 1.3           # sigma 1 mm per axis, in mm here
    assert float(np.max(np.abs(err.mean(axis=0)))) < 0.3
    status = [s for msg in arms.diagnostics for s in msg.status
              if s.name == 'namo_sim: hidden structure']
    assert status and 'tool 50 mm' in status[-1].message


@pytest.mark.parametrize('args, words', [
    (["structure_changes:=['twist:right_arm_joint5:3']"], "kind 'twist'"),
    (["structure_changes:=['bend:no_such_joint:5']"],
     "copy of the planner's URDF): key 'no_such_joint': bend 5 deg at no_such_joint: no such"),
    (['hidden_tool_left_mm:=-5.0'], 'hidden_tool_left_mm'),
    (['tracker_rate_hz:=0.0'], 'tracker rate_hz'),
])
def test_a_bad_hidden_structure_is_a_one_line_error(args, words):
    process = NodeProcess(DOMAIN + 1, command=sim_command(),
                          args=[a for arg in args for a in ('-p', arg)])
    try:
        assert process.wait() == 1
    finally:
        process.stop()
    lines = [line for line in process.stderr.splitlines() if 'namo_sim: error' in line]
    assert len(lines) == 1 and words in lines[0], process.stderr
    assert 'Traceback' not in process.stderr
