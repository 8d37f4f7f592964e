"""
The gesture-similarity score (paper eqs. 1 and 2), batched; lower is better.

For each arm that takes part in a gesture the components are the distances (mm) of the
candidate elbow, wrist and fingertip from the reference ones, and the palm rotation
angle (degrees) between them.  Per-arm components are summed over the arms, so the scale
stays comparable when both arms move.  Two-handed gestures add the change in the
left-right wrist and fingertip distances, ``|d_LR - d_LR_ref|`` [reading: d_offset is the
reference pose's own distance, so the reference scores exactly 0].
"""

from dataclasses import dataclass, fields
import math
from typing import NamedTuple

import numpy as np

from .kinematics import as_joint_array, forward_kinematics

COMPONENTS = ('elbow', 'wrist', 'tip', 'palm', 'wrist_lr', 'tip_lr')
_ARM_COMPONENTS = 4
_FROB_TO_ANGLE = 1.0 / (2.0 * math.sqrt(2.0))


@dataclass(frozen=True)
class ScoreWeights:
    """
    Relative component weights; by default equal and normalised to sum to 1.

    With ``normalise`` the weights of the components a gesture uses are scaled to sum
    to 1: 1/4 each for a one-arm gesture and 1/6 each for a two-handed one (the paper's
    "equal weight values for all components").
    """

    elbow: float = 1.0
    wrist: float = 1.0
    tip: float = 1.0
    palm: float = 1.0
    wrist_lr: float = 1.0
    tip_lr: float = 1.0
    normalise: bool = True

    def __post_init__(self):
        for f in fields(self):
            if f.name == 'normalise':
                continue
            value = getattr(self, f.name)
            if (isinstance(value, bool) or not isinstance(value, (int, float))
                    or not math.isfinite(value) or value < 0):
                raise ValueError(f'score weight {f.name}: expected a finite number >= 0, '
                                 f'got {value!r}')
        if sum(getattr(self, c) for c in COMPONENTS[:_ARM_COMPONENTS]) <= 0:
            raise ValueError('score weights: at least one of elbow, wrist, tip, palm '
                             'must be > 0')

    @classmethod
    def from_mapping(cls, mapping):
        """Build weights from a dict, naming any unknown key."""
        unknown = set(mapping) - set(COMPONENTS) - {'normalise'}
        if unknown:
            raise ValueError(f'score weights: unknown component {sorted(unknown)[0]!r}; '
                             f'expected some of {", ".join(COMPONENTS)}')
        return cls(**mapping)

    def vector(self, two_handed):
        """Return the 6 weights of a gesture (the left-right ones are 0 if one-handed)."""
        w = np.array([getattr(self, c) for c in COMPONENTS], dtype=float)
        if not two_handed:
            w[_ARM_COMPONENTS:] = 0.0
        if self.normalise:
            w /= w.sum()
        return w


class Target(NamedTuple):
    """One reference pose to be matched: both arms' angles (rad) and how it is scored."""

    q_right: np.ndarray
    q_left: np.ndarray
    arms: tuple
    two_handed: bool
    label: str = ''


def gesture_targets(gesture):
    """One Target per keyframe of ``gesture``."""
    return [Target(kf.right, kf.left, gesture.arms, gesture.two_handed,
                   f'{gesture.name}[{i}]') for i, kf in enumerate(gesture.keyframes)]


def rotation_angle_deg(r_a, r_b):
    """
    Angle (deg) of the rotation between ``r_a`` and ``r_b``, i.e. of r_a^T r_b.

    Uses ||A - B||_F = 2 sqrt(2) sin(angle / 2), which stays accurate near zero, where
    the usual acos of the trace loses half its digits.
    """
    frob = np.sqrt(np.sum((r_a - r_b) ** 2, axis=(-2, -1)))
    return np.degrees(2.0 * np.arcsin(np.minimum(frob * _FROB_TO_ANGLE, 1.0)))


