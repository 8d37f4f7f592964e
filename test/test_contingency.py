"""The contingency table: fingerprint, fault sets, keys, best of seeds, file round trip."""

from dataclasses import replace
import io
import json
import math
import os
from pathlib import Path
import time

from namo_fault_recovery.cli.main import main
from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.model.robot import load_robot
from namo_fault_recovery.objective.score import ScoreWeights
from namo_fault_recovery.recovery import contingency as ct
from namo_fault_recovery.recovery.engine import RecoverySettings
from namo_fault_recovery.recovery.result import GestureResult, LibraryResult
import numpy as np
import pytest
from robot_urdfs import installed_urdf

ROBOT = load_robot()
LIBRARY = load_library(ROBOT)
SETTINGS = RecoverySettings()
# Left-arm joints: only Wai uses that arm, and their entries cost milliseconds.
CHEAP = ('left_arm_joint1', 'left_arm_joint3')
ROBOTS = Path(__file__).resolve().parent.parent / 'config' / 'robots'
TALOS = ROBOTS / 'talos.yaml'
TALOS_LIBRARY = ROBOTS / 'talos_gestures.yaml'


def fake_result(total, seed=0, locks=None):
    """Return a small LibraryResult whose total score is ``total``."""
    gestures = (GestureResult('wai', (2.0,), ((0.1 + 0.2,) + (0.0,) * 13,),
                              score_before=70.0, score_after=total, status='converged',
                              breakdown={'elbow': 1.5}),)
    return LibraryResult(gestures, faults={'right_arm_joint2': None},
                         locks=locks or {'right_arm_joint2': -0.2158359208146625},
                         deadline=None, seed=seed, notes=('a note',))


def servable_result(locks, **changes):
    """Return the reference library with ``locks`` applied: an entry the keeper serves."""
    from namo_fault_recovery.recovery.result import reference_result
    names = list(ROBOT.joint_names)
    gestures = tuple(replace(g, positions=tuple(
        tuple(locks.get(names[k], a) for k, a in enumerate(q)) for q in g.positions))
        for g in reference_result(LIBRARY).gestures)
    return replace(reference_result(LIBRARY), gestures=gestures, locks=dict(locks),
                   **changes)


def wait_for_entries(keeper, count):
    """Wait (up to 10 s) until ``keeper`` serves ``count`` entries."""
    for _ in range(200):
        if keeper.entries == count:
            return
        time.sleep(0.05)


def test_fingerprint_is_stable_and_ignores_the_deadline_only():
    base = ct.table_fingerprint(ROBOT, LIBRARY, SETTINGS)
    assert len(base) == 64
    robot = load_robot()
    assert ct.table_fingerprint(robot, load_library(robot), RecoverySettings()) == base
    assert ct.table_fingerprint(ROBOT, LIBRARY, SETTINGS.with_changes(deadline_sec=0.2)) == base
    changed = [SETTINGS.with_changes(**c) for c in (
        {'lock_strategy': 'optimal'}, {'optimizer_preset': 'paper'},
        {'collision_check': False}, {'tool_length_mm': 50.0}, {'bimanual': 'off'},
        {'vq_distortion_mm': SETTINGS.vq_distortion_mm * 2},
        {'weights': ScoreWeights(tip=2.0)})]
    prints = {ct.table_fingerprint(ROBOT, LIBRARY, s) for s in changed}
    assert len(prints) == len(changed) and base not in prints


