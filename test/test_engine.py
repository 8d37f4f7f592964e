"""The one engine entry point, recover(), and the one result type it returns."""

import io
import json

from namo_fault_recovery.cli.main import main
from namo_fault_recovery.model.gestures import GestureLibrary
from namo_fault_recovery.objective.score import ScoreWeights, SimilarityScore
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import recover, RecoverySettings
from namo_fault_recovery.recovery.locks import resolve_locks
from namo_fault_recovery.recovery.result import LibraryResult
import numpy as np
import pytest

FAULT = 'right_arm_joint2'


@pytest.fixture(scope='module')
def node_default(robot, demo_library):
    """
    Recover the demo library with the node's defaults, seed 11, no deadline.

    The demo library (the four gestures plus the dense circle) exercises keyframed
    gestures and a dense motion in one run.
    """
    return recover(robot, demo_library, {FAULT: None}, RecoverySettings(), seed=11,
                   clock=Clock(None))


def test_same_seed_without_deadline_gives_the_same_library(
        robot, demo_library, node_default):
    again = recover(robot, demo_library, {FAULT: None}, RecoverySettings(), seed=11,
                    clock=Clock(None))
    assert again.names == node_default.names
    for a, b in zip(again.gestures, node_default.gestures):
        assert a.positions == b.positions and a.score_after == b.score_after
    assert node_default.deadline is None and node_default.seed == 11
    # The fault changed something: the run is not trivially the reference.
    assert node_default['wai'].score_before > 0
    assert node_default['wai'].score_after < node_default['wai'].score_before


def test_solve_gives_the_library_recover_gives(demo_library, node_default):
    out = io.StringIO()
    assert main(['--gesture-file', str(demo_library.source), 'solve', '--fault', FAULT,
                 '--seed', '11', '--no-deadline', '--json'], out) == 0
    doc = json.loads(out.getvalue())
    assert doc['settings'] == RecoverySettings().public()
    assert doc['deadline'] is None and doc['seed'] == 11
    assert [g['name'] for g in doc['gestures']] == list(node_default.names)
    for g, want in zip(doc['gestures'], node_default.gestures):
        assert np.array_equal(np.array(g['positions']), np.array(want.positions)), g['name']
        assert g['score_after'] == want.score_after
    assert doc['total_score'] == pytest.approx(node_default.total_score)
    assert doc['locks'] == node_default.locks


def test_deadline_sec_zero_is_no_deadline_too(robot, library):
    runs = []
    for flag in (['--deadline-sec', '0'], ['--no-deadline']):
        out = io.StringIO()
        assert main(['--gesture-file', str(library.source), 'solve', '--fault', FAULT,
                     '--seed', '4', '--json'] + flag, out) == 0
        runs.append(json.loads(out.getvalue()))
    assert runs[0]['deadline'] is None and runs[1]['deadline'] is None
    assert ([g['positions'] for g in runs[0]['gestures']]
            == [g['positions'] for g in runs[1]['gestures']])


def test_solve_one_gesture_keeps_the_whole_library_lock(robot, library):
    out = io.StringIO()
    assert main(['--gesture-file', str(library.source), 'solve', '--fault', FAULT,
                 '--gesture', 'bye', '--seed', '1', '--json'], out) == 0
    doc = json.loads(out.getvalue())
    locks, _ = resolve_locks(robot, library, {FAULT: None})
    assert [g['name'] for g in doc['gestures']] == ['bye']
    assert doc['locks'][FAULT] == pytest.approx(locks[FAULT])
    assert doc['faults'] == {FAULT: None}
    assert doc['gestures'][0]['positions'][0][1] == pytest.approx(locks[FAULT])


@pytest.mark.parametrize('name, value', [
    ('deadline_sec', 0.0), ('deadline_sec', float('nan')), ('lock_strategy', 'best'),
    ('optimizer', 'pso'), ('optimizer_preset', 'fast'), ('bimanual', 'both'),
    ('tool_length_mm', -5.0), ('tool_arm', 'middle'), ('trajectory_method', 'spline'),
    ('vq_distortion_mm', 0.0), ('continuity_weight', float('inf')),
    ('collision_check', 'yes'), ('deadline_sec', True), ('weights', {'elbow': 1.0}),
])
def test_settings_reject_a_bad_value_naming_setting_and_value(name, value):
    with pytest.raises(ValueError) as info:
        RecoverySettings(**{name: value})
    message = str(info.value)
    assert message.startswith(f'{name}: ')
    assert repr(value) in message or str(value) in message


def test_no_faults_gives_the_reference_library(robot, product_library):
    result = recover(robot, product_library, {}, RecoverySettings(), seed=2)
    assert result.names == product_library.names
    for g, ref in zip(result.gestures, product_library):
        assert g.positions == tuple(tuple(float(a) for a in kf.positions())
                                    for kf in ref.keyframes)
        assert g.times == tuple(float(t) for t in ref.times) and g.status == 'unchanged'
        assert g.score_before == 0.0 and g.score_after == 0.0
    assert result.locks == {} and result.total_score == 0.0 and result.seed == 2


