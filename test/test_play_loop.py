"""
The whole loop over DDS: the real ``recovery_node`` and ``gesture_player`` processes.

The arms are ``player_harness.FakeArms`` (kinematic controllers in the test process).
A joint is stuck; playing wai detects it and reports it on /actuator_fault, the node
reconfigures the library, and the same play carries on with the reconfigured wai: once
the fault is known the stuck joint is never commanded away from its angle, and the
executed key pose scores as the version it carried on with says.  wai is played again
on the new library, the joint held at its lock.  Two faults in sequence: a right-arm
joint, then a left-arm joint on top of it.
"""

import math

from namo_fault_recovery.objective.score import ScoreWeights, SimilarityScore
from namo_fault_recovery.runtime.private_node import player_command
from node_harness import NodeProcess, ros_env, session_domain, TIMEOUT
import numpy as np
from player_harness import FakeArms, LIBRARY, NAMES, ROBOT
import pytest

pytestmark = pytest.mark.slow

DOMAIN = session_domain(0)       # modules run one after the other: the ids are reused
SCORE_TOL = 0.05     # the fake arms track exactly: only the goal tolerance is left
WAI = SimilarityScore.for_gesture(ROBOT, LIBRARY['wai'], 0, ScoreWeights())


@pytest.fixture(scope='module')
def loop(tmp_path_factory):
    recovery = NodeProcess(DOMAIN, state_dir=tmp_path_factory.mktemp('state'))
    player = NodeProcess(DOMAIN, command=player_command(), env=ros_env(DOMAIN))
    arms = FakeArms(DOMAIN)
    try:
        arms.wait(lambda: (arms.newest_library() or {}).get('wai') is not None, TIMEOUT,
                  'the reference library')
        yield arms
    finally:
        arms.close()
        codes = [proc.stop() for proc in (player, recovery)]    # all stopped, then checked
        for proc, code in zip((player, recovery), codes):
            assert code == 0, proc.describe()
            assert 'Traceback' not in proc.stderr + proc.stdout, proc.describe()


def _score(q):
    return float(WAI(q[:7], q[7:])[0])


def _stick_and_recover(arms, joint, angle, locked):
    """Stick ``joint`` at ``angle``; play wai (it carries on), then again; check both."""
    with arms.lock:
        arms.stuck[joint] = angle
    faults, before = len(arms.faults), len(arms.commands)
    response = arms.play('wai')
    assert response.success and 'carried on' in response.message, response.message
    assert joint in response.message, response.message
    report = arms.wait(lambda: arms.faults[faults:], 5.0, '/actuator_fault')[-1]
    assert list(report.name) == [joint]
    assert report.position[0] == pytest.approx(angle, abs=math.radians(0.5))
    # the original motion, then the hold and the blend: the joint where it is held
    count, held = arms.commanded_after_first(before, joint)
    assert count == 3 and held.size > 10 and np.all(held == report.position[0]), held
    library, version = arms.carried_on_with(response.message)
    assert version['wai'][-1][NAMES.index(joint)] == report.position[0]
    executed = _score(arms.settled())
    assert executed == pytest.approx(_score(version['wai'][-1]), abs=SCORE_TOL)
    if library.described:
        assert _score(version['wai'][-1]) == pytest.approx(library.result['wai'].score_after,
                                                           rel=1e-4)
    locked = dict(locked, **{joint: report.position[0]})

    arms.wait_locked_library('wai', locked, TIMEOUT)
    before = len(arms.commands)
    response = arms.play('wai')
    assert response.success, response.message
    for j, a in locked.items():
        commanded = arms.commanded(before, j)
        assert commanded.size > 10 and np.all(commanded == a), (j, commanded)
    q = arms.settled()      # the final pose, once the arm came to rest
    executed = float(WAI(q[:7], q[7:])[0])
    library = arms.wait(lambda: arms.library_score('wai'), TIMEOUT, 'the diagnostics')
    planned = float(WAI(*np.split(arms.newest_library()['wai'][-1], 2))[0])
    assert planned == pytest.approx(library, rel=1e-4)
    assert executed == pytest.approx(library, abs=SCORE_TOL)
    return locked


def test_stuck_joints_detected_reported_carried_on_and_played_around(loop):
    arms = loop
    # a right-arm joint, then a left-arm joint on top of it: both arms, and two faults
    # one after the other (the second reconfiguration keeps the first lock)
    locked = _stick_and_recover(arms, 'right_arm_joint2', math.radians(-20.0), {})
    _stick_and_recover(arms, 'left_arm_joint1', math.radians(10.0), locked)