def test_fingerprint_follows_the_robot_and_the_library_content_not_their_paths():
    base = ct.table_fingerprint(ROBOT, LIBRARY, SETTINGS)
    assert ct.table_fingerprint(replace(ROBOT, source='/elsewhere.yaml'),
                                replace(LIBRARY, source='/x.yaml'), SETTINGS) == base
    arm = ROBOT.arms['right']
    upper = arm.upper.copy()
    upper[1] -= 0.01
    robot = replace(ROBOT, arms={**ROBOT.arms, 'right': replace(arm, upper=upper)})
    assert ct.table_fingerprint(robot, LIBRARY, SETTINGS) != base
    capsules = replace(ROBOT, capsules=replace(ROBOT.capsules, hand=30.0))
    assert ct.table_fingerprint(capsules, LIBRARY, SETTINGS) != base
    wai = LIBRARY['wai']
    kf = wai.keyframes[0]
    moved = wai.with_keyframes((replace(kf, right=kf.right + 1e-3),) + wai.keyframes[1:])
    library = replace(LIBRARY, gestures=tuple(moved if g.name == 'wai' else g for g in LIBRARY))
    assert ct.table_fingerprint(ROBOT, library, SETTINGS) != base
    later = wai.with_keyframes((replace(kf, time_from_start=kf.time_from_start + 0.5),)
                               + wai.keyframes[1:])
    library = replace(LIBRARY, gestures=tuple(later if g.name == 'wai' else g for g in LIBRARY))
    assert ct.table_fingerprint(ROBOT, library, SETTINGS) != base


def test_entry_key_is_canonical():
    a = {'right_arm_joint2': -0.25, 'left_arm_joint1': 0.5}
    assert ct.entry_key(a) == 'left_arm_joint1=0.500000;right_arm_joint2=-0.250000'
    assert ct.entry_key(dict(reversed(list(a.items())))) == ct.entry_key(a)
    assert ct.entry_key({'right_arm_joint2': -0.25 + 1e-12, 'left_arm_joint1': 0.5}) == \
        ct.entry_key(a)
    assert ct.entry_key({'right_arm_joint2': -0.2501, 'left_arm_joint1': 0.5}) != \
        ct.entry_key(a)
    assert ct.entry_key({'j': -1e-9}) == ct.entry_key({'j': 0.0}) == 'j=0.000000'
    assert ct.entry_key({}) == ''
    with pytest.raises(ValueError, match='finite'):
        ct.entry_key({'j': math.nan})


def test_fault_sets_are_every_joint_at_its_resolved_lock():
    sets = ct.fault_sets(ROBOT, LIBRARY, SETTINGS)
    assert [list(f) for f in sets] == [[j] for j in ROBOT.joint_names]
    averages = np.concatenate([LIBRARY.lock_averages(side) for side in ('right', 'left')])
    for faults, average in zip(sets, averages):
        (angle,) = faults.values()
        assert angle == pytest.approx(average)
    measured = ct.fault_sets(ROBOT, LIBRARY, SETTINGS.with_changes(lock_strategy='measured'))
    assert measured == sets           # no measured angle offline: the average


def test_fault_sets_on_top_of_active_faults_and_for_optimal():
    active = {'right_arm_joint2': 0.1}
    sets = ct.fault_sets(ROBOT, LIBRARY, SETTINGS, active=active)
    assert len(sets) == 13
    assert all(f['right_arm_joint2'] == 0.1 and len(f) == 2 for f in sets)
    assert ct.fault_sets(ROBOT, LIBRARY, SETTINGS, active, joints=('right_arm_joint2',)) == []
    optimal = SETTINGS.with_changes(lock_strategy='optimal')
    sets = ct.fault_sets(ROBOT, LIBRARY, optimal, joints=('right_arm_joint4',))
    assert sets == [{'right_arm_joint4': None}]      # the engine optimises the lock
    locks = ct.table_locks(ROBOT, LIBRARY, sets[0], optimal)
    assert locks['right_arm_joint4'] == pytest.approx(LIBRARY.lock_averages('right')[3])
    with pytest.raises(ValueError, match='unknown joint'):
        ct.fault_sets(ROBOT, LIBRARY, SETTINGS, joints=('elbow',))


