"""Lock strategies, left/right symmetry and staged bimanual expansion."""

from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import recover, RecoverySettings
from namo_fault_recovery.recovery.keyframes import reconfigure_library, SearchOptions
from namo_fault_recovery.recovery.locks import clamp_lock, resolve_locks
from namo_fault_recovery.recovery.motion import adapt_library
import numpy as np
import pytest


def test_average_strategy_uses_the_library_mean(robot, library):
    locks, notes = resolve_locks(robot, library, {'right_arm_joint3': None,
                                                  'left_arm_joint6': None})
    assert locks['right_arm_joint3'] == pytest.approx(np.radians(-5.25))
    assert locks['left_arm_joint6'] == pytest.approx(np.radians(-45.0))   # Wai only
    assert notes == []


# Spec section 2 (paper Table 2), last row "average": the paper's lock angles in degrees,
# right arm joints 1-7.
TABLE_2_AVERAGE_DEG = [52.5, -14.25, -5.25, 89.25, 8.75, -5.75, 30.5]
# Spec section 4: the left arm takes part in Wai alone, so its averages are Wai's angles.
# The keyframe search's own problem, the paper's: no stage 2, no collision term.
PAPER = RecoverySettings(bimanual='off', collision_check=False)
WAI_DEG = [30, 5, -45, 90, -10, -45, 45]


def test_packaged_library_average_locks_are_table_2s_last_row(robot, product_library):
    # The packaged library holds Namo's four gestures as motions (the Bye wave's
    # keyframes average to its Table 2 pose), so the "average" strategy locks every
    # joint at Table 2's row, e.g. right joint 2 at -14.25 deg (a dense demo motion in
    # the library would pull it away: -12.37 deg with the circle).
    faults = dict.fromkeys(robot.joint_names)
    locks, notes = resolve_locks(robot, product_library, faults, 'average')
    assert notes == []
    expected = TABLE_2_AVERAGE_DEG + WAI_DEG
    for joint, deg in zip(robot.joint_names, expected):
        assert locks[joint] == pytest.approx(np.radians(deg), abs=1e-12), joint


def test_measured_strategy_uses_measurement_then_falls_back(robot, library):
    measured = {'right_arm_joint2': 0.25}
    locks, notes = resolve_locks(robot, library, {'right_arm_joint2': None,
                                                  'right_arm_joint5': None},
                                 'measured', measured)
    assert locks['right_arm_joint2'] == 0.25
    assert locks['right_arm_joint5'] == pytest.approx(np.radians(8.75))
    assert notes == ['right_arm_joint5: no measured angle; locked at the library average']


def test_explicit_angle_wins_over_every_strategy(robot, library):
    for strategy in ('average', 'measured', 'optimal'):
        locks, _ = resolve_locks(robot, library, {'right_arm_joint2': -0.1}, strategy,
                                 {'right_arm_joint2': 0.3})
        assert locks == {'right_arm_joint2': -0.1}


def test_measured_value_out_of_limits_is_refused(robot, library):
    with pytest.raises(ValueError, match='measured angle of right_arm_joint2'):
        resolve_locks(robot, library, {'right_arm_joint2': None}, 'measured',
                      {'right_arm_joint2': 9.0})


def test_unknown_strategy(robot, library):
    with pytest.raises(ValueError, match="unknown lock strategy 'best'"):
        resolve_locks(robot, library, {}, 'best')


@pytest.mark.parametrize('joint', ['right_arm_joint2', 'right_arm_joint3'])
def test_optimal_lock_beats_average_on_library_total(robot, library, joint):
    average = reconfigure_library(robot, library, {joint: None}, PAPER, seed=4)
    optimal = reconfigure_library(robot, library, {joint: None},
                                  PAPER.with_changes(lock_strategy='optimal'), seed=4)
    assert optimal.total_score <= average.total_score
    chosen = optimal.locks[joint]
    assert any(f'{joint} = {np.degrees(chosen):.2f} deg' in n for n in optimal.notes)
    # The chosen angle is the one every gesture is locked at.
    side, j = robot.locate_joint(joint)
    for g in optimal.gestures:
        assert g.keyframes[0].arm(side)[j] == chosen
    assert optimal.settings['lock_strategy'] == 'optimal'


@pytest.mark.parametrize('k', range(7))
def test_left_right_symmetry_in_wai(robot, library, k):
    angle = float(library.lock_averages('right')[k])
    kw = {'seed': 1, 'gestures': ['wai'], 'clock': Clock(None)}
    right = reconfigure_library(robot, library, {f'right_arm_joint{k + 1}': angle}, PAPER, **kw)
    left = reconfigure_library(robot, library, {f'left_arm_joint{k + 1}': angle}, PAPER, **kw)
    r, le = right['wai'].score_after, left['wai'].score_after
    assert le == pytest.approx(r, rel=0.005, abs=1e-3)
    # And the solutions are mirror images: left angles equal the right ones.
    np.testing.assert_allclose(left['wai'].keyframes[0].left,
                               right['wai'].keyframes[0].right, atol=0.05)


