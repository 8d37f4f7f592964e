"""Validation of fault reports and joint states (the node's inputs), without ROS."""

import math

from namo_fault_recovery.recovery.locks import frozen_arms
from namo_fault_recovery.runtime.inputs import BadInput, parse_fault, parse_joint_state
import pytest

NAN = float('nan')
INF = float('inf')


def test_fault_without_positions_lets_the_strategy_choose(robot):
    assert parse_fault(robot, ['right_arm_joint2', 'left_arm_joint7']) == {
        'right_arm_joint2': None, 'left_arm_joint7': None}


def test_fault_positions_are_lock_angles_and_nan_means_absent(robot):
    faults = parse_fault(robot, ['right_arm_joint2', 'left_arm_joint1'], [0.25, NAN])
    assert faults == {'right_arm_joint2': 0.25, 'left_arm_joint1': None}
    assert parse_fault(robot, ['left_arm_joint1'], [math.pi]) == {'left_arm_joint1': math.pi}


@pytest.mark.parametrize('names, positions, velocity, reason', [
    ([], [], [], 'empty fault message'),
    (['right_arm_joint8'], [], [], "unknown joint 'right_arm_joint8'"),
    (['right_arm_joint1', 'head'], [], [], "unknown joint 'head'"),
    (['right_arm_joint1', 'right_arm_joint2'], [0.1], [], 'mismatched lengths: 2 names but 1'),
    (['right_arm_joint1'], [], [0.0, 1.0], '2 velocity values'),
    (['right_arm_joint1'], [INF], [], 'non-finite position inf'),
    (['right_arm_joint1'], [-INF], [], 'non-finite position -inf'),
    (['right_arm_joint1'], [3.2], [], 'outside its limits'),
    (['right_arm_joint1', 'right_arm_joint1'], [], [], 'appears twice'),
])
def test_bad_fault_reports_are_rejected_with_a_reason(robot, names, positions, velocity,
                                                      reason):
    with pytest.raises(BadInput, match=reason.replace('(', r'\(')):
        parse_fault(robot, names, positions, velocity)


def test_joint_state_keeps_arm_joints_and_ignores_others(robot):
    assert parse_joint_state(robot, ['head_pan', 'right_arm_joint3', 'wheel'],
                             [1.0, 0.2, 99.0]) == {'right_arm_joint3': 0.2}


@pytest.mark.parametrize('names, positions, reason', [
    ([], [], 'empty joint state'),
    (['right_arm_joint1'], [], 'empty joint state'),
    (['right_arm_joint1', 'right_arm_joint2'], [0.1], 'mismatched lengths'),
    (['right_arm_joint1'], [NAN], 'non-finite measured position nan'),
    (['left_arm_joint2'], [-INF], 'non-finite measured position -inf'),
    (['left_arm_joint2'], [7.0], 'outside its limits'),
])
def test_bad_joint_states_are_rejected(robot, names, positions, reason):
    with pytest.raises(BadInput, match=reason):
        parse_joint_state(robot, names, positions)


def test_frozen_arms(robot):
    left = robot.arms['left'].joint_names
    assert frozen_arms(robot, left) == ('left',)
    assert frozen_arms(robot, left[:6] + ('right_arm_joint1',)) == ()
    assert frozen_arms(robot, robot.joint_names) == ('right', 'left')


def test_a_joint_on_its_stop_reads_past_its_limit_and_is_taken_at_the_limit(robot):
    """Encoder noise at a hard stop: a little past the limit is the limit; far past is not."""
    from namo_fault_recovery.runtime.inputs import MEASURED_LIMIT_TOLERANCE
    upper = float(robot.arms['right'].upper[0])
    assert parse_fault(robot, ['right_arm_joint1'], [upper + 1e-4]) == \
        {'right_arm_joint1': upper}
    assert parse_joint_state(robot, ['right_arm_joint1'], [upper + 1e-4]) == \
        {'right_arm_joint1': upper}
    for parse in (parse_fault, parse_joint_state):
        with pytest.raises(BadInput, match='outside its limits'):
            parse(robot, ['right_arm_joint1'], [upper + 2 * MEASURED_LIMIT_TOLERANCE])
