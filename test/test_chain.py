"""
Chains compiled from a URDF against the DH kinematics, the golden values and Pinocchio.

Robots: Namo (its generated URDF), Talos and TIAGo++ (example-robot-data).

Pinocchio reads each URDF itself and computes every link frame of every chain at random
configurations within the joint limits; ours must agree to 1e-9 m and 1e-9 in rotation
(Namo: 1e-7, since its URDF prints angles with 9 digits and the compiler takes a
printed pi/2 as exact).  The Jacobians are checked against central differences.
"""

import math
from pathlib import Path

from namo_fault_recovery.errors import ConfigError
from namo_fault_recovery.model.capsules import CapsuleModel
from namo_fault_recovery.model.chain import ChainError, compile_chain
from namo_fault_recovery.model.kinematics import batch_forward, forward_kinematics_jacobian
from namo_fault_recovery.model.profile_robot import robot_from_profile
from namo_fault_recovery.model.robot_profile import load_profile
from namo_fault_recovery.model.urdf import urdf_string
from namo_fault_recovery.model.urdf_tree import load_urdf_tree
import numpy as np
import pinocchio as pin
import pytest
from test_urdf import FLIP, GOLDEN, WAI_PALM

ROOT = Path(__file__).resolve().parent.parent
PROFILES = {'namo': ROOT / 'config' / 'namo_profile.yaml',
            'talos': ROOT / 'config' / 'robots' / 'talos.yaml',
            'tiago_dual': ROOT / 'config' / 'robots' / 'tiago_dual.yaml'}
ARMS = ('right', 'left')


@pytest.fixture(scope='module')
def profiles():
    return {name: load_profile(path) for name, path in PROFILES.items()}


@pytest.fixture(scope='module')
def namo(robot):
    """Namo's profile over the URDF generated from the packaged robot file."""
    return load_profile(PROFILES['namo'], urdf=urdf_string(robot))


@pytest.mark.parametrize('side', ARMS)
def test_namo_urdf_chain_is_the_dh_kinematics(robot, namo, side):
    chain = namo.arms[side].chain
    assert chain.joint_names == robot.arms[side].joint_names
    assert np.allclose(chain.lower, robot.arms[side].lower)
    assert np.allclose(chain.upper, robot.arms[side].upper)
    q = np.random.default_rng(5).uniform(-math.pi, math.pi, (400, 7))
    for ours, dh in zip(chain.batch_forward(q), batch_forward(robot, q, side)):
        assert np.abs(ours - dh).max() < 1e-5       # mm; rotations: ~1e-8
    lm, jac = chain.jacobian(q[:50])
    lm_dh, jac_dh = forward_kinematics_jacobian(robot, q[:50], side)
    assert np.abs(jac.positions - jac_dh.positions).max() < 1e-5
    assert np.abs(jac.axes - jac_dh.axes).max() < 1e-7


@pytest.mark.parametrize('pose', sorted(GOLDEN))
@pytest.mark.parametrize('side', ARMS)
def test_namo_urdf_chain_lands_on_the_golden_values(namo, pose, side):
    angles, points = GOLDEN[pose]
    lm = namo.arms[side].chain.forward(np.radians(angles))
    flip = FLIP if side == 'left' else np.ones(3)
    for value, expected in zip((lm.elbow, lm.wrist, lm.tip), points):
        assert np.abs(value - np.array(expected) * flip).max() < 0.006
    if pose == 'wai':
        palm = WAI_PALM if side == 'right' else FLIP[:, None] * WAI_PALM * FLIP[None, :]
        assert np.abs(lm.palm - palm).max() < 1e-4


def pinocchio_frames(path, chain, q):
    """Return {link: (positions (N, 3), rotations (N, 3, 3))} in the chain's base frame."""
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    links = list(chain.link_frames(q[:1]))
    out = {link: ([], []) for link in links}
    for row in q:
        cfg = pin.neutral(model)
        for name, angle in zip(chain.joint_names, row):
            joint = model.joints[model.getJointId(name)]
            if joint.nq == 2:       # continuous: (cos, sin)
                cfg[joint.idx_q:joint.idx_q + 2] = (math.cos(angle), math.sin(angle))
            else:
                cfg[joint.idx_q] = angle
        pin.framesForwardKinematics(model, data, cfg)
        base = data.oMf[model.getFrameId(chain.base)].inverse()
        for link in links:
            rel = base * data.oMf[model.getFrameId(link)]
            out[link][0].append(rel.translation.copy())
            out[link][1].append(rel.rotation.copy())
    return {link: (np.array(p), np.array(r)) for link, (p, r) in out.items()}