@pytest.mark.parametrize('joint', ['right_arm_joint2', 'right_arm_joint5'])
def test_stage_two_never_worse_than_stage_one(robot, library, joint):
    report = reconfigure_library(robot, library, {joint: None}, PAPER.with_changes(bimanual='on'),
                                 seed=2, gestures=['wai'])
    wai = report['wai']
    assert wai.stage in (1, 2)
    assert wai.score_after <= wai.stage1_score + 1e-9
    if wai.stage == 2:
        assert any(j.startswith('left') for j in wai.free_joints)
    off = reconfigure_library(robot, library, {joint: None}, PAPER.with_changes(bimanual='off'),
                              seed=2, gestures=['wai'])
    # The same value, up to the rounding of a batched evaluation (one row or several).
    assert off['wai'].stage == 1
    assert off['wai'].stage1_score == pytest.approx(off['wai'].score_after, rel=1e-12)


def test_bimanual_mode_is_checked(robot, library):
    with pytest.raises(ValueError, match="bimanual: unknown value 'both'"):
        reconfigure_library(robot, library, {'right_arm_joint1': None},
                            PAPER.with_changes(bimanual='both'))


def test_lock_within_the_tolerance_beyond_a_limit_is_clamped_exactly(robot, library):
    upper = float(robot.arms['right'].upper[0])
    lower = float(robot.arms['right'].lower[0])
    locks, _ = resolve_locks(robot, library, {'right_arm_joint1': upper + 5e-10})
    assert locks['right_arm_joint1'] == upper
    assert clamp_lock(robot, 'left_arm_joint1', lower - 5e-10) == lower
    assert clamp_lock(robot, 'left_arm_joint1', 0.25) == 0.25
    measured, _ = resolve_locks(robot, library, {'right_arm_joint2': None}, 'measured',
                                {'right_arm_joint2': lower - 5e-10})
    assert measured['right_arm_joint2'] == float(robot.arms['right'].lower[1])


@pytest.mark.parametrize('method', ['kriging', 'per_point', 'auto'])
def test_every_published_angle_is_within_its_limits_bit_for_bit(
        robot, demo_library, method):
    # A lock at pi + 5e-10 is accepted (within robot.within_limits' 1e-9 tolerance);
    # nothing the engine outputs may lie beyond +-pi, Kriging-interpolated points included
    # (the demo library's dense circle has them).
    side, j = 'right', 3
    joint = robot.arms[side].joint_names[j]
    upper = float(robot.arms[side].upper[j])
    settings = RecoverySettings(trajectory_method=method)
    res = recover(robot, demo_library, {joint: upper + 5e-10}, settings, seed=0,
                  clock=Clock(None))
    assert res.locks[joint] == upper
    lower = np.concatenate([robot.arms[s].lower for s in ('right', 'left')])
    high = np.concatenate([robot.arms[s].upper for s in ('right', 'left')])
    count = 0
    for g in res.gestures:
        q = np.array(g.positions)
        assert np.all(q >= lower) and np.all(q <= high), g.name
        assert np.all(q[:, j] == upper), g.name
        count += q.size
    assert count > 14 * 100   # the circle's 100 points are among them


def test_optimal_is_never_worse_than_average_on_the_final_library(robot, library):
    # The node's settings (collision on, bimanual auto, trajectory auto), no deadline.
    for joint in ('right_arm_joint3', 'left_arm_joint2'):
        totals = {}
        for strategy in ('average', 'optimal'):
            res = recover(robot, library, {joint: None},
                          RecoverySettings(lock_strategy=strategy), seed=0,
                          clock=Clock(None))
            totals[strategy] = sum(g.score_after for g in res.gestures)
            assert any('optimal lock' in n for n in res.notes) == (
                strategy == 'optimal')
        assert totals['optimal'] <= totals['average'] + 1e-9, joint


def test_optimal_engine_includes_the_start_and_solves_it_as_the_fixed_run(robot, library):
    # On the engine's own problem (collision term, stage 2, stay_close), the start lock
    # is solved exactly as the fixed-lock run solves it, so optimal ties or wins.
    joint = 'right_arm_joint2'
    node = RecoverySettings(bimanual='auto', collision_check=True)
    kw = {'seed': 3, 'clock': Clock(None)}
    start = {joint: 0.3}
    fixed = reconfigure_library(robot, library, start, node,
                                options=SearchOptions(stay_close=1e-3), **kw)
    optimal = reconfigure_library(robot, library, {joint: None},
                                  node.with_changes(lock_strategy='optimal'),
                                  options=SearchOptions(stay_close=1e-3, lock_start=start), **kw)
    assert optimal.total_score <= fixed.total_score
    assert any('at the start 17.19 deg' in n for n in optimal.notes)
    if optimal.locks[joint] == 0.3:
        assert optimal.total_score == fixed.total_score


def test_optimal_in_adapt_library_keeps_the_better_of_average_and_its_choice(
        robot, product_library):
    faults = {'right_arm_joint3': None}
    settings = RecoverySettings(trajectory_method='kriging', collision_check=True,
                                bimanual='auto')
    average = adapt_library(robot, product_library, faults, settings, clock=Clock(None),
                            seed=0)
    optimal = adapt_library(robot, product_library, faults,
                            settings.with_changes(lock_strategy='optimal'), clock=Clock(None),
                            seed=0)

    def total(res):
        return sum(g.score_after for g in res.gestures)
    assert total(optimal) <= total(average)
    note = [n for n in optimal.notes if n.startswith('optimal lock')]
    assert len(note) == 1 and 'average lock' in note[0]
