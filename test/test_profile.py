"""
The recovery profile, the template command that guesses one, and ``bench fk``.

The profile loader's one-line errors; the template on Namo, Talos and TIAGo++.
"""

import io
from pathlib import Path

from namo_fault_recovery.cli.main import main as cli_main
from namo_fault_recovery.errors import ConfigError
from namo_fault_recovery.model.profile_template import guess_profile
from namo_fault_recovery.model.robot_profile import load_profile
from namo_fault_recovery.model.urdf_tree import load_urdf_tree
from namo_fault_recovery.resources import distribution_file
import pytest
from robot_urdfs import installed_urdf, TALOS_URDF, TIAGO_URDF
import yaml

ROOT = Path(__file__).resolve().parent.parent
NAMO = ROOT / 'config' / 'namo_profile.yaml'
TALOS = ROOT / 'config' / 'robots' / 'talos.yaml'
TIAGO = ROOT / 'config' / 'robots' / 'tiago_dual.yaml'


def test_packaged_profiles_load_with_their_roles():
    namo = load_profile(NAMO)
    assert set(namo.arms) == {'right', 'left'} and namo.shared == ()
    assert namo.arms['left'].joints == namo.arms['left'].chain.joint_names
    assert namo.velocity_limits['right_arm_joint1'] == pytest.approx(1.5707963, abs=1e-6)
    talos = load_profile(TALOS)
    right = talos.arms['right']
    assert right.chain.joint_names[:2] == ('torso_1_joint', 'torso_2_joint')
    assert right.expansion == ('torso_1_joint', 'torso_2_joint') and right.held == ()
    assert len(right.joints) == 7 and talos.shared == ('torso_1_joint', 'torso_2_joint')
    assert right.landmark_links == {'elbow': 'arm_right_4_link', 'wrist': 'arm_right_5_link',
                                    'tip': 'gripper_right_base_link',
                                    'palm': 'arm_right_7_link'}
    assert talos.velocity_limits['arm_right_1_joint'] == 2.7      # from the URDF
    tiago = load_profile(TIAGO)
    assert tiago.arms['left'].chain.base == 'torso_lift_link'
    assert tiago.arms['left'].chain.n_joints == 7 and tiago.shared == ()


def _write(tmp_path, doc):
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


def _talos_doc():
    doc = yaml.safe_load(TALOS.read_text())
    doc['urdf'] = str(distribution_file('example-robot-data', TALOS_URDF))
    return doc


def _break(doc, change):
    change(doc)
    return doc


@pytest.mark.parametrize('change, says', [
    (lambda d: d['arms']['right']['landmarks'].update(elbow='arm_right_44_link'),
     "arms.right: no link 'arm_right_44_link' in robot 'talos'"),
    (lambda d: d['arms']['right'].update(base='arm_left_1_link'),
     "no path from base link 'arm_left_1_link' down to tip link 'gripper_right_base_link'"),
    (lambda d: d.update(shared=[]),
     "joint 'torso_1_joint' is in arms right and left without being declared shared"),
    (lambda d: d['arms']['right']['landmarks'].update(wrist='arm_left_5_link'),
     "link 'arm_left_5_link' is not fixed to the chain base_link -> gripper_right_base_link"),
    (lambda d: d['arms']['right'].update(joints=d['arms']['right']['joints'][:4]),
     "key 'arms.right.joints': 4 joints; the model takes 5 to 8 joints per arm"),
    (lambda d: d['arms']['right']['joints'].append('arm_left_1_joint'),
     "joint 'arm_left_1_joint' is not a revolute or continuous joint of the chain"),
    (lambda d: d['arms']['right'].update(colour='red'), "key 'arms.right.colour': unknown key"),
    (lambda d: d.update(velocity_limits={'arm_right_1_joint': -1}),
     "key 'velocity_limits.arm_right_1_joint': expected rad/s above 0"),
])
def test_a_bad_profile_is_one_line_naming_file_key_and_expectation(tmp_path, change, says):
    path = _write(tmp_path, _break(_talos_doc(), change))
    with pytest.raises(ConfigError) as err:
        load_profile(path)
    message = str(err.value)
    assert says in message and '\n' not in message
    assert str(path) in message


def test_a_urdf_that_does_not_parse_names_the_urdf(tmp_path):
    (tmp_path / 'broken.urdf').write_text('<robot name="x"><link name="a"/')
    path = _write(tmp_path, _break(_talos_doc(), lambda d: d.update(urdf='broken.urdf')))
    with pytest.raises(ConfigError, match=r'broken\.urdf: not a URDF that parses'):
        load_profile(path)


def test_a_prismatic_joint_in_the_chain_is_refused_naming_it(tmp_path):
    doc = yaml.safe_load(TIAGO.read_text())
    doc['urdf'] = str(distribution_file('example-robot-data', TIAGO_URDF))
    doc['arms']['left']['base'] = 'torso_fixed_link'
    with pytest.raises(ConfigError) as err:
        load_profile(_write(tmp_path, doc))
    assert "joint 'torso_lift_joint' on the chain torso_fixed_link -> " in str(err.value)
    assert 'is prismatic; expected revolute, continuous or fixed joints only' in str(err.value)


def test_a_missing_velocity_limit_must_come_from_the_profile(tmp_path):
    urdf = (ROOT / 'config' / 'namo.urdf').read_text()
    urdf = urdf.replace(' velocity="1.57079633" />', ' />', 1)
    (tmp_path / 'namo.urdf').write_text(urdf)
    doc = yaml.safe_load(NAMO.read_text())
    path = _write(tmp_path, doc)
    with pytest.raises(ConfigError, match="velocity_limits.right_arm_joint1': missing key"):
        load_profile(path)
    doc['velocity_limits'] = {'right_arm_joint1': 1.0}
    assert load_profile(_write(tmp_path, doc)).velocity_limits['right_arm_joint1'] == 1.0