def test_result_lookup_total_and_round_trip(node_default):
    assert node_default['circle'].name == 'circle'
    with pytest.raises(KeyError, match="unknown gesture 'hug'"):
        node_default['hug']
    assert node_default.total_score == pytest.approx(
        sum(g.score_after for g in node_default.gestures))
    circle = node_default['circle']
    assert circle.nfev > 0 and circle.free_joints and circle.stage1_score is not None
    assert len(circle.typical_indices) == circle.typical_points > 0
    assert circle.tip_error_before_mm > circle.tip_error_mm
    back = LibraryResult.from_dict(json.loads(json.dumps(node_default.to_dict())))
    assert back == node_default


def test_old_state_documents_still_load(node_default):
    doc = node_default.to_dict()
    for key in ('seed', 'notes', 'nfev'):
        doc.pop(key)
    doc['settings'] = dict(doc['settings'], seed=5, notes=['an old note'])
    for g in doc['gestures']:
        for key in ('nfev', 'free_joints', 'stage1_score', 'typical_indices',
                    'kriging_sigma_deg', 'tip_error_max_mm'):
            g.pop(key)
    old = LibraryResult.from_dict(doc)
    assert old.seed == 5 and old.notes == ('an old note',)
    assert 'seed' not in old.settings and 'notes' not in old.settings
    assert old['circle'].stage1_score is None and old['circle'].nfev == 0
    assert old['circle'].positions == node_default['circle'].positions


def test_scores_and_breakdown_are_those_of_the_published_keyframes(robot, demo_library,
                                                                   node_default):
    for name in ('wai', 'circle'):
        gesture, g = demo_library[name], node_default[name]
        scores, parts = [], []
        for k, kf in enumerate(g.keyframes):
            scorer = SimilarityScore.for_gesture(robot, gesture, k, ScoreWeights())
            total, part = scorer(kf.right, kf.left, breakdown=True)
            scores.append(float(total[0]))
            parts.append({c: float(part[c][0]) for c in g.breakdown})
        worst = int(np.argmax(scores))
        assert g.score_after == pytest.approx(scores[worst], rel=1e-9)
        assert g.score_mean == pytest.approx(np.mean(scores), rel=1e-9)
        assert g.breakdown == pytest.approx(parts[worst], rel=1e-9, abs=1e-9)
        assert set(g.breakdown) >= {'elbow', 'wrist', 'tip', 'palm'}


def test_a_cut_short_motion_worse_than_the_locked_design_is_replaced_by_it(robot, library):
    from dataclasses import replace
    from namo_fault_recovery.recovery.figures import no_worse_than_locked
    settings = RecoverySettings()
    result = recover(robot, library, {'right_arm_joint2': None}, settings, seed=0)
    lock = result.locks['right_arm_joint2']
    wai = result['wai']
    kept = no_worse_than_locked(robot, library['wai'], wai, result.locks, settings)
    assert kept is wai                                   # better than the design: kept
    worse = replace(wai, score_after=wai.score_before + 10.0, status='deadline')
    fixed = no_worse_than_locked(robot, library['wai'], worse, result.locks, settings)
    assert fixed.score_after == wai.score_before
    column = robot.joint_names.index('right_arm_joint2')
    for q, kf in zip(fixed.positions, library['wai'].keyframes):
        design = list(kf.positions())
        design[column] = lock
        assert list(q) == design
    assert 'cut short' in fixed.message


def _locked_design(robot, gesture, locks):
    """Return a gesture's design (K, 14) with ``locks`` applied."""
    q = gesture.joint_matrix().copy()
    for joint, angle in locks.items():
        q[:, robot.joint_names.index(joint)] = angle
    return q


def _penetration(robot, gesture, positions):
    """Return (any point collides, total penetration in mm) of angles (K, 14)."""
    from namo_fault_recovery.model.kinematics import batch_forward
    from namo_fault_recovery.model.robot import N_JOINTS
    from namo_fault_recovery.objective.collision import CollisionModel
    from namo_fault_recovery.objective.score import gesture_targets
    checker = CollisionModel(robot, gesture_targets(gesture), robot.capsules)
    q = np.array(positions, dtype=float)
    n = N_JOINTS
    lm_r, lm_l = batch_forward(robot, q[:, :n], 'right'), batch_forward(robot, q[:, n:], 'left')
    rows = np.arange(len(q))
    return (bool(checker.collides(lm_r, lm_l, rows).any()),
            float(checker.penetration(lm_r, lm_l, rows).sum()))


