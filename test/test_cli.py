"""The namo-recovery command line: happy paths and one-line errors with exit code 2."""

import argparse
import io
import json
from pathlib import Path
import subprocess
import sys

from namo_fault_recovery.benchmarks.common import ModelFiles
from namo_fault_recovery.cli.main import build_parser, main
from namo_fault_recovery.runtime.private_node import NodeTarget
import pytest


def run(argv):
    out = io.StringIO()
    return main(argv, out), out.getvalue()


PAPER = str(Path(__file__).resolve().parent.parent / 'config' / 'paper_gestures.yaml')
DEMO = str(Path(__file__).resolve().parent.parent / 'config' / 'demo_motions.yaml')


def test_show_prints_library_and_landmarks():
    code, text = run(['show'])
    assert code == 0
    for name in ('wai', 'bye', 'salute', 'side_invite'):
        assert f'\n{name}:' in text
    assert '\ncircle:' not in text                     # the demo library's, below
    assert '52.50,  -14.25' in text                    # Table 2 lock averages
    code, text = run(['--gesture-file', DEMO, 'show'])
    assert code == 0
    for name in ('wai', 'bye', 'salute', 'side_invite', 'circle'):
        assert f'\n{name}:' in text


def test_show_paper_library_lock_averages():
    code, text = run(['--gesture-file', PAPER, 'show'])
    assert code == 0
    assert '(  222.66,   -18.89,   -94.33)' in text   # Wai right wrist
    assert '(  222.66,    18.89,   -94.33)' in text   # its mirror, the left wrist
    assert '52.50,  -14.25' in text                    # Table 2 lock averages


def test_score_check_value():
    code, text = run(['score', '--gesture', 'wai', '--right', '30', '-14.25', '-45', '90',
                      '-10', '-45', '45'])
    assert code == 0
    assert 'score 61.9614' in text
    assert 'wrist_lr' in text


def test_score_json():
    code, text = run(['score', '--gesture', 'bye', '--right', '46', '-11', '24', '95', '-53',
                      '-32', '41', '--json'])
    doc = json.loads(text)
    assert code == 0 and doc['score'] == pytest.approx(0, abs=1e-9)
    assert set(doc['components']) >= {'elbow', 'wrist', 'tip', 'palm'}


@pytest.mark.parametrize('argv, message', [
    (['score', '--gesture', 'hug', '--right'] + ['0'] * 7, "unknown gesture 'hug'"),
    (['score', '--gesture', 'wai', '--right', '1', '2'], 'expected 7 angles'),
    (['score', '--gesture', 'wai', '--right'] + ['x'] * 7, 'could not convert'),
    (['score', '--gesture', 'wai', '--right'] + ['nan'] * 7, 'finite'),
    (['dance'], 'invalid choice'),
    (['--robot-file', '/nonexistent.yaml', 'show'], 'cannot read file'),
])
def test_bad_arguments_one_line_exit_2(capsys, argv, message):
    code, _ = run(argv)
    err = capsys.readouterr().err
    assert code == 2
    assert message in err
    assert err.count('\n') == 1 and 'Traceback' not in err


