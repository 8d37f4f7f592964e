"""Every setting is declared once: the YAML, the tables, the descriptors and the CLI follow it."""

from dataclasses import fields
import io
from pathlib import Path
import re
import shutil

from namo_fault_recovery.cli import settings_command
from namo_fault_recovery.cli.common import engine_settings, UsageError
from namo_fault_recovery.cli.main import build_parser, main
from namo_fault_recovery.objective.score import ScoreWeights
from namo_fault_recovery.recovery import settings as declared
from namo_fault_recovery.recovery.engine import RecoverySettings as FromEngine
from namo_fault_recovery.recovery.settings import (BY_NAME, check, ENGINE, RecoverySettings,
                                                   SETTINGS)
from namo_fault_recovery.ros.parameters import (CHOICES, node_config, parameter_specs,
                                                RERUN_PARAMS, source)
import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent


def _parameters(doc):
    """Flatten a ROS parameter file's ``/**: ros__parameters`` into dotted names."""
    out = {}

    def flatten(mapping, prefix=''):
        for key, value in mapping.items():
            if isinstance(value, dict):
                flatten(value, f'{prefix}{key}.')
            else:
                out[f'{prefix}{key}'] = value
    flatten(doc['/**']['ros__parameters'])
    return out


def test_the_committed_files_are_what_the_declaration_writes():
    assert settings_command.stale(ROOT) == [], \
        'run: namo-recovery settings --write (then commit the files)'


def test_the_yaml_holds_every_parameter_with_its_default_in_order():
    values = _parameters(yaml.safe_load((ROOT / 'config' / 'recovery_node.yaml').read_text()))
    assert list(values) == [s.name for s in SETTINGS]
    for s in SETTINGS:
        assert values[s.name] == s.default and type(values[s.name]) is s.value_type, s.name


def test_the_readme_table_gives_every_default():
    text = (ROOT / 'README.md').read_text(encoding='utf-8')
    rows = dict(re.findall(r'^\| `([a-z_.]+)` \| ([^|]+) \|', text.split(
        settings_command.BEGIN)[1].split(settings_command.END)[0], re.M))
    assert list(rows) == [s.name for s in SETTINGS]
    for s in SETTINGS:
        shown = rows[s.name].strip().removesuffix(f' {s.unit}' if s.unit else '').strip('`')
        assert yaml.safe_load(shown if shown != "''" else "''") == s.default, s.name


def test_a_drifted_file_is_named(tmp_path):
    for name in ('config/recovery_node.yaml', 'README.md', 'msg_docs/interfaces.md'):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / name, tmp_path / name)
    assert settings_command.stale(tmp_path) == []
    path = tmp_path / 'config' / 'recovery_node.yaml'
    path.write_text(path.read_text().replace('deadline_sec: 1.0', 'deadline_sec: 2.0'))
    assert settings_command.stale(tmp_path) == [path]
    out = io.StringIO()
    assert main(['settings', '--check', '--root', str(tmp_path)], out) == 1
    assert 'recovery_node.yaml: out of date' in out.getvalue()
    assert main(['settings', '--write', '--root', str(tmp_path)], io.StringIO()) == 0
    assert settings_command.stale(tmp_path) == []


def test_recovery_settings_are_the_engine_rows():
    assert FromEngine is RecoverySettings
    names = [f.name for f in fields(RecoverySettings)]
    engine = [s.name for s in SETTINGS if s.scope == ENGINE]
    assert names[:-1] == [n for n in engine if '.' not in n] and names[-1] == 'weights'
    default = RecoverySettings()
    for name in names[:-1]:
        assert getattr(default, name) == BY_NAME[name].default
    assert [n for n in engine if n.startswith('weights.')] == [
        f'weights.{f.name}' for f in fields(ScoreWeights)]
    assert default.weights == ScoreWeights()
    assert set(default.public()) == set(names)


def test_the_descriptors_follow_the_declaration():
    specs = {name: (default, d) for name, default, d in parameter_specs()}
    assert list(specs) == [s.name for s in SETTINGS]
    for s in SETTINGS:
        default, d = specs[s.name]
        assert default == s.default and type(default) is s.value_type
        assert d.read_only == s.read_only and d.description.startswith(s.doc)
        assert (s.unit in d.description) if s.unit else True
        ranges = [(r.from_value, r.to_value) for r in
                  (d.floating_point_range or d.integer_range)]
        assert ranges == ([tuple(s.limits)] if s.limits else []), s.name
        assert (d.additional_constraints == 'one of: ' + ', '.join(s.choices)
                if s.choices else not d.additional_constraints)
    assert RERUN_PARAMS == {s.name for s in SETTINGS if s.rerun}
    assert set(CHOICES) == {s.name for s in SETTINGS if s.choices}
    # Fixed at start-up (kept from before the declaration; a new setting may add to them).
    assert {'robot_file', 'gesture_file', 'state_dir', 'contingency_file',
            'diagnostics_period_sec'} <= {s.name for s in SETTINGS if s.read_only}
    assert not RERUN_PARAMS & {s.name for s in SETTINGS if s.read_only}


