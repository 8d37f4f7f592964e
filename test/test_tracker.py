"""The fingertip tracker: noise, latency and capture stamps, rate, dropouts (seeded)."""

from namo_fault_recovery.model.robot import load_robot
from namo_fault_recovery.model.urdf import urdf_string
from namo_fault_recovery.sim.structure_change import apply_changes, hidden_changes
from namo_fault_recovery.sim.tracker import FingertipTracker, TrackerSettings, TrueFingertips
import numpy as np
import pytest

TRUTH = {'right': (100.0, -200.0, -300.0), 'left': (100.0, 200.0, -300.0)}
DT = 0.002       # the simulator's step


def run(settings, seconds):
    """Drive a tracker at the simulator's step for ``seconds``; return what it delivered."""
    tracker = FingertipTracker(settings, start=0.0)
    out = []
    for k in range(int(round(seconds / DT)) + 1):
        now = k * DT
        tracker.capture(now, TRUTH)
        out += [(now, m) for m in tracker.deliver(now)]
    return tracker, out


def test_noise_has_the_set_sigma_and_no_bias():
    _, out = run(TrackerSettings(sigma_mm=1.0, seed=3), 40.0)
    err = np.array([np.subtract(m.point_mm, TRUTH[m.side]) for _, m in out])
    assert len(err) > 2000
    assert np.allclose(err.std(axis=0), 1.0, atol=0.06)
    assert np.all(np.abs(err.mean(axis=0)) < 0.06)
    assert all(m.truth_mm == TRUTH[m.side] for _, m in out)


def test_a_seed_repeats_a_run_and_another_seed_does_not():
    a = [m.point_mm for _, m in run(TrackerSettings(seed=5), 1.0)[1]]
    b = [m.point_mm for _, m in run(TrackerSettings(seed=5), 1.0)[1]]
    c = [m.point_mm for _, m in run(TrackerSettings(seed=6), 1.0)[1]]
    assert a == b and a != c


def test_stamped_at_capture_delivered_after_the_latency_at_the_rate():
    _, out = run(TrackerSettings(latency_s=0.05, rate_hz=30.0), 3.0)
    right = [(now, m) for now, m in out if m.side == 'right']
    captures = np.array([m.capture for _, m in right])
    delivered = np.array([now for now, _ in right])
    # on the 30 Hz grid (to the 2 ms step), one per frame, none delivered early
    assert np.allclose(np.diff(captures), 1 / 30, atol=DT + 1e-9)
    assert np.all(delivered - captures >= 0.05 - 1e-9)
    assert np.all(delivered - captures < 0.05 + DT + 1e-9)
    assert len(right) == pytest.approx((3.0 - 0.05) * 30, abs=2)


def test_dropouts_lose_that_share_and_mark_nothing_else():
    tracker, out = run(TrackerSettings(dropout=0.3, seed=1), 30.0)
    kept = len(out) + tracker.pending
    assert tracker.dropped + kept == 2 * tracker.captured
    assert tracker.dropped / (2 * tracker.captured) == pytest.approx(0.3, abs=0.03)
    right = np.array([m.capture for _, m in out if m.side == 'right'])
    assert np.max(np.diff(right)) > 1.5 / 30        # a gap is what a dropout looks like


def test_a_late_caller_skips_frames_instead_of_bursting():
    tracker = FingertipTracker(TrackerSettings(rate_hz=10.0, latency_s=0.0), start=0.0)
    assert tracker.capture(0.0, TRUTH) == 2
    assert tracker.capture(0.35, TRUTH) == 2     # frames 0.1, 0.2 missed: one capture
    assert tracker.capture(0.36, TRUTH) == 0
    assert tracker.next_capture == pytest.approx(0.4)
    assert [m.capture for m in tracker.deliver(1.0)] == [0.0, 0.0, 0.35, 0.35]


@pytest.mark.parametrize('field, value', [('sigma_mm', -1.0), ('rate_hz', 0.0),
                                          ('dropout', 1.0), ('latency_s', float('nan'))])
def test_impossible_settings_are_one_line(field, value):
    with pytest.raises(ValueError, match=f'tracker {field}') as err:
        TrackerSettings(**{field: value})
    assert '\n' not in str(err.value)


def test_the_truth_is_the_changed_robot():
    robot = load_robot()
    nominal = urdf_string(robot)
    plain = TrueFingertips(apply_changes(nominal, []))
    changes = hidden_changes([''], {'right': 50.0, 'left': 0.0}, plain.fingertip_joints)
    assert [c.describe() for c in changes] == ['tool 50 mm at right_arm_fingertip_joint']
    tooled = TrueFingertips(apply_changes(nominal, changes))
    q = dict.fromkeys(robot.joint_names, 0.3)
    a, b = plain(q), tooled(q)
    assert plain.frame == 'base_link'
    assert np.linalg.norm(b['right'] - a['right']) == pytest.approx(50.0, abs=1e-6)
    assert np.allclose(b['left'], a['left'])