@pytest.mark.parametrize('name', sorted(PROFILES))
def test_chains_match_pinocchio_at_random_configurations(profiles, name, capsys):
    profile = profiles[name]
    tol = 1e-7 if name == 'namo' else 1e-9
    for side, arm in profile.arms.items():
        chain = compile_chain(profile.tree, arm.chain.base, arm.chain.tip)    # metres
        q = np.random.default_rng(11).uniform(chain.lower, chain.upper, (60, chain.n_joints))
        ours = chain.link_frames(q)
        ref = pinocchio_frames(profile.tree.source, chain, q)
        assert set(ours) == set(ref) and len(ours) > chain.n_joints
        pos = max(float(np.abs(ours[k][0] - ref[k][0]).max()) for k in ours)
        rot = max(float(np.abs(ours[k][1] - ref[k][1]).max()) for k in ours)
        with capsys.disabled():
            print(f'\n{name} {side}: {chain.n_joints} joints, {len(ours)} links, max error '
                  f'{pos:.1e} m, {rot:.1e} rotation')
        assert pos < tol and rot < tol


@pytest.mark.parametrize('name', ['talos', 'tiago_dual'])
def test_jacobians_match_central_differences(profiles, name):
    for arm in profiles[name].arms.values():
        chain = arm.chain
        q = np.random.default_rng(2).uniform(chain.lower, chain.upper, (4, chain.n_joints))
        lm, jac = chain.jacobian(q)
        h = 1e-6
        for i in range(chain.n_joints):
            step = np.zeros(chain.n_joints)
            step[i] = h
            up, down = chain.forward(q + step), chain.forward(q - step)
            for k, role in enumerate(('elbow', 'wrist', 'tip')):
                numeric = (getattr(up, role) - getattr(down, role)) / (2 * h)
                assert np.abs(jac.positions[:, k, i] - numeric).max() < 1e-5, (role, i)
            # dR/dq_i R^T = [omega_i]x
            dr = (up.palm - down.palm) / (2 * h)
            omega = dr @ np.swapaxes(lm.palm, -1, -2)
            vec = np.stack((omega[:, 2, 1], omega[:, 0, 2], omega[:, 1, 0]), axis=-1)
            assert np.abs(jac.axes[:, i] - vec).max() < 1e-6, i


def test_the_shared_torso_carries_both_arms_as_pinocchio_does(profiles, capsys):
    """Talos's torso joints move the upright arms' landmarks where the whole tree puts them."""
    robot = robot_from_profile(profiles['talos'], capsules=CapsuleModel())
    shared = robot.shared
    assert shared.names == ('torso_1_joint', 'torso_2_joint')
    rng = np.random.default_rng(3)
    worst = 0.0
    for side, arm in profiles['talos'].arms.items():
        whole = compile_chain(profiles['talos'].tree, arm.chain.base, arm.chain.tip,
                              locked=arm.held)                                   # metres
        assert whole.joint_names[:2] == shared.names
        q = rng.uniform(whole.lower, whole.upper, (40, whole.n_joints))
        ref = pinocchio_frames(profiles['talos'].tree.source, whole, q)
        upright = robot.chains[side].forward(q[:, 2:])
        leaned = shared.carry(upright, q[:, :2])
        for role in ('elbow', 'wrist'):
            link = arm.landmark_links[role]
            err = np.abs(getattr(leaned, role) / 1000.0 - ref[link][0]).max()
            worst = max(worst, float(err))
        palm = arm.landmark_links['palm']
        assert np.abs(leaned.palm - ref[palm][1]).max() < 1e-9
        back = shared.back(leaned, q[:, :2])
        assert np.abs(back.tip - upright.tip).max() < 1e-9
        assert np.abs(back.palm - upright.palm).max() < 1e-12
    with capsys.disabled():
        print(f'\ntalos torso + arm vs pinocchio: max error {worst:.1e} m')
    assert worst < 1e-9