def test_console_entry_point_runs_as_a_process():
    proc = subprocess.run([sys.executable, '-m', 'namo_fault_recovery.cli.main', 'score',
                           '--gesture', 'nope', '--right'] + ['0'] * 7,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.startswith('namo-recovery: error:')
    assert 'Traceback' not in proc.stderr


def test_node_benchmarks_get_their_node_and_models_as_one_object_each():
    args = build_parser().parse_args(
        ['bench', 'stream', '--start-node', '--gesture-file', 'g.yaml', '--robot-file',
         'r.urdf', '--node-param', 'contingency_table:=false', '--domain-id', '5'])
    assert NodeTarget.from_args(args) == NodeTarget(True, 5, 'r.urdf', 'g.yaml',
                                                    ('contingency_table:=false',))
    assert ModelFiles.from_args(args) == ModelFiles('r.urdf', 'g.yaml')
    running = NodeTarget.from_args(build_parser().parse_args(['bench', 'latency']))
    assert running.start(out=io.StringIO()) == (None, None)


def test_bench_stream_takes_the_global_files_and_domain():
    # bench stream declared --gesture-file, --robot-file and --domain-id again with
    # default None, which overwrote the global options given before the command.
    glob = ['--gesture-file', 'g.yaml', '--robot-file', 'r.yaml', '--domain-id', '5']
    for command in (['bench', 'stream'], ['bench', 'latency']):
        args = build_parser().parse_args(glob + command + ['--start-node'])
        assert NodeTarget.from_args(args) == NodeTarget(True, 5, 'r.yaml', 'g.yaml', ()), command
        assert ModelFiles.from_args(args) == ModelFiles('r.yaml', 'g.yaml'), command
    # Given after the command, the command's own option wins.
    args = build_parser().parse_args(glob + ['bench', 'stream', '--gesture-file', 'h.yaml',
                                             '--robot-file', 's.yaml', '--domain-id', '6'])
    assert NodeTarget.from_args(args) == NodeTarget(False, 6, 's.yaml', 'h.yaml', ())
    args = build_parser().parse_args(['bench', 'stream'])
    assert NodeTarget.from_args(args) == NodeTarget(False, None, None, None, ())


def _parsers(parser, path):
    """Yield (command path, parser) for ``parser`` and every subcommand under it."""
    yield ' '.join(path), parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, path + [name])


def test_every_command_has_a_help_page():
    # argparse expands '%' in help texts: a bare one ('% of one core') made
    # 'namo-recovery bench --help' raise TypeError instead of printing the page.
    pages = dict(_parsers(build_parser(), ['namo-recovery']))
    assert 'namo-recovery bench idle' in pages
    for path, parser in pages.items():
        text = parser.format_help()
        assert path.split()[-1] in text, path


ROBOTS = Path(__file__).resolve().parent.parent / 'config' / 'robots'


def test_the_global_robot_profile_solves_shows_and_scores_another_robot(capsys):
    """show, score, solve (and export, precompute) take any robot as the node does."""
    from robot_urdfs import installed_urdf
    installed_urdf('talos')
    robot = ['--robot-profile', str(ROBOTS / 'talos.yaml'),
             '--gesture-file', str(ROBOTS / 'talos_gestures.yaml')]
    code, text = run(robot + ['solve', '--fault', 'arm_right_4_joint', '--seed', '0',
                              '--gesture', 'salute', '--json'])
    assert code == 0, capsys.readouterr().err
    doc = json.loads(text)
    assert doc['robot'] == 'talos' and list(doc['locks']) == ['arm_right_4_joint']
    code, text = run(robot + ['show'])
    assert code == 0 and 'robot: talos' in text and '\nside_invite:' in text
    code, text = run(robot + ['score', '--gesture', 'wai', '--right'] + ['0'] * 7)
    assert code == 0 and text.startswith('gesture wai (keyframe 0): score ')
    assert run(robot + ['score', '--gesture', 'wai', '--right', '0', '0'])[0] == 2
    assert '--right: expected 7 angles in degrees, got 2' in capsys.readouterr().err


def test_a_profile_where_a_dh_file_is_expected_says_so_on_one_line(capsys):
    """--robot-file with a profile, and --robot-profile with a DH-only command."""
    talos = str(ROBOTS / 'talos.yaml')
    assert run(['--robot-file', talos, 'show'])[0] == 2
    err = capsys.readouterr().err.strip()
    assert err == (f'namo-recovery: error: {talos}: a recovery profile (a robot from its '
                   'URDF), not a DH robot file; expected it as robot_profile '
                   '(--robot-profile on the command line)')
    assert run(['--robot-profile', talos, 'bench', 'fk'])[0] == 2
    err = capsys.readouterr().err
    assert '--robot-profile: namo-recovery bench runs on a DH robot file' in err
    assert run(['--robot-profile', talos, '--robot-file', talos, 'solve'])[0] == 2
    assert 'expected one of the two' in capsys.readouterr().err
