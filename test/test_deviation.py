"""
Noticing a structure change: the physics plays a gesture, a noisy tracker watches it.

In process, on the simulator's clock (no DDS, no wall time): the player's plan is
commanded at every 2 ms step, joint states are fed at 100 Hz and tracker samples at
30 Hz with their 50 ms latency, stamped at capture.
"""

import math

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.benchmarks.notice import plan_from_rest, play_watched
from namo_fault_recovery.model.kinematics import forward_kinematics
from namo_fault_recovery.model.urdf import urdf_string
from namo_fault_recovery.playback.deviation import DeviationThresholds, DeviationWatch
from namo_fault_recovery.playback.timing import plan_motion
from namo_fault_recovery.resources import config_path, DEMO_MOTION_FILE
from namo_fault_recovery.sim.structure_change import apply_changes, parse_change
from namo_fault_recovery.sim.tracker import TrackerSettings
import numpy as np
import pytest

ROBOT = load_robot()
LIBRARY = load_library(ROBOT, config_path(DEMO_MOTION_FILE))


def plan_of(gesture):
    return plan_from_rest(ROBOT, LIBRARY[gesture])


def play(gesture, changes=(), sigma=1.0, seed=0, stuck=None, dropout=0.0):
    """Play ``gesture`` on a changed copy; return (the watch, the first suspicion or None)."""
    urdf = apply_changes(urdf_string(ROBOT), [parse_change(c) for c in changes])
    watch, found = play_watched(ROBOT, plan_of(gesture), urdf,
                                TrackerSettings(sigma_mm=sigma, seed=seed, dropout=dropout),
                                stuck=stuck)
    return watch, (found[0] if found else None)


@pytest.mark.parametrize('gesture, sigma', [('wai', 1.0), ('bye', 4.0)])
def test_an_unchanged_robot_raises_no_alarm(gesture, sigma):
    watch, found = play(gesture, sigma=sigma, seed=11)
    assert found is None and not watch.suspected


def test_a_hidden_50_mm_tool_is_noticed_on_its_arm_with_its_size():
    watch, found = play('bye', ['tool:right_arm_fingertip_joint:50'], sigma=1.0)
    assert found is not None and found.side == 'right'
    assert list(watch.suspected) == ['right']
    assert 35.0 < found.error_mm < 55.0 and 40.0 < found.unexplained_mm < 55.0
    assert found.play_time < 1.0             # within the sustain window and a little
    assert 'right arm' in found.describe() and 'mm off its designed path' in found.describe()


def test_an_encoder_offset_is_noticed_through_noise_and_dropouts():
    _, found = play('bye', ['encoder_offset:right_arm_joint4:5'], sigma=4.0, dropout=0.2)
    assert found is not None and found.side == 'right' and found.unexplained_mm > 10.0


def test_a_stuck_joint_is_not_taken_for_a_structure_change():
    # bye moves the right shoulder a lot: stuck, the hand is far off the designed path,
    # but the measured joints explain where it is (the joint monitor's case).
    watch, found = play('bye', stuck=('right_arm_joint1', 0.0))
    assert found is None
    tip = watch.designed['right']
    assert np.max(np.linalg.norm(tip - tip[0], axis=1)) > 100.0


def test_samples_before_the_watched_part_are_ignored():
    plan = plan_of('bye')
    watch = DeviationWatch(ROBOT, plan, 0.0, DeviationThresholds(), begin=1.0)
    far = watch.designed['right'][0] + 200.0
    assert all(watch.fingertip('right', t, far) is None for t in np.arange(0.0, 1.0, 0.02))
    found = [watch.fingertip('right', t, far) for t in np.arange(1.0, 2.0, 0.02)]
    assert any(f is not None for f in found)        # from 1 s on, the same samples count


