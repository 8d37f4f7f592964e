"""The staged expansion into the torso (recovery/lean.py) on Talos, whose arms share two."""

from dataclasses import replace
from pathlib import Path

from builtin_interfaces.msg import Time
from namo_fault_recovery.model.capsules import CapsuleModel
from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.model.kinematics import batch_forward
from namo_fault_recovery.model.profile_robot import robot_from_profile
from namo_fault_recovery.model.robot_profile import load_profile
from namo_fault_recovery.recovery.engine import recover
from namo_fault_recovery.recovery.lean import held_lean, LEAN_GAIN
from namo_fault_recovery.recovery.result import GestureResult
from namo_fault_recovery.recovery.settings import RecoverySettings
from namo_fault_recovery.ros.messages import library_to_msgs
from namo_fault_recovery.runtime.explored_version import explored_library
from namo_fault_recovery.runtime.restore import check_result
import numpy as np
import pytest

ROBOTS = Path(__file__).resolve().parent.parent / 'config' / 'robots'
FAULT = {'arm_right_2_joint': None}     # the salute's fingertip ends 139 mm off, arms alone


@pytest.fixture(scope='module')
def talos():
    robot = robot_from_profile(ROBOTS / 'talos.yaml')
    return robot, load_library(robot, ROBOTS / 'talos_gestures.yaml')


@pytest.fixture(scope='module')
def runs(talos):
    robot, library = talos
    # A generous deadline: what is checked is the stage's result, not its speed.
    settings = RecoverySettings(deadline_sec=5.0)
    return (recover(robot, library, FAULT, settings, seed=3),
            recover(robot, library, FAULT, settings.with_changes(expand_shared=True), seed=3))


def test_off_by_default_nothing_leans(runs):
    upright, _ = runs
    assert not RecoverySettings().expand_shared
    assert all(not g.shared for g in upright.gestures)


def test_the_salute_leans_and_reaches_better(talos, runs):
    robot, _ = talos
    upright, leaned = runs
    before, after = upright['salute'], leaned['salute']
    assert set(after.shared) == {'torso_1_joint', 'torso_2_joint'}
    t = np.array(list(after.shared.values()))
    assert robot.shared.within(t) and np.any(t)
    assert after.score_after <= (1.0 - LEAN_GAIN) * before.score_after
    assert after.tip_error_max_mm < before.tip_error_max_mm - 20.0
    assert 'torso leans' in after.message and not after.collides
    assert any(n.startswith('salute: the torso leans') for n in leaned.notes)
    # Independently: the published arm angles, carried by the published lean, put the
    # fingertip where the reported error says, measured from the upright reference.
    design = load_library(robot, ROBOTS / 'talos_gestures.yaml')['salute'].keyframes
    worst = 0.0
    for kf, q in zip(design, after.positions):
        q_r = np.array(q[:after.right_joints])
        tip = robot.shared.carry(batch_forward(robot, q_r[None], 'right'), t[None]).tip[0]
        ref = batch_forward(robot, kf.right[None], 'right').tip[0]
        worst = max(worst, float(np.linalg.norm(tip - ref)))
    assert worst == pytest.approx(after.tip_error_max_mm, abs=1e-6)


def test_only_the_gestures_a_lean_helps_lean_and_name_the_torso_last(runs):
    _, leaned = runs
    for g in leaned.gestures:
        if not g.shared:
            continue
        assert g.free_joints[-2:] == ('torso_1_joint', 'torso_2_joint')
    assert not leaned['side_invite'].shared


def test_the_before_figures_stay_the_upright_locked_designs(runs):
    upright, leaned = runs
    for name in ('salute', 'bye'):
        assert leaned[name].score_before == upright[name].score_before
        assert leaned[name].tip_error_before_mm == upright[name].tip_error_before_mm


def test_a_published_lean_is_checked_before_it_is_restored(talos, runs):
    robot, library = talos
    _, leaned = runs
    assert check_result(robot, library, leaned, leaned.locks) is None
    salute = leaned['salute']
    bad = replace(leaned, gestures=tuple(
        replace(g, shared={'torso_2_joint': 3.0}) if g is salute else g
        for g in leaned.gestures))
    assert 'outside its limits' in check_result(robot, library, bad, leaned.locks)


def test_a_leaned_gesture_is_not_explored(talos, runs):
    robot, _ = talos
    _, leaned = runs
    salute = leaned['salute']
    with pytest.raises(ValueError, match='leans the torso'):
        explored_library(robot, leaned, 'salute', salute.times,
                         [list(q) for q in salute.positions], None)


