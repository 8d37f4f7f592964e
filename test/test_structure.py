"""A correction measured on the robot: applied to the model, searched on, kept, restored."""

from dataclasses import replace
from functools import lru_cache

from namo_fault_recovery.explore.corrections import corrected_tip
from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.model.kinematics import batch_forward, batch_forward_jacobian
from namo_fault_recovery.model.robot import load_robot
from namo_fault_recovery.model.robot_profile import load_profile
from namo_fault_recovery.model.structure import (ArmCorrection, check_matches,
                                                 corrected_arm, learned_arms)
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import recover
from namo_fault_recovery.recovery.result import reference_result
from namo_fault_recovery.recovery.settings import RecoverySettings
from namo_fault_recovery.resources import config_path, NAMO_PROFILE_FILE
from namo_fault_recovery.runtime.explored_version import explored_library
from namo_fault_recovery.runtime.restore import plan_restart
from namo_fault_recovery.runtime.state_store import decode_state, encode_state, StateStore
import numpy as np
import pytest

ROBOT = load_robot()
TOOL = ArmCorrection('right', ('tip_offset',), ((-50.0, 0.1, -0.2),), 'circle', 7,
                     (0.4, 0.9), 26, 'secant', 'namo', (49.0, 51.0))


@lru_cache(maxsize=1)
def profile():
    return load_profile(config_path(NAMO_PROFILE_FILE))


@pytest.mark.parametrize('side', ['right', 'left'])
@pytest.mark.parametrize('groups, params', [
    (('tip_offset',), ((-50.0, 3.0, 10.0),)),
    (('offset:{s}_arm_joint2',), ((5.0,),)),
    (('bend:{s}_arm_link4',), ((3.0, -10.0, 2.0),)),
    (('bend:{s}_arm_link3', 'offset:{s}_arm_joint5', 'tip_offset'),
     ((3.0, -10.0, 2.0), (4.0,), (1.0, 2.0, 3.0))),
])
def test_the_corrected_model_is_the_one_the_explorer_fitted(side, groups, params):
    groups = tuple(g.format(s=side) for g in groups)
    chain = profile().arms[side].chain
    q = np.random.default_rng(0).uniform(chain.lower, chain.upper, (20, 7))
    robot = ROBOT.with_corrections({side: corrected_arm(profile(), ArmCorrection(
        side, groups, params))})
    tip = batch_forward(robot, q, side).tip
    assert np.abs(tip - corrected_tip(chain, groups, params, q)).max() < 1e-4
    assert np.abs(tip - batch_forward(ROBOT, q, side).tip).max() > 5.0    # it changed
    _, jac = batch_forward_jacobian(robot, q, side)                     # analytic, exact
    step = np.zeros(7)
    step[3] = 1e-6
    numeric = (batch_forward(robot, q + step, side).tip - tip) / 1e-6
    assert np.abs(jac.positions[:, 2, 3] - numeric).max() < 1e-3
    other = 'left' if side == 'right' else 'right'
    assert np.array_equal(batch_forward(robot, q, other).tip, batch_forward(ROBOT, q, other).tip)


def test_the_profile_must_be_the_robots_own_arm():
    check_matches(ROBOT, profile(), 'right')
    longer = replace(ROBOT, d=ROBOT.d + np.array([0, 0, 0, 0, 30.0, 0, 0]))
    with pytest.raises(ValueError, match='is not the robot'):
        check_matches(longer, profile(), 'right')


@pytest.mark.parametrize('bad, words', [
    ({'side': 'middle'}, "arm 'middle'"), ({'groups': ('twist',)}, "group 'twist'"),
    ({'params': ((1.0, 2.0),)}, 'expected 3 finite values'),
])
def test_a_malformed_correction_is_refused_in_one_line(bad, words):
    with pytest.raises(ValueError, match=words):
        replace(TOOL, **bad)


