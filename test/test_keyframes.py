"""Library reconfiguration: locks, fault layouts, frozen arms, reproducibility, CLI."""

import io
import json
from pathlib import Path

from namo_fault_recovery.cli.main import main
from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.objective.score import gesture_targets, SimilarityScore
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import RecoverySettings
from namo_fault_recovery.recovery.keyframes import PoseProblem, reconfigure_library
from namo_fault_recovery.recovery.keyframes import SearchOptions
from namo_fault_recovery.resources import config_path, PAPER_GESTURE_FILE
import numpy as np
import pytest

CONFIG_DIR = Path(__file__).resolve().parent.parent / 'config'
# The keyframe search's own problem, the paper's: no stage 2, no collision term.
PAPER = RecoverySettings(bimanual='off', collision_check=False)


def _check_locks(robot, report):
    for g in report.gestures:
        for kf in g.keyframes:
            for joint, angle in report.locks.items():
                side, j = robot.locate_joint(joint)
                assert kf.arm(side)[j] == angle, (g.name, joint)
            for side in ('right', 'left'):
                arm = robot.arms[side]
                assert np.all(kf.arm(side) >= arm.lower) and np.all(kf.arm(side) <= arm.upper)


@pytest.mark.parametrize('joint', [f'right_arm_joint{k}' for k in range(1, 8)])
def test_single_fault_locks_and_improves(robot, library, joint):
    report = reconfigure_library(robot, library, {joint: None}, PAPER, seed=0)
    side, j = robot.locate_joint(joint)
    assert report.locks[joint] == pytest.approx(library.lock_averages(side)[j])
    _check_locks(robot, report)
    scorer = SimilarityScore(robot, [t for g in library for t in gesture_targets(g)])
    for k, g in enumerate(report.gestures):
        assert g.score_after <= g.score_before + 1e-12
        assert np.isfinite(g.score_after)
        kf = g.keyframes[0]
        assert scorer(kf.right, kf.left, target=k)[0] == pytest.approx(g.score_after)
        assert g.status == 'converged'
    assert report.success


def test_explicit_lock_angle_is_used(robot, library):
    report = reconfigure_library(robot, library, {'right_arm_joint5': 0.3}, PAPER, seed=0,
                                 gestures=['bye'])
    assert report.locks == {'right_arm_joint5': 0.3}
    assert report['bye'].keyframes[0].right[4] == 0.3
    assert [g.name for g in report.gestures] == ['bye']


def test_same_seed_same_library(robot, library):
    a = reconfigure_library(robot, library, {'right_arm_joint3': None}, PAPER, seed=7,
                            clock=Clock(None))
    b = reconfigure_library(robot, library, {'right_arm_joint3': None}, PAPER, seed=7,
                            clock=Clock(None))
    for ga, gb in zip(a.gestures, b.gestures):
        np.testing.assert_array_equal(ga.keyframes[0].right, gb.keyframes[0].right)


def test_multiple_faults_both_arms(robot, library):
    faults = {'right_arm_joint1': None, 'right_arm_joint6': -0.2, 'left_arm_joint2': None}
    report = reconfigure_library(robot, library, faults, PAPER, seed=1)
    _check_locks(robot, report)
    wai = report['wai']
    assert set(wai.free_joints) == ({f'right_arm_joint{k}' for k in (2, 3, 4, 5, 7)}
                                    | {f'left_arm_joint{k}' for k in (1, 3, 4, 5, 6, 7)})
    # One-arm gestures only move the right arm: the left is not part of them.
    assert all(j.startswith('right') for j in report['bye'].free_joints)
    assert all(g.score_after <= g.score_before for g in report.gestures)


def test_left_fault_leaves_one_arm_gestures_unchanged(robot, library):
    report = reconfigure_library(robot, library, {'left_arm_joint4': 1.0}, PAPER, seed=1)
    assert report['bye'].status == 'unchanged'
    assert report['bye'].score_after == report['bye'].score_before == 0.0
    assert report['wai'].status == 'converged'
    assert report['wai'].score_after < report['wai'].score_before


def test_fully_failed_arm_is_frozen_other_arm_served(robot, library):
    faults = {f'right_arm_joint{k}': None for k in range(1, 8)}
    faults['left_arm_joint2'] = 0.4
    report = reconfigure_library(robot, library, faults, PAPER, seed=2)
    assert report.frozen_arms == ('right',)
    assert any('frozen' in n for n in report.notes)
    assert report['bye'].status == 'frozen'
    np.testing.assert_allclose(report['bye'].keyframes[0].right,
                               library.lock_averages('right'))
    wai = report['wai']   # the left arm still moves to do its best
    assert wai.status == 'converged'
    assert all(j.startswith('left') for j in wai.free_joints)
    assert wai.score_after < wai.score_before
    _check_locks(robot, report)


def test_no_fault_returns_the_reference(robot, library):
    report = reconfigure_library(robot, library, {}, PAPER, seed=0)
    for g, ref in zip(report.gestures, library):
        assert g.status == 'unchanged' and g.score_after == 0.0
        np.testing.assert_array_equal(g.keyframes[0].right, ref.keyframes[0].right)


