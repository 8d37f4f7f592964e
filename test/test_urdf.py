"""
The generated URDF against our kinematics, read by an independent URDF library.

yourdfpy parses the URDF and computes the link transforms itself; they must land on the
spec's golden landmarks (namo_model.md) and on our forward kinematics, for both arms.
"""

import io
import math
from pathlib import Path
import xml.etree.ElementTree as ET

from builtin_interfaces.msg import Time
from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.cli.main import main as cli_main
from namo_fault_recovery.model.kinematics import forward_kinematics
from namo_fault_recovery.model.urdf import capsule_segments, urdf_string
from namo_fault_recovery.recovery.result import reference_result
from namo_fault_recovery.ros.messages import library_markers
import numpy as np
import pytest
import yaml
import yourdfpy

ROOT = Path(__file__).resolve().parent.parent
# namo_model.md, right arm, mm: pose (deg) -> elbow, wrist, fingertip.
GOLDEN = {
    'zero': ((0, 0, 0, 0, 0, 0, 0),
             ((0, -182, -206.5), (0, -182, -412.5), (0, -182, -542.5))),
    'wai': ((30, 5, -45, 90, -10, -45, 45),
            ((102.86, -164.00, -178.15), (222.66, -18.89, -94.33), (240.65, -15.83, 34.39))),
    'bye': ((46, -11, 24, 95, -53, -32, 41),
            ((145.81, -221.40, -140.81), (251.91, -299.91, 17.35), (239.79, -277.72, 144.87))),
    'salute': ((100, -43, -45, 100, 47, 28, 10),
               ((148.73, -322.83, 26.23), (194.40, -193.52, 179.94), (188.37, -75.37, 233.83))),
    'side_invite': ((34, -8, 45, 72, 51, 26, 26),
                    ((114.35, -210.74, -169.53), (253.67, -356.79, -128.34),
                     (289.53, -446.04, -40.89))),
}
WAI_PALM = np.array([[-0.1384, 0.9901, -0.0245], [-0.0236, -0.0280, -0.9993],
                     [-0.9901, -0.1377, 0.0272]])
FLIP = np.array([1.0, -1.0, 1.0])


@pytest.fixture(scope='module')
def urdf(robot):
    return yourdfpy.URDF.load(io.StringIO(urdf_string(robot)), build_scene_graph=True,
                              load_meshes=False)


def urdf_landmarks(model, robot, side, q):
    """Return elbow, wrist, tip (mm) and the palm rotation, as yourdfpy computes them."""
    cfg = dict.fromkeys(model.actuated_joint_names, 0.0)
    cfg.update(zip(robot.arms[side].joint_names, q))
    model.update_cfg(cfg)

    def pose(link):
        return model.get_transform(link, 'base_link')
    return (pose(f'{side}_arm_link{robot.elbow_frame}')[:3, 3] * 1e3,
            pose(f'{side}_arm_link{robot.wrist_frame}')[:3, 3] * 1e3,
            pose(f'{side}_arm_fingertip')[:3, 3] * 1e3,
            pose(f'{side}_arm_link7')[:3, :3])


@pytest.mark.parametrize('pose', sorted(GOLDEN))
@pytest.mark.parametrize('side', ['right', 'left'])
def test_urdf_lands_on_the_golden_landmarks(urdf, robot, pose, side):
    angles, points = GOLDEN[pose]
    got = urdf_landmarks(urdf, robot, side, np.radians(angles))
    flip = FLIP if side == 'left' else np.ones(3)      # the left arm is the mirror image
    for name, expected, value in zip(('elbow', 'wrist', 'tip'), points, got):
        # The golden values are rounded to 0.01 mm.
        assert np.abs(value - np.array(expected) * flip).max() < 0.006, (pose, side, name)
    if pose == 'wai':
        palm = WAI_PALM if side == 'right' else FLIP[:, None] * WAI_PALM * FLIP[None, :]
        assert np.abs(got[3] - palm).max() < 1e-4