def test_build_entry_keeps_the_lowest_total_and_the_first_of_a_tie(monkeypatch):
    totals = {0: 5.0, 1: 3.0, 2: 3.0, 3: 4.0}
    seen = []

    def fake_recover(robot, library, faults, settings, seed, clock, quantisations):
        seen.append((seed, clock.end))
        return fake_result(totals[seed], seed)
    monkeypatch.setattr(ct, 'recover', fake_recover)
    faults = {'right_arm_joint2': None}
    built = ct.measure_entry(ROBOT, LIBRARY, faults, SETTINGS)
    assert built.result.seed == 1 and built.result.total_score == 3.0
    assert built.seed_scores == (5.0, 3.0, 3.0, 4.0)
    assert seen == [(s, None) for s in ct.DEFAULT_SEEDS]       # no deadline by default
    assert built.key == ct.entry_key(ct.table_locks(ROBOT, LIBRARY, faults, SETTINGS))
    best = ct.build_entry(ROBOT, LIBRARY, faults, SETTINGS, seeds=(3, 0))
    assert best.seed == 3
    with pytest.raises(ValueError, match='seed'):
        ct.build_entry(ROBOT, LIBRARY, faults, SETTINGS, seeds=())


def test_table_add_lookup_and_file_round_trip(tmp_path):
    table = ct.ContingencyTable('f' * 64, info={'seeds': [0]})
    result = fake_result(12.5)
    key = table.add(result)
    assert key == 'right_arm_joint2=-0.215836'
    optimal_key = table.add(fake_result(9.0, locks={'left_arm_joint1': 0.7}),
                            locks={'left_arm_joint1': 0.5})
    assert table.lookup({'left_arm_joint1': 0.5}).total_score == 9.0
    assert table.lookup({'left_arm_joint1': 0.7}) is None
    assert table.lookup({'right_arm_joint2': -0.2158359208146625 + 1e-10}) is result
    assert table.lookup({'right_arm_joint2': -0.2158359208146625,
                         'right_arm_joint3': 0.0}) is None
    path = tmp_path / 'deep' / 'table.json'
    table.save(path)
    assert os.listdir(path.parent) == ['table.json']           # no temporary file left
    loaded, reason = ct.ContingencyTable.load(path, 'f' * 64)
    assert reason is None
    assert set(loaded.entries) == {key, optimal_key}
    assert loaded.lookup({'right_arm_joint2': -0.2158359208146625}) == result
    assert loaded.info == {'seeds': [0]}
    assert loaded.lookup({'right_arm_joint2': -0.2158359208146625}).gestures[0] \
        .positions[0][0] == 0.1 + 0.2                               # floats bit for bit