@pytest.mark.parametrize('faults, message', [
    ({'elbow': None}, "unknown joint 'elbow'"),
    ({'right_arm_joint1': float('nan')}, 'finite'),
    ({'right_arm_joint1': 7.0}, 'outside the joint limits'),
])
def test_bad_faults_raise(robot, library, faults, message):
    with pytest.raises(ValueError, match=message):
        reconfigure_library(robot, library, faults, PAPER)


def test_deadline_status_and_finite_result(robot, library):
    report = reconfigure_library(robot, library, {'right_arm_joint2': None},
                                 PAPER.with_changes(optimizer_preset='paper'), clock=Clock(0.02),
                                 seed=0)
    assert not report.deadline_met and not report.success
    for g in report.gestures:
        assert g.status == 'deadline' and np.isfinite(g.score_after)
        assert g.score_after <= g.score_before
    _check_locks(robot, report)


def test_the_callers_clock_owns_the_deadline_and_the_cancel_flag(robot, library):
    faults = {'right_arm_joint2': 0.1}
    free = reconfigure_library(robot, library, faults, PAPER, clock=Clock(None), seed=5)
    same = reconfigure_library(robot, library, faults, PAPER, clock=Clock(None), seed=5)
    assert [g.keyframes[0].positions().tolist() for g in same.gestures] == \
        [g.keyframes[0].positions().tolist() for g in free.gestures]
    assert same.deadline is None
    cut = reconfigure_library(robot, library, faults, PAPER, clock=Clock(0.0), seed=5)
    assert all(g.status == 'deadline' for g in cut.gestures) and cut.deadline == 0.0
    _check_locks(robot, cut)
    stopped = reconfigure_library(robot, library, faults, PAPER, seed=5,
                                  clock=Clock(None, cancel=lambda: True))
    assert stopped.cancelled
    with pytest.raises(TypeError, match='cancel'):   # the cancel flag is the clock's
        reconfigure_library(robot, library, faults, PAPER, clock=Clock(None),
                            cancel=lambda: True)


def test_gradient_matches_finite_differences(robot, library):
    scorer = SimilarityScore(robot, [t for g in library for t in gesture_targets(g)])
    rng = np.random.default_rng(4)
    qr, ql = rng.uniform(-3, 3, (8, 7)), rng.uniform(-3, 3, (8, 7))
    target = np.array([0, 1, 2, 3, 0, 0, 1, 2])
    f, g_right, g_left = scorer.value_and_grad(qr, ql, target)
    np.testing.assert_allclose(f, scorer.evaluate(qr, ql, target))
    h = 1e-6
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = h
        fd_r = (scorer.evaluate(qr + dq, ql, target) - scorer.evaluate(qr - dq, ql, target))
        fd_l = (scorer.evaluate(qr, ql + dq, target) - scorer.evaluate(qr, ql - dq, target))
        np.testing.assert_allclose(g_right[:, i], fd_r / (2 * h), atol=1e-5)
        np.testing.assert_allclose(g_left[:, i], fd_l / (2 * h), atol=1e-5)


def test_the_pull_is_per_row_and_a_row_without_one_scores_its_similarity(robot, library):
    targets = [t for g in library for t in gesture_targets(g)]
    scorer = SimilarityScore(robot, targets)
    free = tuple(('right', j) for j in range(7))
    base = (np.array([t.q_right for t in targets[:2]]), np.array([t.q_left for t in targets[:2]]))
    anchor = np.radians([[10.0] * 7, [-20.0] * 7])
    problem = PoseProblem(robot, scorer, [0, 1], base, free, anchor=anchor,
                          continuity=[0.0, 0.01])
    x = np.random.default_rng(2).uniform(-1.0, 1.0, (2, 3, 7))
    qr, ql = problem.assemble(x)
    plain = scorer.evaluate(qr.reshape(-1, 7), ql.reshape(-1, 7),
                            np.repeat([0, 1], 3)).reshape(2, 3)
    pull = 0.01 * np.sum(np.degrees(x[1] - anchor[1]) ** 2, axis=-1)
    f = problem.evaluate(x)
    np.testing.assert_allclose(f[0], plain[0])
    np.testing.assert_allclose(f[1], plain[1] + pull)
    value, grad = problem.value_and_grad(x)   # of the score rounded by 0.01 mm or deg
    np.testing.assert_allclose(value, f, atol=0.1)
    h = 1e-6
    for i in range(7):
        dx = np.zeros(7)
        dx[i] = h
        fd = (problem.evaluate(x + dx) - problem.evaluate(x - dx)) / (2 * h)
        np.testing.assert_allclose(grad[..., i], fd, rtol=1e-4, atol=1e-3)
    assert problem.subset([1]).continuity == pytest.approx(problem.continuity[1:])


