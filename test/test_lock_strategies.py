"""Lock strategies, left/right symmetry and staged bimanual expansion."""

from namo_fault_recovery.recovery.keyframes import reconfigure_library
from namo_fault_recovery.recovery.locks import resolve_locks
import numpy as np
import pytest


def test_average_strategy_uses_the_library_mean(robot, library):
    locks, notes = resolve_locks(robot, library, {'right_arm_joint3': None,
                                                  'left_arm_joint6': None})
    assert locks['right_arm_joint3'] == pytest.approx(np.radians(-5.25))
    assert locks['left_arm_joint6'] == pytest.approx(np.radians(-45.0))   # Wai only
    assert notes == []


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
    kw = {'seed': 4, 'bimanual': 'off'}
    average = reconfigure_library(robot, library, {joint: None}, **kw)
    optimal = reconfigure_library(robot, library, {joint: None}, lock_strategy='optimal',
                                  **kw)
    assert optimal.total_score <= average.total_score
    chosen = optimal.locks[joint]
    assert any(f'{joint} = {np.degrees(chosen):.2f} deg' in n for n in optimal.notes)
    # The chosen angle is the one every gesture is locked at.
    side, j = robot.locate_joint(joint)
    for g in optimal.gestures:
        assert g.keyframes[0].arm(side)[j] == chosen
    assert optimal.lock_strategy == 'optimal'


@pytest.mark.parametrize('k', range(7))
def test_left_right_symmetry_in_wai(robot, library, k):
    angle = float(library.lock_averages('right')[k])
    kw = {'seed': 1, 'gestures': ['wai'], 'bimanual': 'off', 'deadline': None}
    right = reconfigure_library(robot, library, {f'right_arm_joint{k + 1}': angle}, **kw)
    left = reconfigure_library(robot, library, {f'left_arm_joint{k + 1}': angle}, **kw)
    r, le = right['wai'].score_after, left['wai'].score_after
    assert le == pytest.approx(r, rel=0.005, abs=1e-3)
    # And the solutions are mirror images: left angles equal the right ones.
    np.testing.assert_allclose(left['wai'].keyframes[0].left,
                               right['wai'].keyframes[0].right, atol=0.05)


@pytest.mark.parametrize('joint', ['right_arm_joint2', 'right_arm_joint5'])
def test_stage_two_never_worse_than_stage_one(robot, library, joint):
    report = reconfigure_library(robot, library, {joint: None}, seed=2, gestures=['wai'],
                                 bimanual='on')
    wai = report['wai']
    assert wai.stage in (1, 2)
    assert wai.score_after <= wai.stage1_score + 1e-9
    if wai.stage == 2:
        assert any(j.startswith('left') for j in wai.free_joints)
    off = reconfigure_library(robot, library, {joint: None}, seed=2, gestures=['wai'],
                              bimanual='off')
    assert off['wai'].stage == 1 and off['wai'].stage1_score == off['wai'].score_after


def test_bimanual_mode_is_checked(robot, library):
    with pytest.raises(ValueError, match="unknown bimanual mode 'both'"):
        reconfigure_library(robot, library, {'right_arm_joint1': None}, bimanual='both')