def test_a_table_that_does_not_match_is_not_used_and_the_reason_names_it(tmp_path):
    path = tmp_path / 'table.json'
    _, reason = ct.ContingencyTable.load(path, 'abc')
    assert str(path) in reason and 'no such file' in reason
    table = ct.ContingencyTable('abc')
    table.add(fake_result(1.0))
    table.save(path)
    other, reason = ct.ContingencyTable.load(path, 'xyz')
    assert len(other) == 0 and other.fingerprint == 'xyz'
    assert str(path) in reason and "'fingerprint'" in reason
    text = path.read_text()
    cases = {
        text[:len(text) // 2]: 'not valid JSON',
        text.replace('"version": 1', '"version": 7'): "'version'",
        text.replace('"key": "right_arm_joint2=-0.215836"',
                     '"key": "right_arm_joint2=0.1"'): "'entries'[0]: 'key'",
        text.replace('"positions"', '"positionz"'): "'entries'[0]",
        '[]': "'format'",
    }
    for content, words in cases.items():
        path.write_text(content)
        loaded, reason = ct.ContingencyTable.load(path, 'abc')
        assert len(loaded) == 0 and reason is not None, words
        assert str(path) in reason and words in reason, reason


def test_a_failed_save_leaves_the_old_table(tmp_path, monkeypatch):
    path = tmp_path / 'table.json'
    table = ct.ContingencyTable('abc')
    table.save(path)
    before = path.read_text()
    table.add(fake_result(1.0))

    def broken_replace(src, dst):
        raise OSError('disk full')
    monkeypatch.setattr(os, 'replace', broken_replace)
    with pytest.raises(OSError, match='disk full'):
        table.save(path)
    assert path.read_text() == before
    assert os.listdir(tmp_path) == ['table.json']


def test_build_table_real_entries_same_with_a_spawned_pool():
    sets = ct.fault_sets(ROBOT, LIBRARY, SETTINGS, joints=CHEAP)
    seen = []
    table = ct.build_table(ROBOT, LIBRARY, SETTINGS, sets, progress=seen.append, seeds=(0, 1))
    assert table.fingerprint == ct.table_fingerprint(ROBOT, LIBRARY, SETTINGS)
    assert [b.faults for b in seen] == sets and len(table) == 2
    for faults in sets:
        hit = table.lookup(ct.table_locks(ROBOT, LIBRARY, dict.fromkeys(faults), SETTINGS))
        assert hit is not None and hit.locks == pytest.approx(faults)
        assert hit.deadline is None and hit.seed in (0, 1)
    pooled = ct.build_table(ROBOT, LIBRARY, SETTINGS, sets, jobs=2, seeds=(0, 1))
    assert set(pooled.entries) == set(table.entries)
    for key, (_, result) in table.entries.items():
        other = pooled.entries[key][1]
        assert [g.positions for g in other.gestures] == [g.positions for g in result.gestures]


def test_precompute_command_writes_a_table_the_node_settings_accept(tmp_path):
    out = io.StringIO()
    path = tmp_path / 'table.json'
    argv = ['precompute', '--seeds', '1', '--budget', '0.3', '--out', str(path),
            '--collision-check', '--lock-strategy', 'average']
    for joint in CHEAP:
        argv += ['--joint', joint]
    assert main(argv, out) == 0
    text = out.getvalue()
    assert 'left_arm_joint1 = 30.00 deg: total score' in text
    assert 'wrote 2 entries' in text
    table, reason = ct.ContingencyTable.load(path, ct.table_fingerprint(ROBOT, LIBRARY,
                                                                        SETTINGS))
    assert reason is None and len(table) == 2
    assert json.loads(path.read_text())['info']['budget_sec'] == 0.3


@pytest.mark.parametrize('argv, words', [
    (['--jobs', '0'], '--jobs'), (['--seeds', '0'], '--seeds'),
    (['--joint', 'elbow'], '--joint'), (['--budget', '-1'], '--budget'),
    (['--joint', 'left_arm_joint1', '--active', 'left_arm_joint1'], 'no fault set')])
def test_precompute_usage_errors(argv, words, capsys, tmp_path):
    assert main(['precompute', '--out', str(tmp_path / 't.json')] + argv, io.StringIO()) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / 't.json').exists()


def talos_models():
    """Return Talos and its library as the node loads them (skip without the URDF)."""
    from namo_fault_recovery.runtime.robot_source import load_models, RobotSource
    installed_urdf('talos')
    return load_models(RobotSource(profile=str(TALOS)), str(TALOS_LIBRARY))


def test_a_profile_robots_fingerprint_is_its_content_not_its_objects():
    """Two loads of Talos (as precompute and the node) print alike; a tool cache does not count."""
    robot, library = talos_models()
    base = ct.table_fingerprint(robot, library, SETTINGS)
    again, library_again = talos_models()
    assert ct.table_fingerprint(again, library_again, SETTINGS) == base
    again.chains['right'].with_tool(50.0)              # fills the arm's tooled cache
    assert ct.table_fingerprint(again, library_again, SETTINGS) == base
    arm = robot.arms['right']
    upper = arm.upper.copy()
    upper[1] -= 0.01
    moved = replace(robot, arms={**robot.arms, 'right': replace(arm, upper=upper)})
    assert ct.table_fingerprint(moved, library, SETTINGS) != base


def test_precompute_builds_another_robots_table_that_its_node_accepts(tmp_path):
    robot, library = talos_models()
    path = tmp_path / 'talos.json'
    out = io.StringIO()
    assert main(['precompute', '--robot-profile', str(TALOS), '--gesture-file',
                 str(TALOS_LIBRARY), '--seeds', '1', '--budget', '0.3', '--joint',
                 'arm_left_1_joint', '--out', str(path)], out) == 0, out.getvalue()
    assert 'arm_left_1_joint = ' in out.getvalue()
    table, reason = ct.ContingencyTable.load(path, ct.table_fingerprint(robot, library,
                                                                        SETTINGS))
    assert reason is None and len(table) == 1
    locks = ct.table_locks(robot, library, {'arm_left_1_joint': None}, SETTINGS)
    assert table.lookup(locks) is not None