def test_a_gesture_left_out_of_pulled_is_solved_as_without_the_pull(robot, library):
    faults = {'right_arm_joint3': None}
    kw = {'seed': 4, 'clock': Clock(None)}
    plain = reconfigure_library(robot, library, faults, PAPER, **kw)
    unpulled = reconfigure_library(robot, library, faults, PAPER, **kw,
                                   options=SearchOptions(stay_close=0.05, pulled=()))
    pulled = reconfigure_library(robot, library, faults, PAPER, **kw,
                                 options=SearchOptions(stay_close=0.05))
    for a, b in zip(plain.gestures, unpulled.gestures):
        assert a.score_after == b.score_after, a.name
        np.testing.assert_array_equal(a.positions, b.positions)
    # A strong pull holds the poses near their design, at a cost in similarity.
    assert pulled.total_score > plain.total_score + 1.0


def test_cli_solve_json_schema(robot):
    out = io.StringIO()
    code = main(['--gesture-file', str(CONFIG_DIR / 'paper_gestures.yaml'), 'solve',
                 '--fault', 'right_arm_joint2', '--fault', 'left_arm_joint1=20',
                 '--seed', '3', '--json'], out)
    doc = json.loads(out.getvalue())
    assert code == 0 and doc['schema'] == 'namo_fault_recovery.solve/2'
    assert doc['faults'] == {'right_arm_joint2': None,
                             'left_arm_joint1': pytest.approx(np.radians(20.0))}
    assert doc['locks_deg']['left_arm_joint1'] == pytest.approx(20.0)
    assert doc['locks_deg']['right_arm_joint2'] == pytest.approx(-14.25)
    assert doc['seed'] == 3
    # The node's defaults, named as its parameters.
    assert doc['settings']['optimizer'] == 'abc' and doc['settings']['collision_check']
    assert doc['settings']['deadline_sec'] == 1.0 and doc['deadline'] == 1.0
    assert [g['name'] for g in doc['gestures']] == ['wai', 'bye', 'salute', 'side_invite']
    assert doc['total_score'] == pytest.approx(sum(g['score_after'] for g in doc['gestures']))
    for g in doc['gestures']:
        assert {'name', 'times', 'positions', 'score_before', 'score_after', 'wall_time',
                'status', 'stage', 'stage1_score', 'free_joints', 'nfev', 'collides',
                'breakdown'} <= set(g)
        assert all(len(p) == 14 for p in g['positions'])
        assert g['positions'][0][1] == pytest.approx(np.radians(-14.25))
        assert g['positions'][0][7] == pytest.approx(np.radians(20.0))
        assert g['score_after'] <= g['score_before']


def test_cli_solve_text_and_errors(capsys):
    out = io.StringIO()
    # The paper's Table 2 library, as the paper's figures are for it.
    assert main(['--gesture-file', str(config_path(PAPER_GESTURE_FILE)), 'solve', '--fault',
                 'right_arm_joint4', '--gesture', 'wai', '--algorithm', 'ga', '--preset',
                 'paper', '--seed', '1'], out) == 0
    assert 'wai: score 1.3974 ->' in out.getvalue()
    for argv, message in ((['solve', '--fault', 'right_arm_joint9'], 'unknown joint'),
                          (['solve', '--fault', 'right_arm_joint1=abc'], 'JOINT=DEG'),
                          (['solve', '--fault', 'right_arm_joint1', '--gesture', 'hug'],
                           "unknown gesture 'hug'"),
                          (['solve', '--fault', 'right_arm_joint1', '--algorithm', 'pso'],
                           'invalid choice'),
                          (['solve', '--fault', 'right_arm_joint1', '--deadline', '-1'],
                           '--deadline-sec'),
                          (['solve', '--fault', 'right_arm_joint1', '--vq-distortion-mm',
                            '0'], '--vq-distortion-mm: expected a finite number > 0, got 0.0')):
        assert main(argv, io.StringIO()) == 2
        err = capsys.readouterr().err
        assert message in err and err.count('\n') == 1


def test_the_keyframe_search_measures_the_figures_of_its_result(robot):
    # The keyframe search's GestureResult carries the same figures as a whole motion's:
    # no field is left at a default that would read as "0 mm" or "0 evaluations".
    library = load_library(robot)          # the packaged library: the Bye wave is a motion
    report = reconfigure_library(robot, library, {'right_arm_joint2': None}, PAPER, seed=0,
                                 clock=Clock(None))
    bye = report['bye']
    design = np.array([kf.positions() for kf in library['bye'].keyframes])
    designed_step = float(np.degrees(np.abs(np.diff(design, axis=0))).max())
    assert bye.max_jump_designed_deg == pytest.approx(designed_step)
    q = np.array(bye.positions)
    assert bye.max_jump_deg == pytest.approx(float(np.degrees(np.abs(np.diff(q, axis=0))).max()))
    for g in report.gestures:
        assert g.tip_error_before_mm > g.tip_error_mm >= 0.0, g.name
        assert g.tip_error_max_mm >= g.tip_error_mm
        assert g.nfev > 0 and g.wall_time == report.wall_time > 0
    assert abs(sum(g.nfev for g in report.gestures) - report.nfev) <= len(report.gestures)
