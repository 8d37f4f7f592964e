"""``namo-recovery export --format play_motion2``: the file parses back to the library."""

import io
import math

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.cli.main import main
from namo_fault_recovery.playback.export import load_motions
import numpy as np
import yaml

ROBOT = load_robot()
LIBRARY = load_library(ROBOT)


def test_solved_library_exports_and_parses_back(tmp_path):
    path = tmp_path / 'motions.yaml'
    out = io.StringIO()
    code = main(['export', '--format', 'play_motion2', '--out', str(path),
                 '--fault', 'right_arm_joint2=-20', '--seed', '3', '--deadline', '2.0'], out)
    assert code == 0, out.getvalue()
    text = path.read_text()
    params = yaml.safe_load(text)['play_motion2']['ros__parameters']
    assert params['controllers'] == ['right_arm_controller', 'left_arm_controller']
    motions = load_motions(text)
    assert sorted(motions) == sorted(LIBRARY.names)
    j2 = ROBOT.joint_names.index('right_arm_joint2')
    for gesture in LIBRARY:
        joints, times, positions = motions[gesture.name]
        assert joints == list(ROBOT.joint_names)
        assert times == [kf.time_from_start for kf in gesture.keyframes]
        assert np.all(positions[:, j2] == math.radians(-20.0))
        meta = params['motions'][gesture.name]['meta']
        assert meta['usage'] == 'gesture' and 'right_arm_joint2 locked at -20.00' in \
            meta['description']


def test_export_is_exact_for_the_reference(tmp_path):
    from namo_fault_recovery.playback.export import dump, motions_document
    motions = [(g.name, ROBOT.joint_names, [kf.time_from_start for kf in g.keyframes],
                [np.concatenate([kf.right, kf.left]) for kf in g.keyframes])
               for g in LIBRARY]
    back = load_motions(dump(motions_document(motions)))
    for name, joints, times, positions in motions:
        assert np.array_equal(back[name][2], np.array(positions))   # float repr round-trips
        assert back[name][1] == times


def test_export_without_a_node_fails_in_one_line(capsys):
    code = main(['export', '--timeout', '0.5', '--domain-id', '231'], io.StringIO())
    assert code == 2
    assert 'nothing received on /gesture_library' in capsys.readouterr().err