class SimilarityScore:
    """
    Batched score of candidate poses against one or more reference targets.

    Build it once per set of targets (reference landmarks are computed here), then call
    it with candidate angles.  Row ``k`` of the batch is scored against target
    ``target[k]``, so the poses of a whole library can be scored in one call.
    """

    def __init__(self, robot, targets, weights=None):
        targets = list(targets)
        if not targets:
            raise ValueError('SimilarityScore: expected at least one target, got none')
        self.robot = robot
        self.targets = targets
        self.weights = weights if weights is not None else ScoreWeights()
        qr = np.array([t.q_right for t in targets])
        ql = np.array([t.q_left for t in targets])
        self._ref_r = forward_kinematics(robot, qr, 'right')
        self._ref_l = forward_kinematics(robot, ql, 'left')
        self._arm_mask = np.array([[('right' in t.arms), ('left' in t.arms)] for t in targets],
                                  dtype=float)
        self._two = np.array([t.two_handed for t in targets], dtype=bool)
        self._ref_wlr = np.linalg.norm(self._ref_r.wrist - self._ref_l.wrist, axis=-1)
        self._ref_tlr = np.linalg.norm(self._ref_r.tip - self._ref_l.tip, axis=-1)
        self._w = np.array([self.weights.vector(t.two_handed) for t in targets])
        self._uses_left = bool(np.any(self._arm_mask[:, 1]) or np.any(self._two))

    @classmethod
    def for_gesture(cls, robot, gesture, keyframe=0, weights=None):
        """Score against one keyframe of one gesture."""
        return cls(robot, [gesture_targets(gesture)[keyframe]], weights)

    def reference(self, target=0):
        """Return the reference angles (right, left) of a target."""
        t = self.targets[target]
        return t.q_right, t.q_left

    def __call__(self, q_right, q_left=None, target=0, breakdown=False):
        """
        Score candidates; return totals (N,) and, with ``breakdown``, the components.

        ``q_right`` and ``q_left`` have shape (N, 7) or (7,) (broadcast); ``q_left=None``
        uses each target's reference left arm.  ``target`` is an int or an (N,) array of
        target indices.  The breakdown is a dict of (N,) arrays keyed by COMPONENTS, plus
        the per-arm parts under ``'right'`` and ``'left'`` as (N, 4) arrays.
        """
        q_right = np.atleast_2d(as_joint_array(q_right, 'q_right'))
        target = np.asarray(target, dtype=int)
        n = max(q_right.shape[0], target.size)
        target = np.broadcast_to(target, (n,))
        lm_r = forward_kinematics(self.robot, q_right, 'right')
        comps = np.zeros((n, len(COMPONENTS)))
        right = self._arm_terms(lm_r, self._ref_r, target)
        comps[:, :_ARM_COMPONENTS] += right * self._arm_mask[target, 0:1]
        left = np.zeros_like(right)
        if self._uses_left:
            if q_left is None:
                lm_l = _take(self._ref_l, target)
            else:
                q_left = np.atleast_2d(as_joint_array(q_left, 'q_left'))
                lm_l = forward_kinematics(self.robot, q_left, 'left')
            left = self._arm_terms(lm_l, self._ref_l, target)
            comps[:, :_ARM_COMPONENTS] += left * self._arm_mask[target, 1:2]
            two = self._two[target]
            if np.any(two):
                wlr = np.linalg.norm(lm_r.wrist - lm_l.wrist, axis=-1)
                tlr = np.linalg.norm(lm_r.tip - lm_l.tip, axis=-1)
                comps[:, 4] = np.where(two, np.abs(wlr - self._ref_wlr[target]), 0.0)
                comps[:, 5] = np.where(two, np.abs(tlr - self._ref_tlr[target]), 0.0)
        total = np.einsum('nc,nc->n', comps, self._w[target])
        if not breakdown:
            return total
        parts = {c: comps[:, i] for i, c in enumerate(COMPONENTS)}
        parts['right'] = right
        parts['left'] = left
        return total, parts

    @staticmethod
    def _arm_terms(lm, ref, target):
        out = np.empty((np.broadcast_shapes(lm.elbow.shape[:1], target.shape)[0], 4))
        out[:, 0] = np.linalg.norm(lm.elbow - ref.elbow[target], axis=-1)
        out[:, 1] = np.linalg.norm(lm.wrist - ref.wrist[target], axis=-1)
        out[:, 2] = np.linalg.norm(lm.tip - ref.tip[target], axis=-1)
        out[:, 3] = rotation_angle_deg(lm.palm, ref.palm[target])
        return out


def _take(lm, index):
    return type(lm)(*(a[index] for a in lm))