def test_a_robot_without_shared_joints_has_none(profiles):
    assert robot_from_profile(profiles['tiago_dual'], capsules=CapsuleModel()).shared is None


def _urdf(joints):
    """Return a small URDF: a chain of ``(name, type, axis, extra)`` joints from 'base'."""
    links = ['base'] + [f'l{i}' for i in range(len(joints))]
    body = ''.join(f'<link name="{link}"/>' for link in links)
    for i, (name, kind, axis, extra) in enumerate(joints):
        body += (f'<joint name="{name}" type="{kind}"><parent link="{links[i]}"/>'
                 f'<child link="{links[i + 1]}"/><origin xyz="0.1 0.02 0.3" rpy="0.3 -0.2 1.1"/>'
                 f'<axis xyz="{axis}"/><limit lower="-2" upper="2" effort="1" velocity="2"/>'
                 f'{extra}</joint>')
    return f'<robot name="toy">{body}</robot>'


def test_any_axis_and_continuous_joints_compile_and_match_a_dense_product():
    axes = ('0 0 1', '0 -1 0', '1 0 0', '0 0 -1', '0.6 0 0.8', '0 1 0')
    joints = [(f'j{i}', 'continuous' if i == 2 else 'revolute', a, '')
              for i, a in enumerate(axes)]
    tree = load_urdf_tree(_urdf(joints))
    chain = compile_chain(tree, 'base', 'l5')
    assert chain.upper[2] == math.pi and chain.velocity == (2.0,) * 6
    q = np.random.default_rng(0).uniform(-2, 2, (20, 6))
    frames = chain.link_frames(q, ['l5'])['l5']
    for n in range(len(q)):       # the URDF as written: origin, then a turn about the axis
        pose = np.eye(4)
        for joint, angle in zip(tree.path('base', 'l5'), q[n]):
            turn = np.eye(4)
            turn[:3, :3] = _axis_angle(joint.axis, angle)
            pose = pose @ joint.origin @ turn
        assert np.abs(frames[0][n] - pose[:3, 3]).max() < 1e-12
        assert np.abs(frames[1][n] - pose[:3, :3]).max() < 1e-12


def _axis_angle(axis, angle):
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


@pytest.mark.parametrize('kind, extra, says', [
    ('prismatic', '', "joint 'j1' on the chain base -> l2 is prismatic"),
    ('revolute', '<mimic joint="j0"/>', "joint 'j1' on the chain base -> l2 mimics 'j0'"),
])
def test_a_chain_the_model_cannot_take_is_refused_in_one_line(kind, extra, says):
    tree = load_urdf_tree(_urdf([('j0', 'revolute', '0 0 1', ''), ('j1', kind, '0 0 1', extra),
                                 ('j2', 'revolute', '0 0 1', '')]), source='toy.urdf')
    with pytest.raises(ChainError) as err:
        compile_chain(tree, 'base', 'l2')
    message = str(err.value)
    assert message.startswith('toy.urdf: ') and says in message and '\n' not in message
    assert 'expected revolute, continuous or fixed joints only' in message
    compile_chain(tree, 'l1', 'l2')      # below it, the same URDF is fine


@pytest.mark.parametrize('text, says', [
    ('<robot name="x"><link name="a"/', 'not a URDF that parses'),
    ('<robot name="x"><link name="a"/><joint name="j" type="fixed"><parent link="a"/>'
     '<child link="b"/></joint></robot>', "joint 'j' names link 'b'"),
    ('<robot name="x"><link name="a"/><link name="b"/></robot>', 'exactly one root link'),
])
def test_a_urdf_that_does_not_parse_or_is_no_tree_is_one_line(text, says):
    with pytest.raises(ConfigError) as err:
        load_urdf_tree(text, source='bad.urdf')
    assert str(err.value).startswith('bad.urdf: ') and says in str(err.value)
    assert '\n' not in str(err.value)
