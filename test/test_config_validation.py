"""Every config validation error names the file, the key and the problem."""

import copy
import re
import shutil

from conftest import CONFIG_DIR
from namo_fault_recovery import ConfigError, load_library, load_robot
import numpy as np
import pytest
import yaml

ROBOT = yaml.safe_load((CONFIG_DIR / 'namo_robot.yaml').read_text())
GESTURES = yaml.safe_load((CONFIG_DIR / 'gestures.yaml').read_text())


def _write(tmp_path, name, data):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


def _robot_with(tmp_path, edit):
    data = copy.deepcopy(ROBOT)
    edit(data)
    return _write(tmp_path, 'robot.yaml', data)


def _assert_error(exc_info, path, key, problem):
    text = str(exc_info.value)
    assert str(path) in text
    assert f"key '{key}'" in text
    assert re.search(problem, text), text


@pytest.mark.parametrize('edit, key, problem', [
    (lambda d: d['dh'].pop('joints'), 'dh.joints', 'missing key'),
    (lambda d: d.pop('units'), 'units', 'missing key'),
    (lambda d: d['arms'].pop('left'), 'arms.left', 'missing key'),
    (lambda d: d['dh']['joints'][2].pop(), 'dh.joints[2]', 'expected 4 values, got 3'),
    (lambda d: d['arms']['right']['limits'].__setitem__(0, [1, 2, 3]),
     'arms.right.limits[0]', 'expected 2 values, got 3'),
    (lambda d: d['dh']['joints'][0].__setitem__(1, 'long'), 'dh.joints[0][1]',
     "expected a number, got 'long'"),
    (lambda d: d['units'].__setitem__('angle', 'grad'), 'units.angle',
     "unknown angle unit 'grad'"),
    (lambda d: d['units'].__setitem__('length', 'inch'), 'units.length',
     "unknown length unit 'inch'"),
    (lambda d: d['arms']['left']['limits'].__setitem__(3, [90, -90]),
     'arms.left.limits[3]', 'lower limit 90 is above upper limit -90'),
    (lambda d: d['arms']['left']['joints'].__setitem__(0, 'right_arm_joint1'),
     'arms.left.joints[0]', "duplicate joint name 'right_arm_joint1'"),
])
def test_robot_file_errors(tmp_path, edit, key, problem):
    path = _robot_with(tmp_path, edit)
    with pytest.raises(ConfigError) as exc_info:
        load_robot(path)
    _assert_error(exc_info, path, key, problem)


def test_robot_file_unreadable_or_not_yaml(tmp_path):
    with pytest.raises(ConfigError, match='cannot read file'):
        load_robot(tmp_path / 'absent.yaml')
    bad = _write(tmp_path, 'bad.yaml', 'dh: [unclosed')
    with pytest.raises(ConfigError, match='not valid YAML'):
        load_robot(bad)
    empty = _write(tmp_path, 'empty.yaml', '')
    with pytest.raises(ConfigError, match='empty'):
        load_robot(empty)


def test_radians_and_metres_are_accepted(tmp_path):
    data = copy.deepcopy(ROBOT)
    data['units'] = {'length': 'm', 'angle': 'rad'}
    for row in data['dh']['joints']:
        row[:] = [float(np.radians(row[0])), row[1] / 1000, row[2] / 1000,
                  float(np.radians(row[3]))]
    ee = data['dh']['end_effector']
    data['dh']['end_effector'] = [0, 0, ee[2] / 1000, 0]
    for side in ('right', 'left'):
        data['arms'][side]['limits'] = [[-float(np.pi), float(np.pi)]] * 7
    robot_m = load_robot(_write(tmp_path, 'r.yaml', data))
    robot_mm = load_robot()
    np.testing.assert_allclose(robot_m.d, robot_mm.d)
    np.testing.assert_allclose(robot_m.alpha_prev, robot_mm.alpha_prev)
    np.testing.assert_allclose(robot_m.arms['left'].upper, robot_mm.arms['left'].upper)


def _gestures_with(tmp_path, edit):
    data = copy.deepcopy(GESTURES)
    edit(data)
    # The packaged library's dense motions are CSV files beside it.
    shutil.copytree(CONFIG_DIR / 'trajectories', tmp_path / 'trajectories',
                    dirs_exist_ok=True)
    return _write(tmp_path, 'gestures.yaml', data)


