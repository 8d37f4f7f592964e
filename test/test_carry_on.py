"""Carrying on through a stuck joint, free of ROS: resume, phase, blend and the play."""

import math

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.playback.blend import (blend, BlendLimits, phase_time, reachable,
                                                resume)
from namo_fault_recovery.playback.carry import CarryOn
from namo_fault_recovery.playback.monitor import MonitorThresholds
from namo_fault_recovery.playback.timing import plan_motion
import numpy as np
import pytest

ROBOT = load_robot()
LIBRARY = load_library(ROBOT)
NAMES = list(ROBOT.joint_names)
VELOCITY = np.array(ROBOT.velocity_limits * 2)
ACCEL = math.radians(600.0)
LIMITS = BlendLimits(VELOCITY, np.full(14, ACCEL))
GROUPS = [NAMES[:7], NAMES[7:]]
ELBOW = 'right_arm_joint4'


def arrays(name):
    g = LIBRARY[name]
    return (np.array([kf.time_from_start for kf in g.keyframes]),
            np.array([kf.positions() for kf in g.keyframes]))


def planner(times, frames, start, locks):
    return plan_motion(NAMES, start, times, frames, VELOCITY, locks=locks)


def reconfigured(name, joint, angle, shift=math.radians(10.0)):
    """Return the gesture with ``joint`` held at ``angle``, its neighbour moved (a stand-in)."""
    times, frames = arrays(name)
    frames = frames.copy()
    j = NAMES.index(joint)
    frames[:, j] = angle
    frames[:, j - 1] += shift
    return times, frames


def dense(motion, n=3000):
    t = np.linspace(0.0, motion.duration, n)
    return t, motion.command_at(t), motion.velocity_at(t), motion.acceleration_at(t)


def test_resume_follows_the_plan_from_its_instant_and_holds_joints():
    p = planner(*arrays('bye'), np.zeros(14), {})
    held = {ELBOW: 0.3}
    r = resume(p, 1.7, held)
    assert r.duration == pytest.approx(p.duration - 1.7)
    t = np.linspace(0.0, r.duration, 500)
    free = [i for i, j in enumerate(NAMES) if j != ELBOW]
    assert np.allclose(r.command_at(t)[:, free], p.command_at(1.7 + t)[:, free], atol=1e-12)
    assert np.all(r.positions[:, NAMES.index(ELBOW)] == 0.3)
    assert np.all(r.velocities[:, NAMES.index(ELBOW)] == 0.0)
    end = resume(p, p.duration + 1.0, held)       # past the end: the last pose, still
    assert np.allclose(end.command_at(0.02)[free], p.final[free])


def test_phase_maps_waypoint_to_waypoint_and_fractions_of_segments():
    a = planner(*arrays('bye'), np.zeros(14), {})
    b = planner(*reconfigured('bye', ELBOW, 0.4), np.zeros(14), {ELBOW: 0.4})
    assert len(a.waypoint_times) == len(b.waypoint_times)
    for ta, tb in zip(a.waypoint_times, b.waypoint_times):
        assert phase_time(a, b, ta) == pytest.approx(tb)
    middle = 0.5 * (a.waypoint_times[2] + a.waypoint_times[3])
    assert phase_time(a, b, middle) == pytest.approx(
        0.5 * (b.waypoint_times[2] + b.waypoint_times[3]))


@pytest.mark.parametrize('offset_deg', [3.0, 20.0, 45.0])
def test_blend_starts_measured_ends_on_the_target_within_the_limits(offset_deg):
    target = planner(*reconfigured('wai', ELBOW, 0.8), np.zeros(14), {ELBOW: 0.8})
    t0 = 0.9
    q0 = target.command_at(t0) + math.radians(offset_deg) * np.sign(np.arange(14) % 3 - 1)
    q0[NAMES.index(ELBOW)] = 0.8
    v0 = target.velocity_at(t0) + 0.3
    v0[NAMES.index(ELBOW)] = 0.0
    result = blend(target, t0, q0, v0, LIMITS, {ELBOW: 0.8})
    motion, duration = result.motion, result.duration
    assert duration > 0
    assert np.allclose(motion.command_at(0.0), q0) and np.allclose(motion.velocity_at(0.0), v0)
    t, q, v, a = dense(motion)
    after = t >= duration
    assert np.allclose(q[after], target.command_at(t0 + t[after]), atol=1e-9)
    assert motion.duration == pytest.approx(max(duration, target.duration - t0))
    assert np.all(np.abs(v) <= VELOCITY * 1.01)
    own = np.abs(target.acceleration_at(t0 + t))
    assert np.all(np.abs(a) <= np.maximum(ACCEL, own) * 1.05 + 0.05)
    assert np.all(motion.positions[:, NAMES.index(ELBOW)] == 0.8)


