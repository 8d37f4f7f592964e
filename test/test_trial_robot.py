"""
The player's trial robot without DDS: a fake arm and tracker feed it from a thread.

A trial commands a pose, waits for the move and the settling, and averages the tracker
readings captured *after* the settled reading (never one taken while the arm moved);
no readings is a one-line TrialTimeout; a reading of the other joints only is ignored.
"""

import threading
import time

from namo_fault_recovery.runtime.trial_robot import RosTrialRobot, TrialTimeout, TrialTiming
import numpy as np
import pytest

NAMES = ('a', 'b')
LIMITS = (np.full(2, -1.0), np.full(2, 1.0), np.full(2, 1.0))


class FakeArm:
    """Joints that jump to a command after its duration, a tracker at the tip = 100 q mm."""

    def __init__(self, tracker=True, wait=5.0):
        self.q = np.zeros(2)
        self.goal, self.until = np.zeros(2), 0.0
        self.robot = RosTrialRobot(NAMES, LIMITS, self.send, time.monotonic,
                                   TrialTiming(samples=3, tracker_wait_sec=wait))
        self.tracker, self.stop = tracker, threading.Event()
        self.moving_tips = 0
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def send(self, q, duration):
        self.goal, self.until = np.array(q), time.monotonic() + duration

    def _run(self):
        k = 0
        while not self.stop.wait(0.005):
            now = time.monotonic()
            moving = now < self.until
            v = np.full(2, 0.5) if moving else np.zeros(2)
            if not moving:
                self.q = self.goal.copy()
            self.robot.joint_state(now, ['x'], [9.0], [])          # not this arm's joints
            self.robot.joint_state(now, list(NAMES), list(self.q), list(v))
            k += 1
            if self.tracker and k % 3 == 0:
                tip = (np.append(self.q, 0.0) * 100.0) + (1000.0 if moving else 0.0)
                self.moving_tips += moving
                self.robot.fingertip(now, tip)


@pytest.fixture
def arm():
    fake = FakeArm()
    yield fake
    fake.stop.set()


def test_a_trial_measures_after_settling(arm):
    time.sleep(0.05)
    assert np.allclose(arm.robot.current(), 0.0)
    trial = arm.robot.trial(np.array([0.3, -0.2]), 0.1)
    assert np.allclose(trial.q, [0.3, -0.2])
    assert np.allclose(trial.tip, [30.0, -20.0, 0.0])    # no reading taken while moving
    assert arm.moving_tips > 0                             # though the tracker sent some
    assert trial.seconds >= 0.1


def test_no_tracker_is_a_one_line_timeout():
    fake = FakeArm(tracker=False, wait=0.3)
    try:
        time.sleep(0.05)
        with pytest.raises(TrialTimeout, match='0 of 3 tracker readings within 0.3 s'):
            fake.robot.trial(np.array([0.1, 0.1]), 0.05)
    finally:
        fake.stop.set()


def test_no_joint_states_is_a_timeout():
    robot = RosTrialRobot(NAMES, LIMITS, lambda q, d: None, time.monotonic)
    with pytest.raises(TrialTimeout, match='no /joint_states'):
        robot.current()


def test_a_bad_timing_is_refused():
    with pytest.raises(ValueError, match='exploration samples: 0'):
        TrialTiming(samples=0)
