"""
The detector's tracking model and its decisions, on synthetic readings (no ROS, no clock).

The "robot" here is the model itself with known numbers (a delay and a first-order lag)
plus noise, so each test knows what a healthy joint does and can make one stop.
"""

import math

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.playback.monitor import MonitorThresholds, Playback
from namo_fault_recovery.playback.timing import plan_motion
from namo_fault_recovery.playback.tracking import fit_tracking, predict, TrackingModel
import numpy as np
import pytest

ROBOT = load_robot()
LIBRARY = load_library(ROBOT)
NAMES = ROBOT.joint_names
LIMITS = np.array(ROBOT.velocity_limits * 2)
GROUPS = [NAMES[:7], NAMES[7:]]
RATE = 100.0
DELAY, TAU = 0.03, 0.04          # the synthetic controller's


def plan(name):
    g = LIBRARY[name]
    times = np.array([kf.time_from_start for kf in g.keyframes])
    frames = np.array([kf.positions() for kf in g.keyframes])
    return plan_motion(NAMES, np.zeros(14), times, frames, LIMITS)


def readings(p, delay=DELAY, tau=TAU, noise_deg=0.0, seed=0, extra=1.0):
    """Return the times and readings of a healthy controller (``delay``, ``tau``)."""
    t = np.arange(0.0, p.duration + extra, 1.0 / RATE)
    q = predict(p.command_at, t, p.positions[0], delay, tau)
    q += np.random.default_rng(seed).normal(0.0, math.radians(noise_deg), q.shape)
    return t, q


def first_outcome(playback, t, q):
    for ti, qi in zip(t, q):
        outcome = playback.update(ti, qi)
        if outcome is not None:
            return ti, outcome
    return None, None


def test_model_online_equals_batch_and_lags_a_ramp():
    def ramp(t):
        return np.stack([np.asarray(t, float), -2.0 * np.asarray(t, float)], axis=-1)
    model = TrackingModel(ramp, delay=0.02, time_constant=0.05, window=0.05)
    model.reset(0.0, [0.0, 0.0])
    t = np.arange(0.01, 1.0, 0.01)
    online = np.array([model.advance(ti) for ti in t])
    batch = predict(ramp, np.concatenate([[0.0], t]), [0.0, 0.0], 0.02, 0.05)[1:]
    assert np.allclose(online, batch, atol=1e-12)
    # a first-order lag behind a ramp settles at delay + tau behind it
    assert online[-1] == pytest.approx(ramp(t[-1] - 0.07), abs=1e-4)
    low, high = model.band()         # the prediction over the last 0.05 s
    assert low == pytest.approx([t[-1] - 0.12, -2.0 * (t[-1] - 0.07)], abs=1e-4)
    assert high == pytest.approx([t[-1] - 0.07, -2.0 * (t[-1] - 0.12)], abs=1e-4)


def test_fit_recovers_the_controllers_numbers():
    p = plan('bye')
    t, q = readings(p, noise_deg=0.05)
    delay, tau, worst = fit_tracking([(p.command_at, t, q)], delays=np.arange(0, 0.081, 0.01),
                                     time_constants=np.arange(0, 0.081, 0.01))
    assert (delay, tau) == (pytest.approx(DELAY), pytest.approx(TAU))
    assert worst < math.radians(0.3)          # the noise, not the model


@pytest.mark.parametrize('name', ['wai', 'bye', 'salute', 'side_invite'])
def test_healthy_noisy_lagging_controller_is_no_fault(name):
    """A controller 40 ms slower than modelled (inside the band) and noisy is healthy."""
    p = plan(name)
    monitor = MonitorThresholds(tracking_delay=DELAY, tracking_time_constant=TAU)
    for seed in range(3):
        t, q = readings(p, delay=DELAY + 0.04, noise_deg=0.3, seed=seed)
        playback = Playback(p, GROUPS, monitor)
        when, outcome = first_outcome(playback, t, q)
        assert playback.faults == [] and outcome is not None and outcome.ok, outcome


