"""
Retargeting: a gesture library designed on one robot, made for another (ROS-free).

Each keyframe's landmarks (elbow, wrist, fingertip) on the source robot are taken in
that arm's shoulder frame (relative to its shoulder point, :func:`shoulder_position`),
scaled by the ratio of the two arms' lengths (shoulder-elbow-wrist-fingertip at the
zero pose) and placed at the target arm's shoulder; the palm keeps its rotation away
from the arm's zero pose (``R R0^T``, applied to the target's own zero-pose palm),
since two robots' palm frames need not agree.  Both base frames are taken as x
forward, z up (a humanoid's ``base_link`` convention, REP 103).  The target robot's
angles are then found with the engine's own objective: the similarity score against
these scaled landmarks (:class:`~..objective.score.SimilarityScore` with
``reference_landmarks``) plus the capsule self-collision penalty, on the problem the
keyframe search solves (:class:`~.keyframes.PoseProblem`), searched by the engine's
bee colony with a larger budget (no deadline: this runs once, offline).
Both arms are matched in every keyframe, the resting arm of a one-handed gesture to
the source's resting arm, so that the library's resting pose is also the source's.
A motion's later keyframes start from the keyframe before them and are drawn towards
it (the engine's ``stay_close``), so that a motion stays on one branch.
"""

from dataclasses import dataclass

import numpy as np

from .keyframes import PoseProblem
from ..model.kinematics import ArmLandmarks, forward_kinematics, shoulder_position
from ..model.robot import ARMS
from ..model.self_contact import designed_pairs
from ..objective.collision import CollisionModel
from ..objective.score import SimilarityScore, Target
from ..optimize.base import Clock, minimize
from ..optimize.registry import make_algorithm

SOURCES = 64            # food sources of the engine's colony (its default preset has 8)
CYCLES = 60             # colony cycles per keyframe (each source polished as the engine does)
STAY_CLOSE = 1e-3       # per deg^2 away from the keyframe before (a motion's branch)


def arm_length(robot, side: str) -> float:
    """Return an arm's length (mm): shoulder-elbow-wrist-fingertip at the zero pose."""
    lm = forward_kinematics(robot, np.zeros(len(robot.arms[side].joint_names)), side)
    pts = np.stack((shoulder_position(robot, side), lm.elbow, lm.wrist, lm.tip))
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def scaled_landmarks(source, target, side: str, q: np.ndarray) -> ArmLandmarks:
    """Return the source arm's landmarks for q (N, n), moved into the target's arm."""
    lm = forward_kinematics(source, q, side)
    scale = arm_length(target, side) / arm_length(source, side)
    s0, t0 = shoulder_position(source, side), shoulder_position(target, side)
    rest_s = forward_kinematics(source, np.zeros(q.shape[-1]), side).palm
    rest_t = forward_kinematics(target, np.zeros(len(target.arms[side].joint_names)),
                                side).palm
    move = (lambda p: t0 + scale * (p - s0))
    palm = lm.palm @ rest_s.T @ rest_t
    return ArmLandmarks(move(lm.elbow), move(lm.wrist), move(lm.tip), palm)


@dataclass(frozen=True)
class RetargetedGesture:
    """One gesture on the target robot: angles per keyframe and its score per keyframe."""

    name: str
    right: np.ndarray       # (K, n) rad
    left: np.ndarray        # (K, n) rad
    scores: np.ndarray      # (K,) against the scaled reference
    collides: np.ndarray    # (K,) bool: a capsule pair still penetrates


def _problem(target, scorer, checker, ids, starts, anchor=None):
    """Return the PoseProblem of both arms' joints for targets ``ids``, rows ``starts``."""
    free = tuple((side, j) for side in ARMS for j in range(len(target.arms[side].joint_names)))
    n = len(ids)
    base = (np.zeros((n, len(free) // 2)), np.zeros((n, len(free) // 2)))
    return PoseProblem(target, scorer, ids, base, free, collision=checker,
                       anchor=anchor, continuity=STAY_CLOSE if anchor is not None else 0.0,
                       x0=starts[:, 0])


def _solve_keyframe(target, scorer, checker, k, start, anchor, seed):
    """Search keyframe k with the engine's colony from ``start`` (D,); return the best x."""
    problem = _problem(target, scorer, checker, np.array([k]), start[None, None],
                       None if anchor is None else anchor[None])
    algo = make_algorithm('abc', 'default', n_sources=SOURCES, max_cycles=CYCLES)
    res = minimize(problem, algo, clock=Clock(None), seed=seed)
    return np.atleast_2d(res.x)[0]


def _designed_allowance(checker, targets, ref_r, ref_l):
    """Set the checker's designed contact from the scaled references (not from angles)."""
    d = checker.distances(ref_r, ref_l)[0]
    designed = np.array([designed_pairs(t.two_handed) for t in targets], dtype=bool)
    checker.allowed = np.where(designed, np.minimum(checker.radius_sum[None, :], d),
                               checker.radius_sum[None, :])


def retarget_gesture(source, target, gesture, rng):
    """Return the :class:`RetargetedGesture` of one gesture of ``source`` on ``target``."""
    qr = np.array([kf.right for kf in gesture.keyframes])
    ql = np.array([kf.left for kf in gesture.keyframes])
    ref_r = scaled_landmarks(source, target, 'right', qr)
    ref_l = scaled_landmarks(source, target, 'left', ql)
    n = len(target.arms['right'].joint_names)
    zeros = np.zeros((len(qr), n))
    targets = [Target(zeros[k], zeros[k], ARMS, gesture.two_handed, f'{gesture.name}[{k}]',
                      gesture.weights) for k in range(len(qr))]
    scorer = SimilarityScore(target, targets, reference_landmarks=(ref_r, ref_l))
    checker = CollisionModel(target, targets, target.capsules)
    _designed_allowance(checker, targets, ref_r, ref_l)
    low = np.concatenate([target.arms[s].lower for s in ARMS])
    high = np.concatenate([target.arms[s].upper for s in ARMS])
    out, prev = [], None
    for k in range(len(qr)):
        start = np.clip(np.zeros(2 * n) if prev is None else prev, low, high)
        prev = _solve_keyframe(target, scorer, checker, k, start, prev,
                               int(rng.integers(2 ** 63)))
        out.append(prev)
    x = np.array(out)
    right, left = x[:, :n], x[:, n:]
    ids = np.arange(len(qr))
    lm_r = forward_kinematics(target, right, 'right')
    lm_l = forward_kinematics(target, left, 'left')
    scores = scorer.evaluate(lm_r, lm_l, ids)
    return RetargetedGesture(gesture.name, right, left, np.asarray(scores),
                             checker.collides(lm_r, lm_l, ids))


def gesture_score(target, gesture_result, gesture, source):
    """Return the score per keyframe of a gesture's angles on ``target``, as designed."""
    qr = np.array([kf.right for kf in gesture.keyframes])
    ql = np.array([kf.left for kf in gesture.keyframes])
    ref = (scaled_landmarks(source, target, 'right', qr),
           scaled_landmarks(source, target, 'left', ql))
    targets = [Target(gesture_result.right[k], gesture_result.left[k], gesture.arms,
                      gesture.two_handed, gesture.name, gesture.weights)
               for k in range(len(qr))]
    scorer = SimilarityScore(target, targets, reference_landmarks=ref)
    return scorer(gesture_result.right, gesture_result.left, np.arange(len(qr)))
