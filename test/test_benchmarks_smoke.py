"""Tiny versions of every benchmark: they run and write their outputs (no wall-time asserts)."""

import csv
import io
import json
import math
import os
import subprocess
import sys

from namo_fault_recovery.benchmarks import common, deadline, load_best_known, optimum, paper
from namo_fault_recovery.benchmarks import idle, motion, product, speed
from namo_fault_recovery.benchmarks.paper_data import TABLE6
from namo_fault_recovery.cli.main import main
from namo_fault_recovery.objective.score import gesture_targets, SimilarityScore
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import RecoverySettings
from namo_fault_recovery.recovery.keyframes import reconfigure_library
import numpy as np
import pytest
import yaml

# The keyframe search's own problem, the paper's: no stage 2, no collision term.
PAPER = RecoverySettings(bimanual='off', collision_check=False)
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


def run_cli(argv):
    out = io.StringIO()
    return main(argv, out), out.getvalue()


def _finite(x):
    return isinstance(x, float) and math.isfinite(x)


def test_paper_bench_writes_outputs_and_resumes(tmp_path):
    argv = ['bench', 'paper', '--reps', '2', '--gestures', 'bye', '--joints', '2',
            '--algorithms', 'ga-paper', 'bfoa-paper', 'abc-default', '--out', str(tmp_path),
            '--quiet']
    code, text = run_cli(argv)
    assert code == 0
    assert '6 new run(s)' in text
    assert 'paper Table 6 ABC minimum beside ours' in text
    assert len(list((tmp_path / 'cases').glob('*.json'))) == 3
    for name in ('runs.csv', 'summary.csv', 'summary.json', 'tables.md'):
        assert (tmp_path / name).is_file(), name
    with open(tmp_path / 'runs.csv') as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6
    assert all(math.isfinite(float(r['score'])) and float(r['time_s']) > 0 for r in rows)
    summary = json.loads((tmp_path / 'summary.json').read_text())
    for s in summary['stats']:
        assert s['score']['n'] == 2
        assert all(_finite(s['score'][k]) for k in ('min', 'max', 'mean', 'sd', 'median', 'iqr'))
        assert s['score']['min'] <= s['score']['median'] <= s['score']['max']
    kw = summary['kruskal'][0]
    assert kw['score_all']['df'] == 2 and kw['score_paper3']['df'] == 1
    assert 'Table 4' in (tmp_path / 'tables.md').read_text()
    if summary.get('plots'):
        for p in summary['plots']:
            with open(p, 'rb') as fh:
                assert fh.read(8) == PNG_MAGIC
    # Resumable: the same command runs nothing new; one more rep runs only that.
    code, text = run_cli(argv)
    assert code == 0 and '0 new run(s)' in text
    argv[3] = '3'
    code, text = run_cli(argv + ['--no-plots'])
    assert code == 0 and '3 new run(s)' in text


def test_run_gesture_matches_reconfigure_library(robot, library):
    for key in ('abc-default', 'ga-paper'):
        spec = common.lookup_spec(key)
        run = common.run_gesture(spec, robot, library, 'bye', 'right_arm_joint2', 3)
        report = reconfigure_library(robot, library, {'right_arm_joint2': None},
                                     PAPER.with_changes(optimizer=spec.algorithm,
                                                        optimizer_preset=spec.preset),
                                     clock=Clock(None), seed=3, gestures=['bye'])
        assert run['score_engine'] == pytest.approx(report['bye'].score_after, rel=1e-12)
        assert run['score_before'] == pytest.approx(report['bye'].score_before, rel=1e-12)
        assert run['score_engine'] <= run['score'] + 1e-12


def test_dense_optimum_and_yaml_round_trip(robot, library, tmp_path):
    entry = optimum.dense_optimum(robot, library, 'bye', 'right_arm_joint7', starts=8)
    assert _finite(entry['score'])
    assert entry['score'] <= entry['keyframes'][0]['reference_start_score'] + 1e-9
    assert entry['right_deg'][6] == pytest.approx(entry['lock_deg'])
    assert entry['starts'] == 9
    doc = optimum.optima_document(robot, library, {('bye', 'right_arm_joint7'): entry}, 8, 0,
                                  300)
    path = tmp_path / 'optima.yaml'
    optimum.write_optima(path, doc)
    loaded = load_best_known(path)
    assert loaded.score('bye', 'right_arm_joint7') == pytest.approx(entry['score'])
    assert loaded.check_model(robot, library) is None
    with pytest.raises(KeyError, match='no best-known optimum'):
        loaded.score('wai', 'right_arm_joint1')