def test_a_clear_result_is_never_traded_for_a_colliding_locked_design(robot, library):
    # Right joint 2 stuck at 20 deg drives the locked Wai into the torso and the other
    # hand; it still scores 35.37.  Seed 0 once found only a clear pose scoring 43.31,
    # and the fallback to the locked design published the colliding pose.  The search
    # now finds a better clear pose (the repair starts from the colliding optimum too),
    # so the case is made by hand: a clear result that scores worse than the design.
    from dataclasses import replace
    from namo_fault_recovery.recovery.figures import no_worse_than_locked
    locks = {'right_arm_joint2': float(np.radians(20.0))}
    settings = RecoverySettings()
    wai = recover(robot, library, locks, settings, seed=0, clock=Clock(None))['wai']
    assert not wai.collides and wai.colliding_pairs == ()
    assert not _penetration(robot, library['wai'], wai.positions)[0]
    hit, _ = _penetration(robot, library['wai'], _locked_design(robot, library['wai'], locks))
    assert hit                                     # the locked design collides
    worse = replace(wai, score_after=wai.score_before + 8.0, message='wai: reconfigured')
    out = no_worse_than_locked(robot, library['wai'], worse, locks, settings)
    assert out.positions == wai.positions and not out.collides
    assert out.score_after == worse.score_after
    assert 'WARNING' not in out.message and 'that design is published' not in out.message
    assert f'scores better ({wai.score_before:.2f}) but collides' in out.message


def test_of_two_colliding_poses_the_shallower_is_published(robot, library):
    from dataclasses import replace
    from namo_fault_recovery.recovery.figures import no_worse_than_locked
    settings, gesture = RecoverySettings(), library['wai']
    shallow = {'right_arm_joint2': float(np.radians(20.0))}
    deep = {'right_arm_joint2': float(np.radians(40.0))}
    q_shallow = _locked_design(robot, gesture, shallow)
    q_deep = _locked_design(robot, gesture, deep)
    (hit_s, pen_s), (hit_d, pen_d) = (_penetration(robot, gesture, q_shallow),
                                      _penetration(robot, gesture, q_deep))
    assert hit_s and hit_d and pen_s < pen_d
    base = recover(robot, library, shallow, settings, seed=0, clock=Clock(None))['wai']
    # A result deeper in contact than the locked design: the locked design is published.
    worse = replace(base, positions=tuple(map(tuple, q_deep)), collides=True,
                    score_after=base.score_before + 10.0,
                    message='wai: reconfigured; WARNING: the pose still collides')
    out = no_worse_than_locked(robot, gesture, worse, shallow, settings)
    assert np.allclose(out.positions, q_shallow) and out.collides and out.colliding_pairs
    assert out.score_after == base.score_before
    assert out.message.endswith('that design is published; WARNING: the pose still collides')
    # A result in shallower contact than the locked design is kept.
    out = no_worse_than_locked(robot, gesture, replace(worse, positions=tuple(map(
        tuple, q_shallow))), deep, settings)
    assert np.allclose(out.positions, q_shallow) and out.score_after == worse.score_after
    assert 'but collides deeper' in out.message


@pytest.mark.parametrize('fault, gesture', [
    # Keyframes 1 and 3 of the wave, solved independently, landed in basins 24.8 to
    # 33.0 apart from seed to seed; each now restarts from its neighbours' branches.
    ('right_arm_joint5', 'bye'),
    # One pose: the reference start is in the best basin but 50 polish iterations
    # stopped 3 % above its floor, in 9 seeds of 10.
    ('right_arm_joint6', 'wai'),
])
def test_every_seed_finds_the_best_basin_of_the_served_library(
        robot, product_library, fault, gesture):
    # The node's library without the circle (its Kriging path is another matter), the
    # node's settings, no deadline: every seed ends within 1 % of the best known, the
    # best of these runs and of a much longer one (more starts, polished longer).
    served = GestureLibrary(tuple(g for g in product_library if g.name != 'circle'),
                            product_library.source)
    scores = [recover(robot, served, {fault: None}, RecoverySettings(), seed=seed,
                      clock=Clock(None))[gesture].score_after for seed in range(4)]
    thorough = recover(robot, served, {fault: None}, RecoverySettings(), seed=0,
                       clock=Clock(None), optimizer_overrides={
                           'n_sources': 20, 'max_cycles': 40, 'polish': 8,
                           'polish_maxiter': 300})[gesture].score_after
    assert max(scores) <= 1.01 * min(scores + [thorough]), (scores, thorough)


def test_a_dense_motion_that_still_collides_says_so(robot, demo_library, monkeypatch):
    """The circle (Kriging, then the whole-trajectory pass) warns as a keyframed gesture."""
    from namo_fault_recovery.recovery import figures
    monkeypatch.setattr(figures, 'collisions',
                        lambda *args: (True, ('right_hand-torso',)))
    res = recover(robot, demo_library, {FAULT: None}, RecoverySettings(), seed=11,
                  clock=Clock(None))
    circle = res['circle']
    assert circle.collides and circle.method != 'keyframes'
    assert circle.message.endswith(figures.COLLIDES_WARNING), circle.message