def test_precompute_takes_a_robot_file_or_a_profile_not_both(capsys, tmp_path):
    argv = ['--robot-file', str(ROBOTS.parent / 'namo_robot.yaml'), 'precompute',
            '--robot-profile', str(TALOS), '--out', str(tmp_path / 't.json')]
    assert main(argv, io.StringIO()) == 2
    assert 'expected one of the two' in capsys.readouterr().err
    assert not (tmp_path / 't.json').exists()


def test_a_hit_is_served_within_the_node_deadline_not_the_budget_it_was_built_with(tmp_path):
    """An entry built under a 0.3 s budget that cut it reads as served now, its search kept."""
    from namo_fault_recovery.recovery.result import summary
    from namo_fault_recovery.runtime.contingency_keeper import ContingencyKeeper
    table = ct.ContingencyTable(ct.table_fingerprint(ROBOT, LIBRARY, SETTINGS))
    for faults in ct.fault_sets(ROBOT, LIBRARY, SETTINGS):
        locks = ct.table_locks(ROBOT, LIBRARY, faults, SETTINGS)
        cut = servable_result(locks, faults=dict(faults), deadline=0.3, deadline_met=False,
                              success=False, wall_time=0.263)
        cut = replace(cut, gestures=(replace(cut.gestures[0], status='deadline',
                                             wall_time=0.263),) + cut.gestures[1:])
        table.add(cut)
    path = tmp_path / 'offline.json'
    table.save(path)
    logs = []
    keeper = ContingencyKeeper(ROBOT, LIBRARY, tmp_path / 'state', lambda *a: logs.append(a),
                               offline_file=str(path))
    try:
        keeper.configure(SETTINGS)
        wait_for_entries(keeper, len(table))
        hit = keeper.lookup({'right_arm_joint2': None}, SETTINGS)
    finally:
        keeper.stop()
    assert hit is not None, logs
    assert (hit.origin, hit.deadline, hit.deadline_met, hit.success) == ('table', 1.0, True, True)
    assert hit.wall_time == 0.263 and hit.gestures[0].status == 'deadline'   # its search kept
    text = summary(hit)
    assert text.startswith(f'reconfigured {len(LIBRARY)}/{len(LIBRARY)} gestures from a search '
                           f'of 0.263 s made in '
                           'advance (deadline 1.000 s met) for right_arm_joint2'), text
    assert 'MISSED' not in text and 'from the contingency table' in text, text


def test_an_entry_is_checked_and_prepared_as_it_joins_a_failing_one_is_not_served(tmp_path):
    """A hit needs no check of its own: an entry that fails check_result is never served."""
    from namo_fault_recovery.runtime.contingency_keeper import ContingencyKeeper
    table = ct.ContingencyTable(ct.table_fingerprint(ROBOT, LIBRARY, SETTINGS))
    plan = ct.fault_sets(ROBOT, LIBRARY, SETTINGS)
    for faults in plan:
        locks = ct.table_locks(ROBOT, LIBRARY, faults, SETTINGS)
        table.add(servable_result(locks, faults=dict(faults)))
    bad = next(f for f in plan if 'right_arm_joint2' in f)
    locks = ct.table_locks(ROBOT, LIBRARY, bad, SETTINGS)
    table.add(replace(servable_result(locks), locks={'right_arm_joint2': locks[
        'right_arm_joint2'] + 0.1}), locks)         # published angle not its lock angle
    path = tmp_path / 'offline.json'
    table.save(path)
    logs, prepared = [], []
    keeper = ContingencyKeeper(ROBOT, LIBRARY, tmp_path / 'state', lambda *a: logs.append(a),
                               offline_file=str(path), prepare=prepared.append)
    try:
        keeper.configure(SETTINGS)
        wait_for_entries(keeper, len(table) - 1)
        served = keeper.lookup(bad, SETTINGS)    # None, or the builder's entry by now
        hit = keeper.lookup(next(f for f in plan if f is not bad), SETTINGS)
    finally:
        keeper.stop()
    assert served is None or served.locks == locks
    assert hit is not None and any(p.gestures is hit.gestures for p in prepared)
    assert len(prepared) >= len(table) - 1
    assert any('not served' in text and 'right_arm_joint2' in text for _, text in logs), logs