def test_packaged_optima_cover_the_28_cases(robot, library):
    best = load_best_known()
    assert best.check_model(robot, library) is None
    targets = {g.name: gesture_targets(g) for g in library}
    for g, j in common.select_cases(robot, library):
        e = best.cases[(g, j)]
        scorer = SimilarityScore(robot, targets[g])
        value = scorer(np.radians(e['right_deg']), np.radians(e['left_deg']))[0]
        assert value == pytest.approx(e['score'], rel=1e-5)
        side, k = robot.locate_joint(j)
        assert e['right_deg'][k] == pytest.approx(np.degrees(library.lock_averages(side)[k]))
        # Spec section 3: every best-known optimum lies at or below the paper's ABC best.
        assert e['score'] <= TABLE6[(g, k + 1)]['abc']['min']


def test_optimum_bench_gaps(robot, library, tmp_path):
    out = io.StringIO()
    cases = [('side_invite', 'right_arm_joint7')]
    doc = optimum.run_optimum(robot, library, out, cases, optimum.Multistart(starts=4),
                              keys=('ga-paper',), seeds=1, write=tmp_path / 'o.yaml',
                              progress=False)
    text = out.getvalue()
    assert 'gap to the best-known optimum' in text
    assert len(doc['gaps']) == 1 and _finite(doc['gaps'][0]['gaps'][0])
    assert (tmp_path / 'o.yaml').is_file()


def test_speed_bench_structure(tmp_path):
    out = io.StringIO()
    s = speed.run_speed(out, tmp_path, reps=1, joints=['7'], progress=False, sequential_reps=1)
    for k in speed.KEYS:
        assert s['timing'][k]['n'] == 1 and _finite(s['timing'][k]['median'])
    assert _finite(s['ratio']['median'])
    assert s['sequential']['n'] == 1 and _finite(s['sequential']['ratio_median'])
    q = s['quality']
    assert q is not None and len(q['abc-default']['cases']) == 4
    assert 0.0 <= q['abc-default']['share_within_overall'] <= 1.0
    assert q['equal_or_better']['cases'] == 4
    assert 'ratio paper ABC / ours' in out.getvalue()
    assert (tmp_path / 'runs.csv').is_file() and (tmp_path / 'summary.json').is_file()


def test_deadline_bench_structure(tmp_path):
    out = io.StringIO()
    s = deadline.run_deadline(out, tmp_path, deadlines=(0.05,), reps=1,
                              keys=('abc-default', 'ga-paper'), burner=True, progress=False)
    assert [r['condition'] for r in s['rows']] == ['idle', 'cpu burner']
    for r in s['rows']:
        assert r['n'] == 2 and _finite(r['worst_overrun']) and r['bound_share'] == 1.0
    assert 'worst overrun' in out.getvalue()


def test_quick_defaults():
    assert paper.QUICK_REPS * len(paper.QUICK_JOINTS) * 4 <= 40   # keeps --quick short


@pytest.mark.parametrize('argv, message', [
    (['bench', 'paper', '--reps', '0'], '--reps'),
    (['bench', 'paper', '--algorithms', 'nope'], 'unknown algorithm key'),
    (['bench', 'paper', '--joints', '9'], 'joint number 9'),
    (['bench', 'speed', '--joints', 'left_arm_jointX'], 'unknown joint'),
    (['bench', 'deadline', '--deadlines', '-1'], '--deadlines'),
    (['bench', 'optimum', '--stored', '--write'], 'nothing to write'),
    (['bench', 'idle', '--window', '0'], '--window'),
    (['bench', 'idle', '--stops', '-1'], '--stops'),
    (['bench'], 'required'),
])
def test_bad_arguments_exit_2(capsys, argv, message):
    code, _ = run_cli(argv)
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and err.count('\n') == 1


def test_idle_bench_follows_the_process_tree_and_counts_reaped_children():
    burn = 'x = 0\nfor i in range(3_000_000):\n    x += i\n'
    sleeper = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)'])
    try:
        assert sleeper.pid in idle.process_tree(os.getpid())
        before = idle.tree_ticks(os.getpid())[os.getpid()][1]
        subprocess.run([sys.executable, '-c', burn], check=True)      # burns, is reaped
        after = idle.tree_ticks(os.getpid())[os.getpid()][1]
        assert after > before                    # its CPU now counts in the root's
        assert sleeper.pid in idle.tree_ticks(os.getpid())
        assert any(idle.thread_ticks(os.getpid()))
    finally:
        sleeper.kill()
        sleeper.wait()