def test_urdf_matches_our_kinematics_everywhere(urdf, robot):
    rng = np.random.default_rng(7)
    worst = 0.0
    worst_rot = 0.0
    for side in ('right', 'left'):
        arm = robot.arms[side]
        for q in rng.uniform(arm.lower, arm.upper, size=(25, 7)):
            ours = forward_kinematics(robot, q, side)
            theirs = urdf_landmarks(urdf, robot, side, q)
            for a, b in zip((ours.elbow, ours.wrist, ours.tip), theirs[:3]):
                worst = max(worst, float(np.abs(a - b).max()))
            worst_rot = max(worst_rot, float(np.abs(ours.palm - theirs[3]).max()))
    print(f'URDF vs model, 50 random poses: max landmark difference {worst:.2e} mm, '
          f'max palm rotation entry difference {worst_rot:.1e}')
    assert worst < 1e-3
    assert worst_rot < 1e-6


def test_joints_and_limits_come_from_the_robot_file(robot, tmp_path):
    data = yaml.safe_load((ROOT / 'config' / 'namo_robot.yaml').read_text())
    data['arms']['right']['limits'][3] = [-10, 135]
    data['arms']['left']['joints'][0] = 'l_shoulder_pitch'
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(data))
    custom = load_robot(path)
    root = ET.fromstring(urdf_string(custom))
    joints = {j.get('name'): j for j in root.iter('joint') if j.get('type') == 'revolute'}
    assert list(joints) == list(custom.joint_names)
    assert 'l_shoulder_pitch' in joints
    limit = joints['right_arm_joint4'].find('limit')
    assert float(limit.get('lower')) == pytest.approx(math.radians(-10))
    assert float(limit.get('upper')) == pytest.approx(math.radians(135))
    assert root.find('link').get('name') == 'base_link'


def test_collision_capsules_are_the_self_collision_capsules(robot):
    root = ET.fromstring(urdf_string(robot))
    caps = {c.name: c for c in capsule_segments(robot)}
    radii = {'upper_arm': robot.capsules.upper_arm, 'forearm': robot.capsules.forearm,
             'hand': robot.capsules.hand}
    for side in ('right', 'left'):
        for seg, radius in radii.items():
            cap = caps[f'{side}_arm_{seg}']
            assert cap.radius == pytest.approx(radius * 1e-3)
            link = root.find(f"link[@name='{cap.link}']")
            shapes = [c.find('geometry')[0] for c in link.findall('collision')]
            assert sorted(s.tag for s in shapes) == ['cylinder', 'sphere', 'sphere']
            assert all(float(s.get('radius')) == pytest.approx(radius * 1e-3) for s in shapes)
    # Segment lengths: upper arm and forearm as the DH table, the hand 130 mm.
    for seg, length in (('upper_arm', 206.5), ('forearm', 206.0), ('hand', 130.0)):
        cap = caps[f'right_arm_{seg}']
        assert np.linalg.norm(cap.end - cap.start) == pytest.approx(length * 1e-3)


def test_base_link_is_the_frame_of_the_gesture_markers(urdf, robot):
    """The skeleton markers drawn in base_link coincide with the URDF's links."""
    library = load_library(robot, ROOT / 'config' / 'paper_gestures.yaml')
    ref = reference_result(library)
    markers = library_markers(robot, ref, ref, Time())
    gesture = library.gestures[0]         # drawn without an offset
    q = gesture.keyframes[0]
    for side, ident in (('right', 2), ('left', 12)):
        strip = next(m for m in markers if m.ns == gesture.name and m.id == ident)
        assert strip.header.frame_id == 'base_link'
        drawn = np.array([[p.x, p.y, p.z] for p in strip.points]) * 1e3
        elbow, wrist, tip, _ = urdf_landmarks(urdf, robot, side, q.arm(side))
        shoulder = urdf.get_transform(f'{side}_arm_link1', 'base_link')[:3, 3] * 1e3
        assert np.abs(drawn - np.array([shoulder, elbow, wrist, tip])).max() < 1e-3


def test_packaged_urdf_is_the_generated_one(robot):
    packaged = (ROOT / 'config' / 'namo.urdf').read_text()
    assert packaged == urdf_string(robot), 'regenerate: namo-recovery urdf --out config/namo.urdf'


def test_cli_writes_the_urdf(robot, tmp_path, capsys):
    out = tmp_path / 'namo.urdf'
    assert cli_main(['urdf', '--out', str(out)]) == 0
    assert out.read_text() == urdf_string(robot)
    assert cli_main(['urdf']) == 0
    assert capsys.readouterr().out.endswith(urdf_string(robot))
    assert cli_main(['urdf', '--out', str(tmp_path / 'missing' / 'x.urdf')]) == 2
    assert 'cannot write' in capsys.readouterr().err
