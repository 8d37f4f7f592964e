"""
The node's robot from its parameters: robot_file, or robot_profile (+ robot_description).

ROS-free and fast: :mod:`namo_fault_recovery.runtime.robot_source` reads the parameters
and loads the robot and its library as the node and its engine process do; every refusal
is one line naming the parameter or file, the value and what was expected.  Talos comes
from example-robot-data (the tests' extra, as in test_profile.py).
"""

import io
from pathlib import Path

from namo_fault_recovery.errors import ConfigError
from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.model.robot import load_robot
from namo_fault_recovery.resources import distribution_file
from namo_fault_recovery.runtime.robot_source import load_models, robot_source, RobotSource
import pytest
import yaml

CONFIG = Path(__file__).resolve().parent.parent / 'config'
TALOS = CONFIG / 'robots' / 'talos.yaml'
TALOS_LIBRARY = CONFIG / 'robots' / 'talos_gestures.yaml'
TIAGO_LIBRARY = CONFIG / 'robots' / 'tiago_dual_gestures.yaml'


def one_line(exc):
    text = str(exc.value)
    assert '\n' not in text, text
    return text


@pytest.fixture(scope='module')
def talos_urdf():
    doc = yaml.safe_load(TALOS.read_text())
    return Path(distribution_file(doc['urdf']['distribution'], doc['urdf']['file']))


@pytest.fixture(scope='module')
def talos(talos_urdf):
    return load_models(robot_source({'robot_profile': str(TALOS)}), str(TALOS_LIBRARY))


def test_no_profile_is_the_dh_robot_file():
    assert robot_source({'robot_file': '', 'robot_profile': '',
                         'robot_description': ''}) == RobotSource()
    assert robot_source({'robot_file': 'r.yaml'}) == RobotSource(robot_file='r.yaml')
    robot, library = load_models(RobotSource())
    assert robot.name == 'namo' and len(library) == 4


def test_profile_and_robot_file_together_are_refused():
    with pytest.raises(ValueError) as exc:
        robot_source({'robot_file': 'namo.yaml', 'robot_profile': 'talos.yaml'})
    text = one_line(exc)
    assert text.startswith('robot_profile: talos.yaml is given with robot_file namo.yaml')
    assert 'expected one of the two' in text


def test_a_description_needs_a_profile_and_must_be_a_urdf_document():
    with pytest.raises(ValueError) as exc:
        robot_source({'robot_description': '<robot name="x"/>'})
    assert one_line(exc).startswith('robot_description: a URDF without robot_profile; '
                                    'expected robot_profile too')
    with pytest.raises(ValueError) as exc:
        robot_source({'robot_profile': 'p.yaml', 'robot_description': 'talos.urdf'})
    text = one_line(exc)
    assert "expected a URDF document (XML text starting with '<'), got 'talos.urdf'" in text


def test_talos_from_its_profile_with_its_library(talos):
    robot, library = talos
    assert robot.name == 'talos'
    assert robot.joint_names[0] == 'arm_right_1_joint'
    assert robot.joint_names[7] == 'arm_left_1_joint'
    assert library.names == ('wai', 'bye', 'salute', 'side_invite')


def test_the_description_replaces_the_profiles_urdf(talos, talos_urdf):
    source = robot_source({'robot_profile': str(TALOS),
                           'robot_description': talos_urdf.read_text()})
    robot, _ = load_models(source, str(TALOS_LIBRARY))
    assert robot.joint_names == talos[0].joint_names
    assert robot.geometry_key() == talos[0].geometry_key()
    # The capsules are fitted to the document's collision meshes, found from the folder
    # of the URDF the profile names: the same as from the file.
    assert robot.capsules == talos[0].capsules
    assert source.describe() == f'profile {TALOS} with robot_description'


def test_a_description_without_the_profiles_links_names_the_profile_and_link(talos_urdf):
    source = robot_source({'robot_profile': str(TALOS),
                           'robot_description': '<robot name="other"><link name="a"/></robot>'})
    with pytest.raises(ConfigError) as exc:
        source.load()
    text = one_line(exc)
    assert text.startswith(f'<robot_description>: profile {TALOS}, arms.right: no link '
                           "'base_link' in robot 'other'")


def test_a_profile_naming_a_missing_urdf_names_the_profile_and_its_key(tmp_path):
    profile = tmp_path / 'robot.yaml'
    profile.write_text(TALOS.read_text().replace(
        'urdf: {file: talos_data/robots/talos_reduced.urdf, distribution: example-robot-data}',
        'urdf: talos_missing.urdf'))
    with pytest.raises(ConfigError) as exc:
        load_models(robot_source({'robot_profile': str(profile)}), str(TALOS_LIBRARY))
    text = one_line(exc)
    assert text.startswith(f"{profile}: key 'urdf': no URDF file {tmp_path}/talos_missing.urdf;"
                           ' expected a readable file')


def test_a_missing_profile_is_named(tmp_path):
    with pytest.raises(ConfigError) as exc:
        load_models(robot_source({'robot_profile': str(tmp_path / 'none.yaml')}))
    assert one_line(exc).startswith(f'{tmp_path}/none.yaml: cannot read file')


def test_the_packaged_namo_library_on_talos_says_to_give_talos_library(talos):
    with pytest.raises(ConfigError) as exc:
        load_models(robot_source({'robot_profile': str(TALOS)}))
    text = one_line(exc)
    assert text.startswith(f'{TALOS}: gesture_file is empty and the packaged library '
                           "(Namo's) does not fit robot 'talos'")
    assert text.endswith("expected gesture_file set to a library of 'talos'")


def test_a_library_made_for_another_robot_is_refused(talos):
    robot, _ = talos
    with pytest.raises(ConfigError) as exc:       # TIAGo++'s, 7 joints per arm too
        load_library(robot, TIAGO_LIBRARY)
    assert one_line(exc).startswith(
        f"{TIAGO_LIBRARY}: key 'robot': a library for robot 'tiago_dual', whose joints are "
        "not those of robot 'talos'")
    with pytest.raises(ConfigError) as exc:       # Namo's limits (+-180 deg) would take it
        load_library(load_robot(), TALOS_LIBRARY)
    assert one_line(exc).startswith(f"{TALOS_LIBRARY}: key 'robot': a library for robot "
                                    "'talos', whose joints are not those of robot 'namo'")


def test_namo_recovery_library_prints_talos_arms_by_their_joint_names(talos):
    from namo_fault_recovery.cli.node_commands import arm_of, format_library
    from namo_fault_recovery.recovery.result import reference_result
    from namo_fault_recovery.ros.client import PublishedLibrary
    robot, library = talos
    assert [arm_of(j) for j in ('right_arm_joint2', 'arm_left_4_joint', 'torso_1_joint',
                                'upright_joint')] == ['right', 'left', None, None]
    out = io.StringIO()
    format_library(PublishedLibrary(1, tuple(robot.joint_names), reference_result(library),
                                    0.0, True), out)
    wai = out.getvalue().split('\nwai\n')[1].split('\nbye\n')[0].splitlines()
    assert [row.split()[0] for row in wai] == ['t', 'right', 'left'], out.getvalue()
    assert len(wai[1].split()) == len(wai[2].split()) == 8       # the side + 7 angles