def test_the_table_serves_its_entries_when_the_log_says_they_are_loaded(tmp_path):
    """The log line a caller waits for comes after the entries were checked and installed."""
    from namo_fault_recovery.runtime.contingency_keeper import ContingencyKeeper
    table = ct.ContingencyTable(ct.table_fingerprint(ROBOT, LIBRARY, SETTINGS))
    for faults in ct.fault_sets(ROBOT, LIBRARY, SETTINGS):
        table.add(servable_result(ct.table_locks(ROBOT, LIBRARY, faults, SETTINGS),
                                  faults=dict(faults)))
    path = tmp_path / 'offline.json'
    table.save(path)
    seen = []
    keeper = None

    def log(level, text):
        seen.append((text, keeper.entries))

    keeper = ContingencyKeeper(ROBOT, LIBRARY, tmp_path / 'state', log,
                               offline_file=str(path), prepare=lambda result: time.sleep(0.01))
    try:
        assert keeper.status() == ('loading', 0, 0)
        keeper.configure(SETTINGS)
        assert keeper.status()[0] == 'loading'          # until the entries are checked
        wait_for_entries(keeper, len(table))
        for _ in range(100):
            if any('entries loaded from' in text for text, _ in seen) and \
                    keeper.status()[0] != 'loading':
                break
            time.sleep(0.05)
        # Every single fault came from the file: nothing is left to build.
        assert keeper.status() == ('complete', len(table), 0)
        keeper.configure(replace(SETTINGS, continuity_weight=0.02))   # a new fingerprint
        assert keeper.status()[0] == 'loading'
    finally:
        keeper.stop()
    loaded = [entries for text, entries in seen if 'entries loaded from' in text]
    assert loaded == [len(table)], seen


def test_a_partial_table_never_reads_complete_while_its_plan_is_made(tmp_path, monkeypatch):
    """From the configure() to the builder's start: loading, then building, never complete."""
    from namo_fault_recovery.runtime import contingency_keeper
    from namo_fault_recovery.runtime.contingency_keeper import ContingencyKeeper

    def slow_plan(*args, **kwargs):              # widens the window between the two steps
        time.sleep(0.3)
        return ct.fault_sets(*args, **kwargs)
    monkeypatch.setattr(contingency_keeper, 'fault_sets', slow_plan)
    table = ct.ContingencyTable(ct.table_fingerprint(ROBOT, LIBRARY, SETTINGS))
    plan = ct.fault_sets(ROBOT, LIBRARY, SETTINGS)
    for faults in plan[:3]:
        table.add(servable_result(ct.table_locks(ROBOT, LIBRARY, faults, SETTINGS),
                                  faults=dict(faults)))
    path = tmp_path / 'offline.json'
    table.save(path)
    keeper = ContingencyKeeper(ROBOT, LIBRARY, tmp_path / 'state', lambda *a: None,
                               offline_file=str(path))
    seen = []
    try:
        keeper.configure(SETTINGS)
        end = time.monotonic() + 20.0
        while time.monotonic() < end and (not seen or seen[-1][0] != 'building'):
            seen.append(keeper.status())
    finally:
        keeper.stop()
    states = [s for s, _, _ in seen]
    assert states[-1] == 'building', states[-5:]
    assert 'complete' not in states, [s for s in seen if s[0] != 'loading'][:3]
    assert seen[-1][2] == len(plan) - 3, seen[-1]