def _arms(doc):
    """Return what a profile says per arm, without the file's own keys (urdf, comments)."""
    return {side: {k: arm[k] for k in ('base', 'tip', 'landmarks', 'joints', 'expansion')
                   if k in arm} for side, arm in doc['arms'].items()}


def test_the_template_of_namo_is_its_packaged_profile():
    tree = load_urdf_tree(ROOT / 'config' / 'namo.urdf')
    template = guess_profile(tree, 'namo.urdf')
    doc = yaml.safe_load(template.text)
    packaged = yaml.safe_load(NAMO.read_text())
    for arm in doc['arms'].values():
        assert arm.pop('expansion') == []
        assert arm['landmarks']['fingertip'] == {'link': arm['tip'], 'offset': [0, 0, 0]}
        arm['landmarks']['fingertip'] = arm['tip']
    assert _arms(doc) == _arms(packaged)
    assert template.missing == [f'{s} fingertip offset: unknown; wrote [0, 0, 0] m in '
                                f'{s}_arm_fingertip' for s in ('right', 'left')]


@pytest.mark.parametrize('profile, urdf, edited, top', [
    (TALOS, TALOS_URDF, {('right', 'tip'), ('left', 'tip'), ('right', 'landmarks'),
                         ('left', 'landmarks')}, {'capsules': {'upper_arm': 100}}),
    (TIAGO, TIAGO_URDF, set(), {}),
])
def test_shipped_profiles_are_the_template_plus_the_readme_edits(profile, urdf, edited, top):
    template = yaml.safe_load(guess_profile(
        load_urdf_tree(distribution_file('example-robot-data', urdf)), 'x.urdf').text)
    shipped = yaml.safe_load(profile.read_text())
    assert shipped['urdf'] == {'file': urdf, 'distribution': 'example-robot-data'}
    assert {k: v for k, v in template.items() if k not in ('urdf', 'arms')} == \
        {k: v for k, v in shipped.items() if k not in ('urdf', 'arms') and k not in top}
    assert {k: shipped[k] for k in top} == top
    guessed, kept = _arms(template), _arms(shipped)
    differ = {(side, key) for side in kept for key in kept[side]
              if kept[side][key] != guessed[side][key]}
    assert differ == edited


def test_profile_command_writes_a_loading_template_and_reports(tmp_path):
    out = io.StringIO()
    urdf = distribution_file('example-robot-data', TIAGO_URDF)
    target = tmp_path / 'tiago.yaml'
    assert cli_main(['profile', '--urdf', str(urdf), '--out', str(target)], out=out) == 0
    text = out.getvalue()
    assert 'right elbow: arm_right_4_link' in text and 'the template loads as it is' in text
    assert 'torso_lift_joint above torso_lift_link is prismatic' in text
    assert load_profile(target).arms['right'].chain.tip == 'hand_right_grasping_frame'


def test_profile_command_on_a_bad_urdf_is_a_usage_error(tmp_path, capsys):
    (tmp_path / 'x.urdf').write_text('<robot name="x"><link name="a"/')
    assert cli_main(['profile', '--urdf', str(tmp_path / 'x.urdf')]) == 2
    assert 'not a URDF that parses' in capsys.readouterr().err


def test_bench_fk_prints_the_ratio_and_agrees(tmp_path):
    out = io.StringIO()
    argv = ['bench', 'fk', '--batch', '50', '--rounds', '3', '--out', str(tmp_path)]
    assert cli_main(argv, out=out) == 0
    text = out.getvalue()
    assert 'fk ratio' in text and 'fk (engine robot) ratio' in text and 'URDF / DH' in text
    doc = yaml.safe_load((tmp_path / 'fk.json').read_text())
    assert doc['max_difference_mm'] < 1e-5 and doc['fk']['ratio'] > 0


def test_the_template_says_when_it_finds_no_arm_and_that_profile_is_refused(tmp_path):
    links = ''.join(f'<link name="l{i}"/>' for i in range(4))
    joints = ''.join(f'<joint name="j{i}" type="revolute"><parent link="l{i}"/>'
                     f'<child link="l{i + 1}"/><axis xyz="0 0 1"/>'
                     '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
                     for i in range(3))
    urdf = tmp_path / 'three.urdf'
    urdf.write_text(f'<robot name="three">{links}{joints}</robot>')
    template = guess_profile(load_urdf_tree(urdf), 'three.urdf')
    assert template.guessed == []
    assert template.missing[0].startswith('arms: no serial run of 5 or more revolute joints')
    path = tmp_path / 'three.yaml'
    path.write_text(template.text)
    with pytest.raises(ConfigError, match="key 'arms': expected one or two of right, left"):
        load_profile(path)


def test_the_template_finds_arms_that_hang_from_their_branch_by_a_fixed_mount(tmp_path):
    """Baxter's arms start below a fixed mount joint (right_torso_arm_mount, then right_s0)."""
    urdf = installed_urdf('baxter')
    template = guess_profile(load_urdf_tree(urdf), str(urdf))
    doc = yaml.safe_load(template.text)
    for side in ('right', 'left'):
        assert doc['arms'][side]['joints'] == [f'{side}_{j}' for j in (
            's0', 's1', 'e0', 'e1', 'w0', 'w1', 'w2')], doc['arms'][side]
        assert doc['arms'][side]['base'] == 'torso'
    path = tmp_path / 'baxter.yaml'
    path.write_text(template.text)
    profile = load_profile(path)
    assert profile.arms['left'].chain.n_joints == 7
