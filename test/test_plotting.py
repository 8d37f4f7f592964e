"""Figures: stick-figure PNGs, box plots, and the message when matplotlib is missing."""

import io
import sys

from namo_fault_recovery.benchmarks import common, plotting
from namo_fault_recovery.cli.main import main
from namo_fault_recovery.resources import config_path, PAPER_GESTURE_FILE
import numpy as np
import pytest

PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


def _is_png(path):
    with open(path, 'rb') as fh:
        data = fh.read()
    return data[:8] == PNG_MAGIC and data[12:16] == b'IHDR' and len(data) > 1000


def test_plot_command_writes_png(tmp_path):
    path = tmp_path / 'wai.png'
    out = io.StringIO()
    code = main(['--gesture-file', str(config_path(PAPER_GESTURE_FILE)), 'plot', '--gesture',
                 'wai', '--fault', 'right_arm_joint2', '--out', str(path)], out)
    assert code == 0
    assert _is_png(path)
    text = out.getvalue()
    assert 'lock right_arm_joint2 = -14.25 deg' in text   # Table 2's average
    assert 'left  reconfigured' in text   # both arms for Wai


def test_plot_function_one_arm_explicit_lock(robot, library, tmp_path):
    report = common.run_recover(robot, library, {'right_arm_joint4': np.radians(60.0)},
                                seed=0, gestures=['salute'])
    assert report.names == ('salute',)
    assert report['salute'].positions[0][3] == pytest.approx(np.radians(60.0))
    path = plotting.plot_reconfiguration(robot, library, report, 'salute',
                                         tmp_path / 'sub' / 'salute.png')
    assert _is_png(path)


def test_arm_points_start_at_the_shoulder(robot):
    pts, normal = plotting.arm_points(robot, np.radians([30, 5, -45, 90, -10, -45, 45]),
                                      'right')
    assert pts.shape == (4, 3)
    np.testing.assert_allclose(pts[0], [0.0, -182.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(pts[2], [222.66, -18.89, -94.33], atol=0.01)
    assert normal[1] > 0.9   # in Wai the right palm faces the left hand (+y)


def test_boxplot_paper(tmp_path):
    runs = {(k, 'bye', 'right_arm_joint2'): [{'score': s + i, 'time': 0.1 * (i + 1)}
                                             for i, s in enumerate((3.0, 4.0, 5.0))]
            for k in ('a', 'b')}
    paths = plotting.boxplot_paper(runs, ['a', 'b'], [('bye', 'right_arm_joint2')], tmp_path)
    assert [p.name for p in paths] == ['scores_bye.png', 'times.png']
    assert all(_is_png(p) for p in paths)


def test_without_matplotlib_says_how_to_install(monkeypatch, capsys, tmp_path):
    for name in list(sys.modules):
        if name == 'matplotlib' or name.startswith(('matplotlib.', 'mpl_toolkits')):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, 'matplotlib', None)
    with pytest.raises(plotting.MatplotlibMissing, match='pip install matplotlib'):
        plotting._figure((1, 1))
    path = tmp_path / 'x.png'
    code = main(['plot', '--gesture', 'wai', '--fault', 'right_arm_joint2', '--out', str(path)],
                io.StringIO())
    assert code == 2
    assert 'pip install matplotlib' in capsys.readouterr().err
    assert not path.exists()


@pytest.mark.parametrize('argv, message', [
    (['plot', '--gesture', 'nope', '--fault', 'right_arm_joint2'], 'unknown gesture'),
    (['plot', '--gesture', 'wai', '--fault', 'bogus'], 'unknown joint'),
    (['plot', '--gesture', 'wai', '--fault', 'right_arm_joint2=abc'], 'JOINT=DEG'),
    (['plot', '--gesture', 'wai', '--fault', 'right_arm_joint2', '--keyframe', '3'],
     '--keyframe'),
])
def test_plot_bad_arguments_exit_2(capsys, argv, message):
    assert main(argv, io.StringIO()) == 2
    assert message in capsys.readouterr().err
