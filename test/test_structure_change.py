"""Hidden structure changes: each URDF edit moves the chain exactly as its kind says."""

import math

from namo_fault_recovery.errors import ConfigError
from namo_fault_recovery.model.kinematics import forward_kinematics as forward
from namo_fault_recovery.model.robot import load_robot
from namo_fault_recovery.model.robot_profile import load_profile
from namo_fault_recovery.model.urdf import urdf_string
from namo_fault_recovery.resources import config_path, NAMO_PROFILE_FILE
from namo_fault_recovery.sim.physics import NamoSim
from namo_fault_recovery.sim.structure_change import apply_changes, parse_change
import numpy as np
import pytest

ROBOT = load_robot()
NOMINAL = urdf_string(ROBOT)
RNG = np.random.default_rng(7)
Q = RNG.uniform(-1.5, 1.5, size=(20, 7))


def chain(changes=(), side='right'):
    """Return one arm's chain compiled from Namo's URDF after ``changes``."""
    text = apply_changes(NOMINAL, [parse_change(c) for c in changes])
    return load_profile(config_path(NAMO_PROFILE_FILE), urdf=text).arms[side].chain


def test_no_change_keeps_the_kinematics():
    assert np.allclose(chain().batch_forward(Q).tip, chain([]).batch_forward(Q).tip)
    nominal = chain().batch_forward(Q).tip
    assert np.allclose(nominal, forward(ROBOT, Q, 'right').tip, atol=1e-6)


@pytest.mark.parametrize('side', ['right', 'left'])
def test_a_hidden_tool_is_the_told_tool(side):
    hidden = chain([f'tool:{side}_arm_fingertip_joint:50'], side).batch_forward(Q)
    told = forward(ROBOT.with_tool(50.0, side), Q, side)
    assert np.allclose(hidden.tip, told.tip, atol=1e-6)
    assert np.allclose(hidden.wrist, told.wrist, atol=1e-6)
    other = 'left' if side == 'right' else 'right'
    assert np.allclose(chain([f'tool:{side}_arm_fingertip_joint:50'], other).batch_forward(Q).tip,
                       chain([], other).batch_forward(Q).tip)


def test_an_encoder_offset_shifts_the_true_angle():
    shifted = Q.copy()
    shifted[:, 3] += math.radians(5.0)
    offset = chain(['encoder_offset:right_arm_joint4:5']).batch_forward(Q).tip
    assert np.allclose(offset, chain().batch_forward(shifted).tip, atol=1e-12)
    assert not np.allclose(offset, chain().batch_forward(Q).tip, atol=1e-3)


def test_a_bend_keeps_lengths_and_moves_what_is_beyond():
    bent = chain(['bend:right_arm_joint5:10']).batch_forward(Q)
    nominal = chain().batch_forward(Q)
    assert np.allclose(bent.elbow, nominal.elbow)
    assert np.allclose(np.linalg.norm(bent.wrist - bent.elbow, axis=1),
                       np.linalg.norm(nominal.wrist - nominal.elbow, axis=1))
    moved = np.linalg.norm(bent.tip - nominal.tip, axis=1)
    assert np.all(moved > 0.01)


def test_a_longer_link_is_longer_by_the_amount():
    longer = chain(['link_length:right_arm_joint5:30']).batch_forward(Q)
    nominal = chain().batch_forward(Q)
    grow = (np.linalg.norm(longer.wrist - longer.elbow, axis=1)
            - np.linalg.norm(nominal.wrist - nominal.elbow, axis=1))
    assert np.allclose(grow, 30.0, atol=1e-6)


@pytest.mark.parametrize('spec, words', [
    ('twist:right_arm_joint5:3', "kind 'twist'"),
    ('tool:right_arm_joint5', 'KIND:JOINT:AMOUNT'),
    ('tool:right_arm_fingertip_joint:-5', 'expected a finite number >= 0 of mm'),
    ('bend:right_arm_joint5:nan', 'expected a finite number of deg'),
])
def test_a_bad_spec_is_one_line(spec, words):
    with pytest.raises(ConfigError) as err:
        parse_change(spec, 'sim.yaml', 'structure_changes')
    assert words in str(err.value) and 'sim.yaml' in str(err.value)
    assert '\n' not in str(err.value)


@pytest.mark.parametrize('spec, words', [
    ('bend:no_such_joint:5', 'no such joint'),
    ('encoder_offset:right_arm_fingertip_joint:5', 'expected a revolute or continuous'),
    ('link_length:right_arm_joint5:-900', 'expected a positive length'),
])
def test_a_change_the_urdf_cannot_take_is_one_line(spec, words):
    with pytest.raises(ConfigError) as err:
        apply_changes(NOMINAL, [parse_change(spec)], 'sim copy')
    assert words in str(err.value) and 'sim copy' in str(err.value)
    assert '\n' not in str(err.value)


def test_the_simulator_runs_the_changed_copy():
    text = apply_changes(NOMINAL, [parse_change('link_length:right_arm_joint5:30')])
    sim = NamoSim(ROBOT, urdf=text)
    sim.step(10)
    body = sim.model.body('right_arm_link5').id
    parent = sim.model.body('right_arm_link4').id
    gap = np.linalg.norm(sim.data.xpos[body] - sim.data.xpos[parent])
    nominal = NamoSim(ROBOT)
    nominal.step(10)
    base = np.linalg.norm(nominal.data.xpos[body] - nominal.data.xpos[parent])
    assert gap == pytest.approx(base + 0.030, abs=1e-6)