def test_speed_command(tmp_path):
    code, text = run_cli(['bench', 'speed', '--reps', '1', '--joints', '3',
                          '--sequential-reps', '0', '--out', str(tmp_path), '--quiet'])
    assert code == 0
    assert 'ratio paper ABC / ours' in text and 'one gesture at a time' not in text


def test_paper_bench_in_two_processes(tmp_path):
    code, text = run_cli(['bench', 'paper', '--reps', '1', '--jobs', '2', '--gestures', 'bye',
                          'salute', '--joints', '7', '--algorithms', 'ga-paper', 'abc-default',
                          '--out', str(tmp_path), '--quiet', '--no-plots'])
    assert code == 0 and '4 new run(s)' in text
    assert len(list((tmp_path / 'cases').glob('*.json'))) == 4


def test_motion_deadline_bench_reports_each_case(tmp_path, robot):
    assert len(motion.deadline_cases(robot)) == 17    # 14 single faults, 2 tools, elbow
    out = io.StringIO()
    case = ('left_arm_joint1 (average lock)', {'faults': {'left_arm_joint1': None}})
    rows = motion.bench_motion_deadline(out, str(tmp_path), seed=0, deadline=1.0,
                                        cases=[case])
    doc = json.loads((tmp_path / 'motion_deadline.json').read_text())
    assert doc['rows'] == rows and len(rows) == 1
    row = rows[0]
    for key in ('deadline_met', 'wall_ms', 'tip_error_vs_per_point_mm', 'max_step_deg',
                'designed_step_deg'):
        assert key in row
    assert 'target <= +1 mm' in out.getvalue()


def test_motion_bench_compares_both_methods_on_the_wave(tmp_path, demo_library):
    out = io.StringIO()
    rows = motion.bench_motion(out, str(tmp_path), seed=0, motions=('bye',))
    text = out.getvalue()
    # By default it reads the demo library, which holds both of its motions.
    assert set(motion.MOTIONS) <= set(demo_library.names)
    assert '## bye: 6 points' in text and 'The paper (its own 3-DOF arm' in text
    assert len(rows) == 2 * len(motion.SCENARIOS)
    doc = json.loads((tmp_path / 'motion.json').read_text())
    assert len(doc['rows']) == len(rows)
    for kriging, per_point in zip(rows[::2], rows[1::2]):
        assert (kriging['method'], per_point['method']) == ('kriging', 'per_point')
        assert per_point['cost_pct'] == 100.0 and per_point['typical'] == 6
        assert 0 < kriging['typical'] < 6 and kriging['nfev'] > 0
        for row in (kriging, per_point):
            assert _finite(row['tip_error_mean_mm']) and _finite(row['jump_before_deg'])
            assert row['tip_error_mean_mm'] <= row['tip_error_max_mm'] + 1e-9


def _bench_product(tmp_path, parts, *options):
    """Run ``bench product`` on one joint with optima of one seed made first."""
    optima = tmp_path / 'optima.yaml'
    code, text = run_cli(['bench', 'product', '--update-optima', '--optima-file', str(optima),
                          '--optima-seeds', '1', '--demo-optima-seeds', '1', '--jobs', '1',
                          '--parts', parts, '--joints', 'right_arm_joint2', '--no-burner',
                          *options, '--out', str(tmp_path / 'out'), '--quiet'])
    assert code == 0, text
    return optima, text


def test_product_bench_offline_parts(tmp_path):
    optima, text = _bench_product(tmp_path, 'quality,table,demo', '--seeds', '1',
                                  '--demo-seeds', '1')
    for part in ('quality at the deadline', 'contingency table', 'demo library'):
        assert part in text
    doc = yaml.safe_load(optima.read_text())
    product_sets = doc['libraries']['product']['fault_sets']
    assert len(product_sets) == 1 + 3          # the fault asked for + the refinement sets
    assert doc['made']['commit'] and doc['libraries']['demo']['seeds'] == 1
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert summary['quality']['conditions']['idle']['runs'] == 1
    assert len(summary['table']['entries']) == 1
    assert 'circle' in summary['demo']['runs'][0]['scores']
    # The seeds of the stored optimum, rerun, are at the optimum (gap 0).
    assert all(math.isfinite(g) for g in summary['quality']['runs'][0]['gaps'].values())
    # How far a run beat the best-known is reported beside the count (0 when none did).
    lowest = min(summary['quality']['runs'][0]['gaps'].values())
    idle = summary['quality']['conditions']['idle']
    assert idle['below_best_known_max_pct'] == pytest.approx(-100 * min(0.0, lowest))
    assert idle['below_best_known'] == int(lowest < -1e-6)