def test_the_designed_distance_allows_the_lag_window():
    watch = DeviationWatch(ROBOT, plan_of('bye'), 0.0, DeviationThresholds(lag_s=0.1))
    t = 1.0
    behind = watch.designed['right'][np.searchsorted(watch.times, t - 0.08)]
    assert watch.designed_distance('right', t, behind) < 1.0
    far = watch.designed['right'][np.searchsorted(watch.times, t - 0.5)]
    assert watch.designed_distance('right', t, far) > 10.0


def explored_bye(approach=0.0):
    """Return bye played 6 deg further on every joint, from ``approach`` deg further away."""
    gesture = LIBRARY['bye']
    frames = [np.concatenate([kf.right, kf.left]) + np.radians(6.0)
              for kf in gesture.keyframes]
    return plan_motion(ROBOT.joint_names,
                       np.full(len(ROBOT.joint_names), np.radians(6.0 - approach)),
                       [kf.time_from_start for kf in gesture.keyframes], frames,
                       list(ROBOT.velocity_limits) * 2)


def lagging_explored_play(offset_mm, lag=0.3, thresholds=DeviationThresholds(),
                          approach=0.0):
    """
    Watch an explored bye that runs ``lag`` s behind its command (a loaded machine).

    The played joints differ from the design's (the exploration's correction for a change
    the model does not know), and the true fingertip follows the designed path, plus
    ``offset_mm`` (a further change): the model explains none of it.  ``approach`` (deg)
    starts the played motion further from its first keyframe than the design, so its
    approach takes longer and every keyframe comes later.
    """
    design, played = plan_of('bye'), explored_bye(approach)
    span = np.ptp([kf.time_from_start for kf in LIBRARY['bye'].keyframes])  # as the player:
    watch = DeviationWatch(ROBOT, design, 0.0, thresholds, design.duration - span,  # not
                           played=played)                                # the approach
    names, found = list(ROBOT.joint_names), []
    for k, t in enumerate(np.arange(0.0, played.duration + 1.0, 0.01)):
        q = played.command_at(t - lag)
        watch.joint_state(t, names, q)
        if k % 3 == 0:      # the true arm: where the model puts it 6 deg back on every joint
            tip = forward_kinematics(ROBOT, q[:7] - np.radians(6.0), 'right').tip
            hit = watch.fingertip('right', t, tip + offset_mm)
            found += [hit] if hit else []
    return found


def test_an_arm_behind_its_command_is_watched_at_the_moment_it_is_at():
    # 0.3 s behind, the fingertip is tens of mm behind the designed point of the plan's
    # clock; read off the measured joints, the moment the arm is at matches the design.
    assert lagging_explored_play(np.zeros(3)) == []
    assert lagging_explored_play(np.zeros(3), thresholds=DeviationThresholds(max_lag_s=0.0))
    found = lagging_explored_play(np.array([0.0, 30.0, 0.0]))
    assert len(found) == 1 and found[0].side == 'right'
    assert 20.0 < found[0].error_mm < 35.0          # the nearest point of the path


def test_an_explored_version_timed_otherwise_is_watched_keyframe_for_keyframe():
    # Its approach is longer (from further away): every keyframe comes later than the
    # design's, and the design is read at the same keyframe, not at the same time.
    assert lagging_explored_play(np.zeros(3), lag=0.0, approach=30.0) == []
    design, played = plan_of('bye'), explored_bye(approach=30.0)
    watch = DeviationWatch(ROBOT, design, 0.0, played=played)
    assert played.waypoint_times[1] > design.waypoint_times[1] + 0.1      # later
    assert watch.design_time(played.waypoint_times[1]) == pytest.approx(
        design.waypoint_times[1])
    assert watch.design_time(played.duration + 0.5) == pytest.approx(design.duration + 0.5)


def test_bad_thresholds_are_one_line():
    with pytest.raises(ValueError, match='structure change threshold_mm'):
        DeviationThresholds(threshold_mm=-1.0)
    with pytest.raises(ValueError, match='share'):
        DeviationThresholds(share=math.inf)