def test_a_later_fault_on_the_changed_arm_is_searched_on_the_corrected_model():
    library = load_library(ROBOT, config_path('demo_motions.yaml'))
    learned = ROBOT.with_learned(learned_arms(profile(), [TOOL]))
    settings = RecoverySettings(trajectory_method='kriging', collision_check=False)
    want = batch_forward(ROBOT, library['circle'].joint_matrix()[:, :7], 'right').tip
    truth = learned.changed_model()              # where the changed arm really goes
    errors = {}
    for name, robot in (('nominal', ROBOT), ('corrected', learned)):
        result = recover(robot, library, {'right_arm_joint2': None}, settings, seed=0,
                         clock=Clock(None), optimizer_overrides={'max_cycles': 40})
        q = np.array(result['circle'].positions)[:, :7]
        errors[name] = np.linalg.norm(batch_forward(truth, q, 'right').tip - want, axis=1)
        assert set(result.corrections) == ({'right'} if robot is learned else set())
    assert errors['nominal'].mean() > 40.0, errors
    assert errors['corrected'].mean() < 3.0 and errors['corrected'].max() < 10.0, errors
    assert result.corrections['right']['params'] == [[-50.0, 0.1, -0.2]]


def explored(library):
    current = reference_result(library)      # as the node publishes it at start
    q = np.array(current['bye'].positions)
    q[:, 1] += 0.01
    return explored_library(ROBOT, current, 'bye', current['bye'].times, q, TOOL)


def test_the_explored_version_is_scored_by_what_was_measured():
    result = explored(load_library(ROBOT))
    gesture = result['bye']
    assert result.origin == 'explored' and gesture.method == 'explored'
    assert gesture.score_after == 0.9 and gesture.tip_error_mm == pytest.approx(0.65)
    assert gesture.score_before == 51.0 and gesture.tip_error_before_mm == 50.0
    assert result.corrections == {'right': TOOL.to_dict()}
    assert 'explored on the robot' in result.notes[-1]
    assert result['wai'] == reference_result(load_library(ROBOT))['wai']     # only bye
    with pytest.raises(ValueError, match="'hug' is not in the library"):
        explored_library(ROBOT, result, 'hug', (0.0,), np.zeros((1, 14)), TOOL)


def test_a_restart_restores_the_correction_and_its_explored_version(tmp_path):
    library = load_library(ROBOT)
    result = explored(library)
    text = encode_state({}, result, 'fp', 3, (TOOL,))
    assert decode_state(text).corrections == (TOOL,)
    store = StateStore(tmp_path)
    store.save({}, result, 'fp', 3, (TOOL,))
    plan = plan_restart(store, ROBOT, library, 'fp', RecoverySettings())
    assert plan.corrections == (TOOL,) and plan.library == result and not plan.faults
    assert 'the measured right arm (tip_offset)' in plan.message
    other = replace(TOOL, params=((-40.0, 0.0, 0.0),))
    store.save({}, result, 'fp', 4, (other,))          # the library is for another one
    plan = plan_restart(store, ROBOT, library, 'fp', RecoverySettings())
    assert plan.corrections == (other,) and plan.library is None
    assert 'other measured corrections' in plan.message


def test_the_correction_message_round_trips():
    from namo_fault_recovery.ros.exploration import correction_status
    from namo_fault_recovery.ros.explored_intake import parse_correction
    from namo_fault_recovery.playback.book import GestureTrack
    from namo_fault_recovery.explore.corrections import Correction

    class Found:
        model = Correction(None, TOOL.groups, TOOL.params)
        measured_error_mm, trials, method, correction = (0.4, 0.9), 26, 'secant', 'tool'

    track = GestureTrack('circle', ('a',), np.zeros(2), np.zeros((2, 1)), 7)
    status = correction_status(ROBOT, profile(), track, 'right', Found(), (49.0, 51.0))
    assert parse_correction(status) == TOOL