def test_optima_of_one_library_keep_the_others():
    """``--optima-libraries demo`` rewrites the demo entry only; each says when it was made."""
    new = {'made': {'date': 'new'}, 'libraries': {'demo': {'seeds': 8}}}
    old = {'made': {'date': 'old'},
           'libraries': {'product': {'seeds': 256}, 'demo': {'seeds': 32}}}
    doc = product.merge_optima(new, old)
    assert list(doc['libraries']) == ['product', 'demo']
    assert doc['libraries']['demo'] == {'seeds': 8, 'made': {'date': 'new'}}
    assert doc['libraries']['product'] == {'seeds': 256, 'made': {'date': 'old'}}
    with pytest.raises(KeyError, match="unknown library 'circle'"):
        product.generate_optima(io.StringIO(), libraries=('circle',))


def test_remade_product_optima_keep_what_an_earlier_run_found_lower():
    def entry(fingerprint, sets):
        return {'fingerprint': fingerprint, 'fault_sets': {
            key: {'best': dict(best), 'best_seed': {g: seed for g in best}}
            for key, (best, seed) in sets.items()}}

    old = {'made': {}, 'libraries': {'product': entry('m', {
        'j1=0.1': ({'wai': 15.0, 'bye': 9.0}, 7), 'j2=0.2': ({'wai': 1.0}, 3)})}}
    new = {'made': {}, 'libraries': {'product': entry('m', {
        'j1=0.1': ({'wai': 15.5, 'bye': 8.0}, 2)})}}
    sets = product.merge_optima(new, old)['libraries']['product']['fault_sets']
    assert sets['j1=0.1']['best'] == {'wai': 15.0, 'bye': 8.0}
    assert sets['j1=0.1']['best_seed'] == {'wai': 7, 'bye': 2}
    assert sets['j1=0.1']['kept_from_earlier'] == ['wai']
    assert sets['j2=0.2']['best'] == {'wai': 1.0}            # not solved this time
    other = {'made': {}, 'libraries': {'product': entry('another model', {
        'j1=0.1': ({'wai': 15.5}, 2)})}}
    sets = product.merge_optima(other, old)['libraries']['product']['fault_sets']
    assert sets == {'j1=0.1': {'best': {'wai': 15.5}, 'best_seed': {'wai': 2}}}


def test_product_bench_node_parts(tmp_path):
    pytest.importorskip('rclpy')
    # The packaged best-known optima (regenerating them is the offline test's business):
    # the refinement part scores each version against them.
    code, text = run_cli(['bench', 'product', '--parts', 'latency,refine', '--joints',
                          'right_arm_joint2', '--no-burner', '--refine-window', '1',
                          '--refine-reps', '1', '--out', str(tmp_path / 'out'), '--quiet'])
    assert code == 0, text
    assert 'product_best_known.yaml' in text
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    # The hit part waits for the one entry it times, not the whole table.
    assert summary['latency_hit']['table_entries_waited'] == 1
    assert summary['latency_hit']['build']['cpu_s'] is None
    hit = summary['latency_hit']['conditions']['idle']
    assert hit['n'] == 1 and hit['origins'] == {'table': 1}
    assert summary['latency_miss']['conditions']['idle']['origins'] == {'deadline': 1}
    cases = summary['refine']['cases']
    assert len(cases) == 3 and all(c['versions'] for c in cases)
    assert set(summary['refine']['sets']) == {'right2+right4', 'right1+left3', 'right2@-20deg'}
    assert cases[0]['versions'][0]['origin'] == 'deadline'


def test_a_wave_that_flips_the_wrist_too_fast_is_not_playable(robot, product_library):
    from dataclasses import replace

    from namo_fault_recovery.benchmarks.product import playable
    from namo_fault_recovery.recovery.result import reference_result
    bye = reference_result(product_library)['bye']
    assert playable(robot, bye)                      # the design respects the limits
    positions = [list(q) for q in bye.positions]
    positions[1][5] -= 3.0                           # right joint 6 swings 172 deg and back
    assert not playable(robot, replace(bye, positions=tuple(map(tuple, positions))))