def test_unmodelled_lag_is_what_the_model_is_for():
    """The same slow controller with a model that assumes none: off by more than 2 deg."""
    p = plan('bye')
    t, q = readings(p, delay=0.2, tau=0.0)
    playback = Playback(p, GROUPS, MonitorThresholds())
    assert first_outcome(playback, t, q)[1].faults
    playback = Playback(p, GROUPS, MonitorThresholds(tracking_delay=0.2))
    assert first_outcome(playback, t, q)[1].ok


@pytest.mark.parametrize('joint', ['right_arm_joint1', 'right_arm_joint3', 'right_arm_joint4',
                                   'right_arm_joint6', 'right_arm_joint7'])
def test_stuck_joint_caught_within_0_3_s_of_leaving_its_command_by_2_deg(joint):
    p = plan('bye')
    j = NAMES.index(joint)
    t, q = readings(p, noise_deg=0.1)
    q[:, j] = 0.0 + np.random.default_rng(1).normal(0.0, math.radians(0.1), len(t))
    monitor = MonitorThresholds(tracking_delay=DELAY, tracking_time_constant=TAU)
    when, outcome = first_outcome(Playback(p, GROUPS, monitor), t, q)
    assert outcome is not None and not outcome.ok
    assert [f for f, _ in outcome.faults] == [joint]
    assert outcome.faults[0][1] == pytest.approx(0.0, abs=math.radians(0.5))
    departs = t[np.argmax(np.abs(p.command_at(t)[:, j]) > math.radians(2.0))]
    assert 0.0 < when - departs <= 0.3, (joint, when - departs)


def test_late_readings_in_a_burst_are_no_fault():
    """Readings held back 150 ms by a busy executor, then handled at once, are no fault."""
    p = plan('bye')
    t, q = readings(p, noise_deg=0.1)
    receipt = t.copy()
    for start in np.arange(1.0, p.duration, 0.5):     # a 150 ms stall every 0.5 s
        held = (t >= start) & (t < start + 0.15)
        receipt[held] = start + 0.15
    monitor = MonitorThresholds(tracking_delay=DELAY, tracking_time_constant=TAU)
    playback = Playback(p, GROUPS, monitor)
    when, outcome = first_outcome(playback, receipt, q)
    assert playback.faults == [] and outcome.ok, outcome


def test_a_sustained_late_stream_beyond_the_band_is_seen():
    """The band is what a late reading may be: every reading 150 ms late is a fault."""
    p = plan('bye')
    t, q = readings(p)
    monitor = MonitorThresholds(tracking_delay=DELAY, tracking_time_constant=TAU)
    when, outcome = first_outcome(Playback(p, GROUPS, monitor), t + 0.15, q)
    assert outcome is not None and outcome.faults


def test_thresholds_refuse_negative_model_numbers():
    with pytest.raises(ValueError, match='tracking_delay'):
        MonitorThresholds(tracking_delay=-0.01)
    with pytest.raises(ValueError, match='tracking_time_constant'):
        MonitorThresholds(tracking_time_constant=-1.0)
    with pytest.raises(ValueError, match='delay'):
        TrackingModel(lambda t: t, delay=-1.0)


def test_a_joint_moving_alone_among_small_corrections_is_caught():
    """From wai's end with left joint 1 jumped to 10 deg, the others correct 2-4 deg."""
    g = LIBRARY['wai']
    start = g.keyframes[-1].positions().copy()
    j = NAMES.index('left_arm_joint1')
    start[j] = math.radians(10.0)
    start[NAMES.index('left_arm_joint2')] += math.radians(3.0)
    frames = np.array([kf.positions() for kf in g.keyframes])
    p = plan_motion(NAMES, start, [kf.time_from_start for kf in g.keyframes], frames, LIMITS)
    t, q = readings(p, noise_deg=0.05)
    q[:, j] = math.radians(10.0)
    monitor = MonitorThresholds(tracking_delay=DELAY, tracking_time_constant=TAU)
    when, outcome = first_outcome(Playback(p, GROUPS, monitor), t, q)
    assert outcome is not None and [f for f, _ in outcome.faults] == ['left_arm_joint1']
