"""
End to end over DDS: ``namo_sim`` (MuJoCo), ``recovery_node`` and ``gesture_player``.

A fresh state directory; right_arm_joint2 stuck at -20 deg in the simulator from the
start.  Playing wai detects and reports the fault, the library is reconfigured, and wai
is played again: the stuck joint is never commanded away from its held angle (every
published command is recorded), the executed key pose from /joint_states scores within
a small tolerance of the library's own score for wai, and the simulator counts no
self-contact during the replay.  Then the same with a left-arm joint, and with two
faults one after the other (one test, the three scenarios in sequence).
"""

import math

from diagnostic_msgs.msg import DiagnosticArray
from namo_fault_recovery.objective.score import ScoreWeights, SimilarityScore
from namo_fault_recovery.ros.sim_node import sim_command
from namo_fault_recovery.runtime.private_node import player_command
from node_harness import NodeProcess, ros_env, session_domain, TIMEOUT
import numpy as np
from player_harness import LIBRARY, NAMES, Recorder, ROBOT
import pytest
from sensor_msgs.msg import JointState

pytestmark = pytest.mark.slow

DOMAIN = session_domain(0)       # modules run one after the other: the ids are reused
# The physics tracks within the goal tolerance (2 deg): the executed score may differ
# from the library's by that much.  bench detection measures up to 0.4 on these poses.
SCORE_TOL = 1.0
HELD_TOL = math.radians(0.5)     # the physics holds a stuck joint within this
WAI = SimilarityScore.for_gesture(ROBOT, LIBRARY['wai'], 0, ScoreWeights())


class SimRecorder(Recorder):
    """Recorder plus the simulator's contact reports and stick/release topics."""

    def setup(self):
        self.contacts = []
        self.node.create_subscription(DiagnosticArray, '/namo_sim/contacts',
                                      self._on_contacts, 10)
        self.stick_pub = self.node.create_publisher(JointState, '/namo_sim/stick', 10)
        self.release_pub = self.node.create_publisher(JointState, '/namo_sim/release', 10)

    def _on_contacts(self, msg):
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            with self.lock:
                self.contacts.append(values)

    def stick(self, joint, angle):
        self.wait(lambda: self.stick_pub.get_subscription_count() > 0, TIMEOUT, '~/stick')
        self.stick_pub.publish(JointState(name=[joint], position=[angle]))
        self.wait(lambda: self.contacts and f'{joint}:' in self.contacts[-1]['stuck'],
                  TIMEOUT, f'{joint} stuck')

    def release_all(self):
        self.release_pub.publish(JointState(name=NAMES))
        self.wait(lambda: self.contacts and not self.contacts[-1]['stuck'], TIMEOUT,
                  'every joint released')


@pytest.fixture(scope='module')
def loop(tmp_path_factory):
    env = ros_env(DOMAIN)
    sim = NodeProcess(DOMAIN, command=sim_command(), env=env,
                      args=['-p', "stuck_joints:=['right_arm_joint2:-20.0']"])
    recovery = NodeProcess(DOMAIN, state_dir=tmp_path_factory.mktemp('state'))
    player = NodeProcess(DOMAIN, command=player_command(), env=env)
    arms = SimRecorder(DOMAIN)
    try:
        arms.wait(lambda: (arms.newest_library() or {}).get('wai') is not None, TIMEOUT,
                  'the reference library')
        arms.wait(lambda: arms.states > 10 and arms.contacts, TIMEOUT, 'the simulator')
        yield arms
    finally:
        arms.close()
        codes = [proc.stop() for proc in (player, recovery, sim)]    # all stopped, then checked
        for proc, code in zip((player, recovery, sim), codes):
            assert code == 0, proc.describe()
        # namo_sim's physics thread may still print a traceback as it stops (its own
        # issue, seen in test_sim_node.py too); the nodes under test here must not.
        for proc in (player, recovery):
            assert 'Traceback' not in proc.stderr + proc.stdout, proc.describe()


def _stick_and_recover(arms, joint, angle, locked):
    """Play wai with ``joint`` stuck at ``angle``; check detection, recovery, replay."""
    faults = len(arms.faults)
    response = arms.play('wai', timeout=60.0)
    assert not response.success and joint in response.message, response.message
    report = arms.wait(lambda: arms.faults[faults:], 5.0, '/actuator_fault')[-1]
    assert list(report.name) == [joint]
    assert report.position[0] == pytest.approx(angle, abs=HELD_TOL)
    locked = dict(locked, **{joint: report.position[0]})

    arms.wait_locked_library('wai', locked, TIMEOUT)
    assert arms.trigger('/namo_sim/reset_contacts').success
    before, reports = len(arms.commands), len(arms.contacts)
    response = arms.play('wai', timeout=60.0)
    assert response.success, response.message
    for j, a in locked.items():
        commanded = arms.commanded(before, j)
        assert commanded.size > 10 and np.all(commanded == a), (j, commanded)
        assert abs(a - angle) <= HELD_TOL or j != joint
    # the final pose, once the arm came to rest: namo_sim's readings carry 0.02 deg of
    # noise (joint_state_noise_deg), two readings of a still arm differ by up to ~0.1 deg
    q = arms.settled(tol=math.radians(0.2))
    executed = float(WAI(q[:7], q[7:])[0])
    library = arms.wait(lambda: arms.library_score('wai'), TIMEOUT, 'the diagnostics')
    assert executed == pytest.approx(library, abs=SCORE_TOL), (executed, library)
    after = arms.wait(lambda: arms.contacts[reports + 1:], TIMEOUT, 'a contact report')
    assert after[-1]['contact_events'] == '0', after[-1]
    return locked


def test_stuck_joints_on_the_simulator(loop):
    arms = loop
    # right_arm_joint2, stuck at -20 deg since the simulator started
    _stick_and_recover(arms, 'right_arm_joint2', math.radians(-20.0), {})
    assert arms.trigger('/clear_faults').success
    arms.release_all()
    # a left-arm joint
    arms.stick('left_arm_joint1', math.radians(10.0))
    _stick_and_recover(arms, 'left_arm_joint1', math.radians(10.0), {})
    assert arms.trigger('/clear_faults').success
    arms.release_all()
    # two faults, one after the other
    arms.stick('right_arm_joint2', math.radians(-20.0))
    locked = _stick_and_recover(arms, 'right_arm_joint2', math.radians(-20.0), {})
    arms.stick('left_arm_joint1', math.radians(10.0))
    _stick_and_recover(arms, 'left_arm_joint1', math.radians(10.0), locked)