def _set_left(data, value):
    data['gestures'][1]['keyframes'][0]['left'] = value


@pytest.mark.parametrize('edit, key, problem', [
    (lambda d: _set_left(d, {'left_arm_joint1': 0, 'left_arm_joint9': 0}),
     'gestures[1].keyframes[0].left.left_arm_joint9', "unknown joint 'left_arm_joint9'"),
    (lambda d: d['gestures'][2]['keyframes'][0].pop('left'),
     'gestures[2].keyframes[0].left', 'missing key'),
    (lambda d: d['gestures'].clear(), 'gestures', 'the library is empty'),
    (lambda d: d['gestures'][3].__setitem__('name', 'bye'), 'gestures[3].name',
     "duplicate gesture name 'bye'"),
    (lambda d: d['gestures'][0]['keyframes'].append(
        dict(d['gestures'][0]['keyframes'][0], time_from_start=1.0)),
     'gestures[0].keyframes[1].time_from_start', 'strictly increasing; got 1 after 2'),
    (lambda d: d.__setitem__('units', 'turns'), 'units', "unknown angle unit 'turns'"),
    (lambda d: d['gestures'][1]['keyframes'][0]['right'].__setitem__(0, 270),
     'gestures[1].keyframes[0].right[0]', 'outside its limits'),
    (lambda d: d['gestures'][1].__setitem__('arms', ['right', 'middle']),
     'gestures[1].arms', 'distinct arms'),
    (lambda d: d['gestures'][1]['keyframes'][0].__setitem__('right', [1, 2, 3]),
     'gestures[1].keyframes[0].right', 'expected 7 values, got 3'),
])
def test_gesture_file_errors(tmp_path, robot, edit, key, problem):
    path = _gestures_with(tmp_path, edit)
    with pytest.raises(ConfigError) as exc_info:
        load_library(robot, path)
    text = str(exc_info.value)
    assert str(path) in text and key in text, text
    assert re.search(problem, text), text


def test_joint_map_form_is_accepted(tmp_path, robot, library):
    names = robot.arms['left'].joint_names
    path = _gestures_with(tmp_path, lambda d: _set_left(d, dict.fromkeys(names, 0)))
    loaded = load_library(robot, path)
    np.testing.assert_array_equal(loaded['bye'].keyframes[0].left, np.zeros(7))


def test_packaged_library(library):
    assert library.names == ('wai', 'bye', 'salute', 'side_invite')
    wai = library['wai']
    assert wai.two_handed and wai.arms == ('right', 'left')
    np.testing.assert_array_equal(wai.keyframes[0].left, wai.keyframes[0].right)
    np.testing.assert_allclose(np.degrees(library['salute'].keyframes[0].right),
                               [100, -43, -45, 100, 47, 28, 10])
    for g in library:
        assert not g.two_handed or g.name == 'wai'
        assert g.keyframes[0].time_from_start > 0
    with pytest.raises(KeyError, match="unknown gesture 'hug'"):
        library['hug']


def test_lock_averages_equal_table_2(library):
    np.testing.assert_allclose(np.degrees(library.lock_averages('right')),
                               [52.5, -14.25, -5.25, 89.25, 8.75, -5.75, 30.5], atol=1e-9)
    # The left arm only takes part in Wai, so its averages are Wai's angles.
    np.testing.assert_allclose(np.degrees(library.lock_averages('left')),
                               [30, 5, -45, 90, -10, -45, 45], atol=1e-9)


def test_demo_library_is_the_packaged_gestures_plus_the_circle(product_library, demo_library):
    # The packaged library is exactly Namo's four gestures; the demo adds the circle.
    assert product_library.names == ('wai', 'bye', 'salute', 'side_invite')
    assert demo_library.names == product_library.names + ('circle',)
    for g in product_library:
        d = demo_library[g.name]
        # demo_motions.yaml copies gestures.yaml's gestures: they must not drift apart.
        for field in ('arms', 'two_handed', 'description', 'weights', 'joints', 'expand'):
            assert getattr(d, field) == getattr(g, field), (g.name, field)
        assert len(d.keyframes) == len(g.keyframes)
        for a, b in zip(d.keyframes, g.keyframes):
            assert a.time_from_start == b.time_from_start
            np.testing.assert_array_equal(a.right, b.right)
            np.testing.assert_array_equal(a.left, b.left)
    assert len(demo_library['circle'].keyframes) == 100
