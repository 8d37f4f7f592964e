"""The similarity score: zero at the references, the spec's check value, batching."""

from namo_fault_recovery import gesture_targets, ScoreWeights, SimilarityScore
from namo_fault_recovery.objective.score import rotation_angle_deg
import numpy as np
import pytest


def test_zero_at_every_reference(robot, library):
    for gesture in library:
        scorer = SimilarityScore.for_gesture(robot, gesture)
        kf = gesture.keyframes[0]
        total, parts = scorer(kf.right, kf.left, breakdown=True)
        assert total[0] == pytest.approx(0.0, abs=1e-9), gesture.name
        for value in parts.values():
            assert np.all(np.abs(value) < 1e-6)


def test_spec_check_value_wai_joint2(robot, library):
    wai = library['wai']
    q = wai.keyframes[0].right.copy()
    q[1] = np.radians(-14.25)
    total = SimilarityScore.for_gesture(robot, wai)(q)
    assert round(float(total[0]), 2) == 61.96


def test_default_weights_sum_to_one():
    w = ScoreWeights()
    np.testing.assert_allclose(w.vector(False), [0.25] * 4 + [0, 0])
    np.testing.assert_allclose(w.vector(True), [1 / 6] * 6)
    raw = ScoreWeights(elbow=2.0, normalise=False)
    np.testing.assert_allclose(raw.vector(False), [2, 1, 1, 1, 0, 0])


def test_breakdown_recombines_to_total(robot, library):
    rng = np.random.default_rng(0)
    wai = library['wai']
    scorer = SimilarityScore.for_gesture(robot, wai, weights=ScoreWeights(tip=3.0))
    q = rng.uniform(-1, 1, size=(30, 7))
    total, parts = scorer(q, breakdown=True)
    w = scorer.weights.vector(True)
    again = sum(w[i] * parts[c] for i, c in enumerate(
        ('elbow', 'wrist', 'tip', 'palm', 'wrist_lr', 'tip_lr')))
    np.testing.assert_allclose(total, again)
    assert np.all(total > 0)


def test_library_batch_equals_per_gesture(robot, library):
    targets = [t for g in library for t in gesture_targets(g)]
    batch = SimilarityScore(robot, targets)
    rng = np.random.default_rng(5)
    qr = rng.uniform(-np.pi, np.pi, size=(len(targets) * 3, 7))
    ql = rng.uniform(-np.pi, np.pi, size=qr.shape)
    index = np.tile(np.arange(len(targets)), 3)
    scores = batch(qr, ql, target=index)
    for k, gesture in enumerate(library):
        single = SimilarityScore.for_gesture(robot, gesture)
        rows = index == k
        np.testing.assert_allclose(scores[rows], single(qr[rows], ql[rows]))


def test_one_arm_gesture_ignores_other_arm(robot, library):
    bye = library['bye']
    scorer = SimilarityScore.for_gesture(robot, bye)
    q = bye.keyframes[0].right
    assert scorer(q, np.ones(7))[0] == pytest.approx(0.0, abs=1e-9)


def test_rotation_angle_is_accurate_near_zero_and_pi():
    def rot_z(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    for deg in (1e-6, 0.5, 19.25, 90.0, 179.0, 180.0):
        got = rotation_angle_deg(np.eye(3), rot_z(np.radians(deg)))
        assert got == pytest.approx(deg, rel=1e-6, abs=1e-9)


@pytest.mark.parametrize('kwargs, message', [
    ({'elbow': -1.0}, 'elbow.*>= 0'),
    ({'palm': float('nan')}, 'palm'),
    ({'elbow': 0, 'wrist': 0, 'tip': 0, 'palm': 0}, 'at least one'),
])
def test_bad_weights(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ScoreWeights(**kwargs)


def test_unknown_weight_key():
    with pytest.raises(ValueError, match="unknown component 'knee'"):
        ScoreWeights.from_mapping({'knee': 1.0})


@pytest.mark.parametrize('gesture', ['wai', 'bye'])
def test_the_residuals_recombine_to_the_score_with_their_jacobians(robot, library, gesture):
    """The least-squares blocks sum (w |r|) to the score, their Jacobians match differences."""
    from namo_fault_recovery.model.kinematics import batch_forward_jacobian
    scorer = SimilarityScore(robot, gesture_targets(library[gesture]))
    q = {side: np.random.default_rng(k).uniform(-0.8, 0.8, (4, 7))
         for k, side in enumerate(('right', 'left'))}
    target = np.arange(4) % len(scorer.targets)

    def blocks(q):
        pairs = {side: batch_forward_jacobian(robot, q[side], side) for side in q}
        lms = {side: pair[0] for side, pair in pairs.items()}
        return scorer.residuals(lms, {side: pair[1] for side, pair in pairs.items()}, target)

    base = blocks(q)
    total = sum(w * np.linalg.norm(r, axis=-1) for r, _, w in base)
    exact, parts = scorer.evaluate(q['right'], q['left'], target, breakdown=True)
    # The palm blocks carry sin(angle) about the rotation's axis; all else is the score's.
    w_palm = ScoreWeights().vector(library[gesture].two_handed)[3]
    arms = [s for s in ('right', 'left') if s in library[gesture].arms]
    sag = sum(parts[s][:, 3] - np.degrees(np.sin(np.radians(parts[s][:, 3]))) for s in arms)
    assert np.allclose(total, exact - w_palm * sag, rtol=1e-9, atol=1e-9)
    h = 1e-6
    for side in ('right', 'left'):
        for j in range(7):
            moved = {s: v.copy() for s, v in q.items()}
            moved[side][:, j] += h
            for (r0, d_r, _), (r1, _, _) in zip(base, blocks(moved)):
                fd = (r1 - r0) / h
                analytic = d_r[side][..., j] if side in d_r else np.zeros_like(fd)
                assert np.allclose(analytic, fd, atol=1e-3 * (1.0 + np.abs(fd).max()))
