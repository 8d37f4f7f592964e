"""
Retargeting: a gesture library designed on one robot, made for another (ROS-free).

Each keyframe's landmarks (elbow, wrist, fingertip) on the source robot are taken in
that arm's shoulder frame (relative to its shoulder point, :func:`shoulder_point`),
scaled by the ratio of the two arms' lengths (shoulder-elbow-wrist-fingertip at the
zero pose) and placed at the target arm's shoulder; the palm keeps its rotation away
from the source's zero pose (``R R0^T``), applied to the target's palm in the pose
that matches the source's zero pose (:func:`rest_palms`), since two robots' palm frames
and zero poses need not agree.  Both base frames are taken as x
forward, z up (a humanoid's ``base_link`` convention, REP 103).  The target robot's
angles are then found with the engine's own objective: the similarity score against
these scaled landmarks (:class:`~..objective.score.SimilarityScore` with
``reference_landmarks``) plus the capsule self-collision penalty, on the problem the
keyframe search solves (:class:`~.keyframes.PoseProblem`), searched by the engine's
bee colony with a larger budget (no deadline: this runs once, offline).
Both arms are matched in every keyframe, the resting arm of a one-handed gesture to
the source's resting arm, so that the library's resting pose is also the source's.
A motion's later keyframes start from the keyframe before them and are drawn towards
it (the engine's ``stay_close``), so that a motion stays on one branch.  Of
:data:`RESTARTS` such searches per gesture (every other one starting each keyframe from
the source's own angles, clipped, when the arms have as many joints), the one with the
fewest capsule contacts, then the lowest summed score, is kept.
"""

from dataclasses import dataclass

import numpy as np

from .keyframes import PoseProblem
from ..model.kinematics import (arm_joint_count, ArmLandmarks, forward_kinematics,
                                shoulder_position, split_arms)
from ..model.robot import ARMS
from ..model.self_contact import designed_pairs
from ..model.weights import ScoreWeights
from ..objective.collision import CollisionModel
from ..objective.score import SimilarityScore, Target
from ..optimize.base import Clock, minimize
from ..optimize.registry import make_algorithm

SOURCES = 64            # food sources of the engine's colony (its default preset has 8)
CYCLES = 60             # colony cycles per keyframe (each source polished as the engine does)
REST_PALM_WEIGHT = 0.05  # the palm's weight when the rest pose is matched
RESTARTS = 4            # whole searches per gesture; the best (fewest contacts, then score)
STAY_CLOSE = 1e-3       # per deg^2 away from the keyframe before (a motion's branch)


def shoulder_point(robot, side: str) -> np.ndarray:
    """
    Return the origin (mm) of an arm's shoulder frame: its second joint's, at rest.

    On Namo the first two joints' origins coincide (:func:`shoulder_position`); on
    Talos and TIAGo++ the first joint is a mount beside the torso and the shoulder
    proper, where the upper arm starts, is the second joint's origin.
    """
    chains = getattr(robot, 'chains', None)
    if chains is None:
        return shoulder_position(robot, side)
    chain = chains[side].chain
    link = robot.profile.tree.joints[chain.joint_names[1]].child
    return np.array(chain.link_frames(np.zeros(chain.n_joints), [link])[link][0][0])


def arm_length(robot, side: str) -> float:
    """Return an arm's length (mm): shoulder-elbow-wrist-fingertip at the zero pose."""
    lm = forward_kinematics(robot, np.zeros(len(robot.arms[side].joint_names)), side)
    pts = np.stack((shoulder_point(robot, side), lm.elbow, lm.wrist, lm.tip))
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def scaled_landmarks(source, target, side: str, q: np.ndarray,
                     rest_palm: np.ndarray | None = None) -> ArmLandmarks:
    """
    Return the source arm's landmarks for q (N, n), moved into the target's arm.

    ``rest_palm`` is the target's palm rotation in the pose that matches the source's
    zero pose (:func:`rest_palms`); None takes the target's own zero pose.
    """
    lm = forward_kinematics(source, q, side)
    scale = arm_length(target, side) / arm_length(source, side)
    s0, t0 = shoulder_point(source, side), shoulder_point(target, side)
    rest_s = forward_kinematics(source, np.zeros(q.shape[-1]), side).palm
    rest_t = rest_palm if rest_palm is not None else forward_kinematics(
        target, np.zeros(len(target.arms[side].joint_names)), side).palm
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
    base = tuple(np.zeros((len(ids), arm_joint_count(target, side))) for side in ARMS)
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