@pytest.mark.parametrize('offset_deg', [10.0, 90.0])
def test_blend_onto_a_still_target_is_time_optimal(offset_deg):
    """At rest, off by x on one joint: full acceleration, a coast at the limit if reached."""
    target = planner(*arrays('salute'), np.zeros(14), {})
    j, x = NAMES.index('right_arm_joint5'), math.radians(offset_deg)
    q0 = target.final.copy()
    q0[j] += x
    result = blend(target, target.duration, q0, np.zeros(14), LIMITS)
    motion, duration = result.motion, result.duration
    vmax = VELOCITY[j]
    if ACCEL * math.sqrt(x / ACCEL) <= vmax:
        best = 2 * math.sqrt(x / ACCEL)            # bang-bang
    else:
        best = x / vmax + vmax / ACCEL             # the speed limit reached: a coast
    assert duration == pytest.approx(best, rel=1e-6)
    t, q, v, a = dense(motion)
    assert np.max(np.abs(v[:, j])) == pytest.approx(min(vmax, math.sqrt(x * ACCEL)), rel=1e-2)
    assert np.max(np.abs(a[:, j])) <= ACCEL * (1 + 1e-6)
    assert np.allclose(q[-1], target.final, atol=1e-12)


def test_blend_with_nothing_to_correct_is_the_target_itself():
    target = planner(*arrays('salute'), np.zeros(14), {})
    result = blend(target, 1.0, target.command_at(1.0), target.velocity_at(1.0), LIMITS)
    motion, duration = result.motion, result.duration
    assert duration == 0.0
    t = np.linspace(0.0, motion.duration, 300)
    assert np.allclose(motion.command_at(t), target.command_at(1.0 + t), atol=1e-12)


def test_reachable_is_exact_for_a_rest_to_rest_move():
    """From rest to rest over x: reachable in exactly T iff T >= the time-optimal move."""
    vmax, x = 1.5, np.array([0.01, 0.3, 2.0])
    best = np.where(np.sqrt(x * ACCEL) <= vmax, 2 * np.sqrt(x / ACCEL), x / vmax + vmax / ACCEL)
    zero = np.zeros(3)
    assert np.all(reachable(zero, zero, x, zero, best * 1.001, ACCEL, vmax))
    assert not np.any(reachable(zero, zero, x, zero, best * 0.999, ACCEL, vmax))
    assert not np.any(reachable(zero, zero, -x, zero, best * 0.999, ACCEL, vmax))


def test_each_joint_rejoins_at_a_reachable_state_within_its_limits():
    """Random starts onto bye: every joint meets the target's position and speed, in limits."""
    target = planner(*arrays('bye'), np.zeros(14), {})
    rng = np.random.default_rng(3)
    for _ in range(20):
        t0 = rng.uniform(0.0, target.duration)
        q0 = target.command_at(t0) + rng.uniform(-0.6, 0.6, 14)
        v0 = rng.uniform(-1.0, 1.0, 14) * VELOCITY
        result = blend(target, t0, q0, v0, LIMITS, max_wait=1.0)
        assert result.duration > 0 and 0.0 <= result.wait <= 1.0
        t, q, v, a = dense(result.motion, 4000)
        assert np.allclose(q[0], q0) and np.allclose(v[0], v0)
        after = t >= result.duration
        on = t0 + np.maximum(t[after] - result.wait, 0.0)
        assert np.allclose(q[after], target.command_at(on), atol=1e-7)
        assert np.all(np.abs(v) <= np.maximum(VELOCITY, np.abs(v0)) * 1.001)
        own = np.abs(target.acceleration_at(t0 + np.maximum(t - result.wait, 0.0)))
        assert np.all(np.abs(a) <= np.maximum(ACCEL, own) * 1.01 + 1e-6)


