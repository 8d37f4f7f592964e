"""The parts of ``bench detection-suite``, tiny (one gesture, one joint; no DDS, no clock)."""

import io
import math

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.benchmarks import detection_suite as suite
from namo_fault_recovery.cli.main import main
import numpy as np
import pytest

ROBOT = load_robot()
LIBRARY = load_library(ROBOT)


def test_arrival_replays_lateness_in_order_after_the_goal_delay():
    arrival = suite.Arrival([0.010, 0.050, 0.0, 0.0], np.random.default_rng(3))
    times = [0.01 * k for k in range(1, 9)]
    receipts = [arrival.receipt(t) for t in times]
    assert all(b >= a for a, b in zip(receipts, receipts[1:]))   # a burst stays in order
    assert all(r >= t + arrival.goal_delay for r, t in zip(receipts, times))
    assert max(r - t for r, t in zip(receipts, times)) <= arrival.goal_delay + 0.050 + 1e-12
    on_time = suite.Arrival([], np.random.default_rng(0))
    assert on_time.receipt(0.5) == 0.5


def test_normal_and_stuck_plays_on_the_physics():
    pytest.importorskip('mujoco', reason='the simulator physics needs mujoco')
    from namo_fault_recovery.sim.physics import designed_allowances, NamoSim
    sim = NamoSim(ROBOT, allowances=designed_allowances(ROBOT, LIBRARY))
    sim.set_reading_noise(math.radians(0.1), seed=1)
    rng = np.random.default_rng(0)
    options = suite.SuiteOptions(reps=1)
    late = [0.006, 0.012, 0.030, 0.004]
    normal = suite.normal_play(sim, ROBOT, LIBRARY['salute'], suite.Arrival(late, rng),
                               options, rng)
    assert normal['ok'] and normal['faults'] == [] and normal['contact_events'] == 0
    assert 0.0 <= normal['score_gap'] < 1.0
    stuck = suite.stuck_play(sim, ROBOT, LIBRARY['salute'], 'right_arm_joint4',
                             suite.Arrival(late, rng), options, rng)
    assert stuck['detected'] and stuck['wrong_joints'] == []
    assert 0.0 < stuck['latency_s'] <= suite.TARGET_LATENCY_S
    doc = {'normal': {'salute': [normal]}, 'stuck': {'salute': {'right_arm_joint4': [stuck]}}}
    s = suite.summary(doc)
    assert (s['false_alarm_plays'], s['finished_within_goal_time'], s['detected']) == (0, 1, 1)
    assert s['latency_s']['within_target'] == 1


def test_lateness_from_a_missing_file_is_a_usage_error(tmp_path):
    out = io.StringIO()
    code = main(['bench', 'detection-suite', '--lateness-from', str(tmp_path / 'none.json'),
                 '--reps', '1'], out)
    assert code == 2