def test_node_config_reads_every_engine_setting_by_name():
    values = {s.name: s.default for s in SETTINGS}
    changed = {'lock_strategy': 'optimal', 'tool_length_mm': 50.0, 'collision_check': False,
               'continuity_weight': 0.5, 'weights.tip': 3.0, 'weights.normalise': False}
    config = node_config(dict(values, **changed))
    assert config.settings == RecoverySettings(
        lock_strategy='optimal', tool_length_mm=50.0, collision_check=False,
        continuity_weight=0.5, weights=ScoreWeights(tip=3.0, normalise=False))


def _solve(*argv):
    return build_parser().parse_args(['solve', *argv])


def test_the_cli_options_are_the_declared_settings():
    parser = build_parser()
    solve = parser._subparsers._group_actions[0].choices['solve']
    options = {}
    for action in solve._actions:
        options.setdefault(action.dest, []).extend(action.option_strings)
        if action.dest in BY_NAME and BY_NAME[action.dest].cli:
            assert action.default == BY_NAME[action.dest].default
    for s in SETTINGS:
        if s.cli:
            assert {s.option, *s.aliases} <= set(options[s.name]), s.name
        else:
            assert s.name == 'seed' or s.name not in options, s.name
    assert engine_settings(_solve()) == RecoverySettings()
    assert engine_settings(_solve('--algorithm', 'ga', '--preset', 'paper',
                                  '--no-collision', '--vq-distortion-mm', '30',
                                  '--deadline', '0.5')) == RecoverySettings(
        optimizer='ga', optimizer_preset='paper', collision_check=False,
        vq_distortion_mm=30.0, deadline_sec=0.5)
    with pytest.raises(UsageError, match=r'^--vq-distortion-mm: expected a finite number > 0, '
                                         r'got -1\.0$'):
        engine_settings(_solve('--vq-distortion-mm', '-1'))


@pytest.mark.parametrize('name, value, expected', [
    ('deadline_sec', -1.0, 'deadline_sec: expected a finite number > 0, got -1.0'),
    ('deadline_sec', True, 'deadline_sec: expected a finite number > 0, got True'),
    ('tool_length_mm', float('nan'), 'tool_length_mm: expected a finite number >= 0, got nan'),
    ('lock_strategy', 'best', "lock_strategy: unknown value 'best'; expected one of average, "
                              'measured, optimal'),
    ('collision_check', 'yes', "collision_check: expected true or false, got 'yes'"),
    ('seed', 1.5, 'seed: expected an integer, got 1.5'),
    ('robot_file', 3, 'robot_file: expected a string, got 3'),
    ('weights.tip', -1.0, 'weights.tip: expected a finite number >= 0, got -1.0'),
])
def test_one_validator_gives_one_line_naming_key_value_and_expectation(
        name, value, expected):
    reason = check(name, value)
    assert reason.startswith(expected) and '\n' not in reason
    if BY_NAME[name].scope == ENGINE and '.' not in name:
        with pytest.raises(ValueError) as info:
            RecoverySettings(**{name: value})
        assert str(info.value) == reason


def test_the_weights_are_checked_together_and_unknown_names_pass():
    values = {s.name: s.default for s in SETTINGS}
    zero = dict(values, **{f'weights.{c}': 0.0 for c in ('elbow', 'wrist', 'tip')})
    assert 'at least one of elbow, wrist, tip, palm' in check('weights.palm', 0.0, zero)
    assert check('weights.palm', 0.5, zero) is None
    assert check('use_sim_time', 'anything') is None
    assert check('deadline_sec', 100.0) is None      # the node's range is its descriptor's
    assert len(check('lock_strategy', 'x' * 10_000)) < 400


def test_a_bad_value_from_a_params_file_names_the_file(tmp_path):
    first, second = tmp_path / 'a.yaml', tmp_path / 'b.yaml'
    first.write_text('/**:\n  ros__parameters:\n    deadline_sec: 0.5\n')
    second.write_text('recovery_node:\n  ros__parameters:\n    weights:\n      tip: -1.0\n')
    argv = ['node', '--ros-args', '--params-file', str(first), '--params-file', str(second)]
    assert source('deadline_sec', argv) == f' (in {first})'
    assert source('weights.tip', argv) == f' (in {second})'
    assert source('lock_strategy', argv) == ''
    assert source('deadline_sec', argv + ['-p', 'deadline_sec:=0.2']) == ''


def test_the_table_is_in_parameter_order_and_names_are_unique():
    names = [s.name for s in SETTINGS]
    assert len(names) == len(set(names)) == len(declared.BY_NAME)
    assert names[:5] == ['robot_file', 'robot_profile', 'robot_description', 'gesture_file',
                         'deadline_sec']