def test_playability_counts_straight_paths_that_touch_and_the_played_ones_bent_clear():
    """Left joint 3 locked: Wai's keyframes are clear, its straight path presses the palms."""
    from namo_fault_recovery.benchmarks.playability import run_playability
    out = io.StringIO()
    summary = run_playability(out, seeds=1, joints=['left_arm_joint3'], jobs=1,
                              progress=False)
    part = summary['parts']['budget']
    assert part['unplayable'] == 0 and part['gestures'] == 4
    assert part['straight_path_contacts'] >= 1 and part['max_straight_depth_mm'] > 1.0
    assert part['path_contacts'] == 0 and part['max_path_depth_mm'] <= 1.0
    assert 'played paths touch beyond their design' in out.getvalue()


def test_playability_locks_a_joint_across_the_range_the_library_moves_it():
    """``--lock-angles``: right joint 3 at -15 and 15 deg (15: where far twins came up)."""
    from namo_fault_recovery.benchmarks.playability import run_playability, stuck_angles
    from namo_fault_recovery.cli.main import main as cli_main
    from namo_fault_recovery.model.gestures import load_library
    from namo_fault_recovery.model.robot import load_robot
    robot = load_robot()
    library = load_library(robot)
    angles = np.degrees(stuck_angles(robot, library, 'right_arm_joint3', 2))
    np.testing.assert_allclose(angles, [-15.0, 15.0], atol=1e-9)   # keyframes -45..45 deg
    summary = run_playability(io.StringIO(), seeds=0, deadline_seeds=1,
                              joints=['right_arm_joint3'], jobs=1, progress=False,
                              lock_angles=2)
    part = summary['parts']['deadline']
    assert part['runs'] == 2 and part['gestures'] == 8
    assert summary['lock_angles_deg']['right_arm_joint3'] == pytest.approx([-15.0, 15.0])
    assert part['path_contacts'] == 0 and part['unplayable'] == 0
    argv = ['bench', 'playability', '--seeds', '1', '--lock-angles', '-1']
    assert cli_main(argv, out=io.StringIO()) == 2


def test_playability_runs_on_a_profile_robot_and_its_bent_paths_are_clear():
    """Talos, left joint 1 locked: Wai's straight approach presses 62 mm, the played 0."""
    from namo_fault_recovery.benchmarks.playability import run_playability
    from namo_fault_recovery.cli.main import main as cli_main
    summary = run_playability(io.StringIO(), seeds=1, joints=['arm_left_1_joint'], jobs=1,
                              progress=False, robot_name='talos')
    part = summary['parts']['budget']
    assert summary['robot'] == 'talos' and part['gestures'] == 4
    assert part['straight_path_contacts'] >= 1 and part['max_straight_depth_mm'] > 10.0
    assert part['path_contacts'] == 0 and part['unplayable'] == 0
    argv = ['bench', 'playability', '--robot', 'talos', '--library', 'demo', '--seeds', '1']
    assert cli_main(argv, out=io.StringIO()) == 2


def test_latency_scores_the_published_trajectories_itself():
    """A node whose reported scores hide a bad gesture is judged on what it published."""
    import dataclasses
    from types import SimpleNamespace as NS
    from namo_fault_recovery.benchmarks import latency
    from namo_fault_recovery.recovery.engine import recover
    path = common.config_path('robots/talos_best_known.yaml')
    models = latency.served_models(path)
    robot, library = models[0]
    assert robot.name == 'talos' and library.names == ('wai', 'bye', 'salute', 'side_invite')
    assert latency.served_models(common.config_path('product_best_known.yaml'))[1][1].names[-1] \
        == 'circle'
    result = recover(robot, library, {'arm_right_1_joint': None}, RecoverySettings(), seed=0,
                     clock=Clock(None))
    samples = latency.LatencySamples(latency.served_optima(path), models)
    samples.judge(result, robot.joint_names)
    assert samples.rescored == 1 and samples.node_diff < 1e-9 and samples.gaps[0] < 0.01
    # The same scores reported, but the wave published as the locked reference.
    bye = next(g for g in result.gestures if g.name == 'bye')
    locked = np.array([library['bye'].keyframes[0].positions()] * len(bye.positions))
    locked[:, robot.joint_names.index('arm_right_1_joint')] = result.locks['arm_right_1_joint']
    hiding = NS(locks=result.locks, tool_mm=0.0, gestures=[
        dataclasses.replace(g, positions=tuple(map(tuple, locked))) if g is bye else g
        for g in result.gestures])
    samples.judge(hiding, robot.joint_names)
    assert samples.gaps[1] > 0.01 and samples.beyond[0].startswith('arm_right_1_joint=')
    assert samples.node_diff > 0.01
    out = io.StringIO()
    samples.latencies.append(0.1)
    samples.round_trips.append(0.1)
    latency.write_latency(out, samples.report(2), [])
    assert ("quality as served (the client's scores of the published trajectories against "
            "the best-known; the node's own scores within ") in out.getvalue()
    # A library it cannot score (a torso lean; another count of keyframes): the node's.
    leaned = NS(locks=result.locks, tool_mm=0.0, gestures=[
        dataclasses.replace(g, shared={'torso_2_joint': 0.1}) if g is bye else g
        for g in result.gestures])
    short = NS(locks=result.locks, tool_mm=0.0, gestures=[
        dataclasses.replace(g, positions=g.positions * 2) if g is bye else g
        for g in result.gestures])
    for other in (leaned, short):
        samples.judge(other, robot.joint_names)
    assert samples.rescored == 2 and len(samples.gaps) == 4