def rest_palms(source, target, rng) -> dict:
    """
    Return {side: the target's palm rotation} in the pose that matches the source's rest.

    Two robots' zero poses need not agree (TIAGo++'s arms point sideways, Namo's hang):
    a palm keeps its rotation away from the rest pose, so the target's rest is found
    first, matching the source's zero-pose elbow, wrist and fingertip; the palm, at
    :data:`REST_PALM_WEIGHT`, only picks the roll of an arm that positions leave free
    (a hanging straight arm), the one nearest the target's own zero pose.
    """
    zero = {side: np.zeros((1, arm_joint_count(source, side))) for side in ARMS}
    x = _search(source, target, zero['right'], zero['left'], False,
                ScoreWeights(palm=REST_PALM_WEIGHT), 'rest', rng,
                {'right': None, 'left': None})[0]
    return {side: forward_kinematics(target, q, side).palm
            for side, q in zip(ARMS, split_arms(target, x[0]))}


def _search(source, target, qr, ql, two_handed, weights, name, rng, rest, own=False):
    """
    Return (x (K, J), scorer, checker) of the keyframes (qr, ql) of ``source``.

    Each keyframe starts from the one before (the first from the zero pose, or with
    ``own`` from the source's angles, clipped: arms of one design often share them).
    """
    ref_r = scaled_landmarks(source, target, 'right', qr, rest['right'])
    ref_l = scaled_landmarks(source, target, 'left', ql, rest['left'])
    zeros = {side: np.zeros(arm_joint_count(target, side)) for side in ARMS}
    targets = [Target(zeros['right'], zeros['left'], ARMS, two_handed, f'{name}[{k}]',
                      weights) for k in range(len(qr))]
    scorer = SimilarityScore(target, targets, reference_landmarks=(ref_r, ref_l))
    checker = CollisionModel(target, targets, target.capsules)
    _designed_allowance(checker, targets, ref_r, ref_l)
    low = np.concatenate([target.arms[s].lower for s in ARMS])
    high = np.concatenate([target.arms[s].upper for s in ARMS])
    out, prev = [], None
    for k in range(len(qr)):
        if own:
            first = np.concatenate((qr[k], ql[k]))
        else:
            first = np.zeros(len(target.joint_names)) if prev is None else prev
        start = np.clip(first, low, high)
        prev = _solve_keyframe(target, scorer, checker, k, start, prev,
                               int(rng.integers(2 ** 63)))
        out.append(prev)
    return np.array(out), scorer, checker


def retarget_gesture(source, target, gesture, rng, rest=None):
    """
    Return the :class:`RetargetedGesture` of one gesture of ``source`` on ``target``.

    ``rest`` is :func:`rest_palms` (computed here if None; pass it for a library).
    """
    rest = rest if rest is not None else rest_palms(source, target, rng)
    qr = np.array([kf.right for kf in gesture.keyframes])
    ql = np.array([kf.left for kf in gesture.keyframes])
    ids = np.arange(len(qr))
    best = None
    same = (qr.shape[1], ql.shape[1]) == tuple(arm_joint_count(target, s) for s in ARMS)
    for k in range(RESTARTS):       # the colony's luck: keep the best of a few searches
        x, scorer, checker = _search(source, target, qr, ql, gesture.two_handed,
                                     gesture.weights, gesture.name, rng, rest,
                                     own=same and k % 2 == 1)
        right, left = split_arms(target, x)
        lm_r = forward_kinematics(target, right, 'right')
        lm_l = forward_kinematics(target, left, 'left')
        scores = np.asarray(scorer.evaluate(lm_r, lm_l, ids))
        hits = checker.collides(lm_r, lm_l, ids)
        key = (int(hits.sum()), float(scores.sum()))
        if best is None or key < best[0]:
            best = (key, RetargetedGesture(gesture.name, right, left, scores, hits))
    return best[1]