def test_a_target_accelerating_beyond_the_limit_does_not_starve_the_blend():
    """
    Bye's wave accelerates past 600 deg/s^2: 10 deg off, the arm is back within 1 s.

    The blend that sized its correction by what the target left to spare found none
    within 10 s there.
    """
    target = planner(*arrays('bye'), np.zeros(14), {})
    t = np.linspace(0.0, target.duration, 2000)
    wave = np.max(np.abs(target.acceleration_at(t)), axis=1) > ACCEL
    t0 = float(t[np.argmax(wave)])
    assert np.any(wave)
    q0 = target.command_at(t0) + math.radians(10.0)
    result = blend(target, t0, q0, target.velocity_at(t0), LIMITS)
    assert 0.0 < result.duration < 1.0


def test_the_phase_waits_when_the_target_moves_away():
    """A joint far behind a target that runs away: waiting at the phase is back sooner."""
    target = planner(*arrays('salute'), np.zeros(14), {})
    t = np.linspace(0.0, target.duration, 2000)
    j = NAMES.index('right_arm_joint1')
    t0 = float(t[np.argmax(np.abs(target.velocity_at(t)[:, j]))])
    q0 = target.command_at(t0)
    q0[j] -= np.sign(target.velocity_at(t0)[j]) * 0.5        # behind it, at rest
    chase = blend(target, t0, q0, np.zeros(14), LIMITS)
    waited = blend(target, t0, q0, np.zeros(14), LIMITS, max_wait=1.0)
    assert chase.wait == 0.0 and waited.wait > 0.0
    assert waited.duration < chase.duration - 0.05


class Arm:
    """A kinematic arm: follows the last motion sent (no lag); stuck joints stay put."""

    def __init__(self, motion):
        self.motion, self.since, self.stuck, self.sent = motion, 0.0, {}, [(0.0, motion)]

    def at(self, t):
        q = self.motion.command_at(t - self.since)
        for joint, angle in self.stuck.items():
            q[NAMES.index(joint)] = angle
        return q

    def take(self, step, t):
        if step.send is not None:
            self.motion, self.since = step.send, t
            self.sent.append((t, step.send))


def drive(session, arm, stick_at, library_after=0.2, make_offer=None, faults_at=None):
    """
    Drive ``session`` at 100 Hz with ``arm``: the elbow sticks where it is at ``stick_at``.

    ``library_after`` s after the first fault, ``make_offer(holds)`` (if given) is offered
    (the library is made for the fault, so it is built then).  ``faults_at`` = (t, faults)
    reports faults from outside instead of the elbow sticking.  Return (outcome, faults
    detected, end time).
    """
    t, faults, offered_at = 0.0, [], None
    while t < 20.0:
        t = round(t + 0.01, 10)
        if stick_at is not None and t >= stick_at and ELBOW not in arm.stuck:
            arm.stuck[ELBOW] = float(arm.at(t)[NAMES.index(ELBOW)])
        if faults_at is not None and t >= faults_at[0]:
            arm.take(session.fault(t, faults_at[1]), t)
            faults_at, offered_at = None, t + library_after
        if offered_at is not None and t >= offered_at and make_offer is not None:
            assert session.offer(*make_offer(session.holds), 'test')
            offered_at = None
        step = session.update(t, arm.at(t))
        arm.take(step, t)
        if step.faults:
            faults += list(step.faults)
            offered_at = offered_at or t + library_after
        outcome = step.outcome or session.expire(t)
        if outcome is not None:
            return outcome, faults, t
    raise AssertionError('the play did not end')


def play(name='wai', wait=3.0):
    times, frames = arrays(name)
    plan = planner(times, frames, np.zeros(14), {})
    return plan, CarryOn(plan, GROUPS, MonitorThresholds(), planner, LIMITS, wait=wait), \
        Arm(plan)


def events(session, kind):
    return [when for when, k, _ in session.events if k == kind]


def test_a_stuck_joint_mid_play_carries_on_with_the_reconfigured_gesture():
    plan, session, arm = play()
    outcome, faults, end = drive(session, arm, 0.4 * plan.duration, 0.2,
                                 lambda holds: reconfigured('wai', ELBOW, holds[ELBOW]))
    assert outcome.ok, outcome.reason
    assert 'carried on' in outcome.reason and ELBOW in outcome.reason
    assert [j for j, _ in faults] == [ELBOW]
    assert faults[0][1] == pytest.approx(arm.stuck[ELBOW])
    # the same play, not started again; every motion after the fault holds the elbow
    (fault_at,), (switch,) = events(session, 'fault'), events(session, 'switch')
    later = [m for when, m in arm.sent if when >= fault_at]
    assert len(later) == 2          # the hold, then the blend onto the new gesture
    for motion in later:
        assert np.all(motion.positions[:, NAMES.index(ELBOW)] == arm.stuck[ELBOW])
    assert fault_at + 0.2 <= switch <= fault_at + 0.2 + 0.02
    assert session.back_at is not None and switch < session.back_at < switch + 1.5
    # it ends on the reconfigured keyframe, not where the old gesture ended
    _, goal = reconfigured('wai', ELBOW, arm.stuck[ELBOW])
    assert np.allclose(arm.at(end), goal[-1], atol=math.radians(2.0))
    assert not np.allclose(arm.at(end), plan.final, atol=math.radians(2.0))
    assert end < plan.duration + 2.0