def test_shared_joints_take_the_urdf_speed_without_an_expansion_key(tmp_path):
    text = (ROBOTS / 'talos.yaml').read_text().replace(
        '    expansion: [torso_1_joint, torso_2_joint]\n', '')
    assert 'expansion' not in text.split('arms:')[1]
    profile = tmp_path / 'talos.yaml'
    profile.write_text(text)
    robot = robot_from_profile(load_profile(profile), capsules=CapsuleModel())
    assert robot.shared.velocity == (5.4, 5.4)


def test_a_robot_without_shared_joints_is_unchanged(robot, library):
    settings = RecoverySettings(deadline_sec=5.0)
    faults = {'right_arm_joint2': None}
    plain = recover(robot, library, faults, settings, seed=1)
    asked = recover(robot, library, faults, settings.with_changes(expand_shared=True), seed=1)
    assert [g.positions for g in plain.gestures] == [g.positions for g in asked.gestures]


def test_the_lean_survives_the_record_and_reaches_the_message(talos, runs):
    robot, _ = talos
    _, leaned = runs
    salute = leaned['salute']
    assert GestureResult.from_dict(salute.to_dict()).shared == salute.shared
    msg = library_to_msgs(robot.joint_names, replace(leaned, gestures=(salute,)), Time())[0]
    assert msg.joint_names[-2:] == ['torso_1_joint', 'torso_2_joint']
    assert len(msg.joint_names) == len(robot.joint_names) + 2
    for point in msg.points:
        assert list(point.positions[-2:]) == list(salute.shared.values())


STUCK = {'torso_2_joint': np.radians(10.0)}     # the torso stuck 10 deg forward


@pytest.fixture(scope='module')
def held(talos):
    robot, library = talos
    return recover(robot, library, STUCK, RecoverySettings(deadline_sec=5.0), seed=1)


def test_a_torso_that_stuck_is_made_up_for_by_the_arms(talos, held):
    robot, library = talos
    assert held.locks == STUCK and held.faults == STUCK
    t = np.array([0.0, np.radians(10.0)])
    for g in held.gestures:
        assert g.shared == {'torso_1_joint': 0.0, 'torso_2_joint': np.radians(10.0)}
        assert g.score_after < 0.3 * g.score_before, g.name         # 46-74 -> 5-11
        assert g.tip_error_before_mm > 80.0 and not g.collides, g.name
        # The published arms, carried by the held lean, put the fingertips where the
        # reported error says, measured from the upright design.
        worst = 0.0
        for kf, q in zip(library[g.name].keyframes, g.positions):
            for side, arm in (('right', q[:g.right_joints]), ('left', q[g.right_joints:])):
                if side not in library[g.name].arms:
                    continue
                tip = robot.shared.carry(batch_forward(robot, np.array(arm)[None], side),
                                         t[None]).tip[0]
                ref = batch_forward(robot, kf.arm(side)[None], side).tip[0]
                worst = max(worst, float(np.linalg.norm(tip - ref)))
        assert worst == pytest.approx(g.tip_error_max_mm, abs=1e-6), g.name
    assert any('held where it stuck' in n for n in held.notes)
    assert check_result(robot, library, held, STUCK) is None
    upright = replace(held, gestures=tuple(replace(g, shared={}) for g in held.gestures))
    assert 'not held at its lock' in check_result(robot, library, upright, STUCK)


def test_a_torso_stuck_upright_changes_nothing(talos):
    robot, library = talos
    result = recover(robot, library, {'torso_1_joint': None}, RecoverySettings(), seed=1)
    assert result.locks == {'torso_1_joint': 0.0}
    assert all(g.status == 'unchanged' and not g.shared for g in result.gestures)


def test_a_torso_fault_is_parsed_within_its_limits(talos):
    from namo_fault_recovery.runtime.inputs import BadInput, parse_fault
    robot, _ = talos
    assert parse_fault(robot, ['torso_2_joint'], [0.2]) == {'torso_2_joint': 0.2}
    with pytest.raises(BadInput, match='outside its limits'):
        parse_fault(robot, ['torso_2_joint'], [1.5])
    with pytest.raises(BadInput, match='unknown joint'):
        parse_fault(robot, ['head_1_joint'], [0.0])


def test_the_torso_is_read_on_joint_states_and_held_where_it_was_seen(talos):
    from namo_fault_recovery.runtime.inputs import parse_joint_state
    robot, library = talos
    seen = parse_joint_state(robot, ['torso_2_joint', 'head_1_joint', 'arm_left_1_joint'],
                             [0.1, 0.3, 0.2])
    assert seen == {'torso_2_joint': 0.1, 'arm_left_1_joint': 0.2}    # not the head
    arms, held = held_lean(robot, {'torso_2_joint': None, 'arm_left_1_joint': None}, seen)
    assert held == {'torso_2_joint': 0.1} and arms == {'arm_left_1_joint': None}