def test_latency_judges_each_library_as_served_against_its_locks_best_known(tmp_path):
    from types import SimpleNamespace as NS
    from namo_fault_recovery.benchmarks import latency
    path = tmp_path / 'optima.yaml'
    path.write_text(yaml.safe_dump({'fault_sets': {
        'j2=0.500000': {'wai': 10.0, 'bye': 2.0}}}))
    samples = latency.LatencySamples(latency.served_optima(path))

    def result(locks, wai, bye):
        return NS(locks=locks, gestures=[NS(name='wai', score_after=wai),
                                         NS(name='bye', score_after=bye)])
    samples.judge(result({'j2': 0.5}, 10.05, 2.0))          # 0.5 %: within
    samples.judge(result({'j2': 0.5000000001}, 10.0, 2.1))  # the same key; 5 %
    samples.judge(result({'j2': 0.7}, 10.0, 2.0))           # another lock: no best-known
    samples.latencies.append(0.1)
    samples.round_trips.append(0.1)
    quality = samples.report(3)['served_quality']
    assert quality == {'judged': 2, 'without_best_known': 1, 'within_1pct': 1,
                       'max_gap_pct': pytest.approx(5.0),
                       'beyond_1pct': ['j2=0.500000: bye 5.00 %'], 'rescored_by_client': 0,
                       'node_score_diff_pct': None}
    out = io.StringIO()
    latency.write_latency(out, samples.report(3), [])
    assert ("quality as served (the node's scores against the best-known): 1 of 2 "
            'libraries with every gesture within 1 %, largest gap 5.00 %; 1 without a '
            'best-known for their locks\n'
            '  beyond 1 %: j2=0.500000: bye 5.00 %\n') in out.getvalue()
    product_file = latency.served_optima(common.config_path('product_best_known.yaml'))
    assert [len(next(iter(lib.values()))) for lib in product_file] == [4, 5]
    (tmp_path / 'bad.yaml').write_text('fault_sets: 3\n')
    with pytest.raises(common.BenchError, match=r'--optima .*bad.yaml: expected fault_sets'):
        latency.served_optima(tmp_path / 'bad.yaml')


@pytest.mark.parametrize('library', ['product', 'demo'])
def test_the_packaged_optima_were_made_for_the_packaged_model_and_settings(library):
    """
    A quality figure is a gap to a stored best-known, which must fit what is measured.

    Optima made for another model, library or settings are a stale yardstick (the
    product's of 2026-12-04 were beaten by up to 1.29 % before they were made again).  A
    change that moves the fingerprint regenerates them: ``bench product --update-optima
    --optima-libraries LIBRARY``.
    """
    robot, lib = product.load_models(library)
    doc = product.load_product_best_known()
    assert product.fingerprint_warning(doc, library, robot, lib, product.node_settings()) == ''


@pytest.mark.parametrize('name', ['talos', 'tiago_dual'])
def test_the_other_robots_optima_were_made_for_their_models(name):
    from namo_fault_recovery.benchmarks.robots import load_optima, optima_warning, shipped_robot
    bench = shipped_robot(name)
    assert optima_warning(bench, load_optima(bench), *bench.models()) == ''