def test_without_a_library_the_play_fails_after_the_wait_holding_the_joint():
    plan, session, arm = play(wait=0.5)
    outcome, faults, end = drive(session, arm, 0.4 * plan.duration)
    assert not outcome.ok and 'no reconfigured library' in outcome.reason
    assert outcome.faults == ((ELBOW, pytest.approx(arm.stuck[ELBOW])),)
    assert end == pytest.approx(events(session, 'fault')[0] + 0.5, abs=0.02)


def test_a_version_that_does_not_hold_the_joint_where_it_is_is_refused():
    plan, session, arm = play()
    t = 0.0
    while not session.waiting:
        t = round(t + 0.01, 10)
        if t >= 0.4 * plan.duration and ELBOW not in arm.stuck:
            arm.stuck[ELBOW] = float(arm.at(t)[NAMES.index(ELBOW)])
        arm.take(session.update(t, arm.at(t)), t)
    held = session.holds[ELBOW]
    assert not session.offer(*arrays('wai'))                          # the old one
    assert not session.offer(*reconfigured('wai', ELBOW, held + 0.1))  # locked elsewhere
    times, frames = reconfigured('bye', ELBOW, held)
    frames[1, NAMES.index(ELBOW)] += 0.01
    assert not session.offer(times, frames)                            # moves it
    assert session.offer(*reconfigured('wai', ELBOW, held))


def test_carry_on_off_ends_the_play_on_the_fault_as_before():
    plan, session, arm = play(wait=0.0)
    outcome, faults, _ = drive(session, arm, 0.4 * plan.duration)
    assert not outcome.ok and outcome.reason.startswith('actuator fault detected')
    assert [j for j, _ in faults] == [ELBOW]
    assert len(arm.sent) == 1          # nothing sent after the fault: the node holds


def test_a_fault_reported_by_someone_else_is_held_where_it_is():
    plan, session, arm = play()
    at = 0.5 * plan.duration
    where = float(plan.command_at(at)[NAMES.index('right_arm_joint3')])
    outcome, faults, _ = drive(
        session, arm, None, 0.1,
        lambda holds: reconfigured('wai', 'right_arm_joint3', holds['right_arm_joint3']),
        faults_at=(at, [('right_arm_joint3', where)]))
    assert outcome.ok and 'carried on' in outcome.reason, outcome.reason
    assert faults == []              # not the player's own detection: nothing to report
    for when, motion in arm.sent[1:]:
        assert np.all(motion.positions[:, NAMES.index('right_arm_joint3')] == where)


def test_carry_on_benchmark_case_on_the_physics():
    """One case of ``bench carry-on``: the elbow stuck mid-wai, carried on, held, back."""
    pytest.importorskip('mujoco', reason='the simulator physics needs mujoco')
    from namo_fault_recovery.benchmarks import carry_on
    from namo_fault_recovery.sim.physics import designed_allowances, NamoSim
    sim = NamoSim(ROBOT, allowances=designed_allowances(ROBOT, LIBRARY))
    bench = carry_on.Bench(ROBOT, LIBRARY, sim, carry_on.Reconfigurer(ROBOT, LIBRARY, 0.3))
    entry = bench.case('wai', ELBOW)
    assert entry['exercised'] and entry['ok'], entry['reason']
    assert 'carried on' in entry['reason']
    assert entry['detected_s'] < entry['switch_s'] < entry['back_s']
    assert entry['held_elsewhere'] == 0 and entry['wrong_joints'] == []
    assert entry['score_gap'] < 1.0
    assert sim.stuck and abs(sim.positions()[NAMES.index(ELBOW)] - sim.stuck[ELBOW]) < 1e-3
    # a joint the gesture does not move (salute: the left arm) is not a case
    assert not bench.case('salute', 'left_arm_joint1')['exercised']
