"""
The gesture-similarity score (paper eqs. 1 and 2), batched; lower is better.

For each arm that takes part in a gesture the components are the distances (mm) of the
candidate elbow, wrist and fingertip from the reference ones, and the palm rotation
angle (degrees) between them.  Per-arm components are summed over the arms, so the scale
stays comparable when both arms move.  Two-handed gestures add the change in the
left-right wrist and fingertip distances, ``|d_LR - d_LR_ref|`` [reading: d_offset is the
reference pose's own distance, so the reference scores exactly 0].
"""

from collections.abc import Iterable
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ..model.gestures import Gesture
from ..model.kinematics import (arm_joint_count, ArmLandmarks, as_joint_array, batch_forward,
                                batch_forward_jacobian, forward_kinematics, take_landmarks)
from ..model.robot import RobotModel
from ..model.weights import ARM_COMPONENTS, COMPONENTS, ScoreWeights

_FROB_TO_ANGLE = 1.0 / (2.0 * math.sqrt(2.0))


class Target(NamedTuple):
    """One reference pose to be matched: both arms' angles (rad) and how it is scored."""

    q_right: np.ndarray
    q_left: np.ndarray
    arms: tuple
    two_handed: bool
    label: str = ''
    weights: ScoreWeights | None = None   # this target's gesture's own; None: the scorer's


def gesture_targets(gesture: Gesture, indices: Iterable[int] | None = None) -> list[Target]:
    """One Target per keyframe of ``gesture`` (or per keyframe index in ``indices``)."""
    indices = range(len(gesture.keyframes)) if indices is None else indices
    return [Target(gesture.keyframes[i].right, gesture.keyframes[i].left, gesture.arms,
                   gesture.two_handed, f'{gesture.name}[{i}]', gesture.weights)
            for i in indices]


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

    def __init__(self, robot: RobotModel, targets: Iterable[Target],
                 weights: ScoreWeights | None = None,
                 reference_robot: RobotModel | None = None,
                 reference_landmarks: tuple | None = None) -> None:
        targets = list(targets)
        if not targets:
            raise ValueError('SimilarityScore: expected at least one target, got none')
        self.robot = robot
        self._n = {side: arm_joint_count(robot, side) for side in ('right', 'left')}
        self.targets = targets
        self.weights = weights if weights is not None else ScoreWeights()
        qr = np.array([t.q_right for t in targets])
        ql = np.array([t.q_left for t in targets])
        # After a structure change (a tool) the candidates move on the changed robot but
        # the references stay those of the designed motion on the original one.
        # Retargeting (another robot's gesture, scaled) gives the references as landmarks
        # (right, left), one per target, instead of angles.
        reference_robot = reference_robot if reference_robot is not None else robot
        if reference_landmarks is not None:
            self._ref_r, self._ref_l = reference_landmarks
        else:
            self._ref_r = forward_kinematics(reference_robot, qr, 'right')
            self._ref_l = forward_kinematics(reference_robot, ql, 'left')
        self._arm_mask = np.array([[('right' in t.arms), ('left' in t.arms)] for t in targets],
                                  dtype=float)
        self._two = np.array([t.two_handed for t in targets], dtype=bool)
        self._ref_wlr = np.linalg.norm(self._ref_r.wrist - self._ref_l.wrist, axis=-1)
        self._ref_tlr = np.linalg.norm(self._ref_r.tip - self._ref_l.tip, axis=-1)
        self._w = np.array([self.target_weights(k).vector(t.two_handed)
                            for k, t in enumerate(targets)])
        self._ref_stack = {
            side: (np.stack((lm.elbow, lm.wrist, lm.tip), axis=1), lm.palm)
            for side, lm in (('right', self._ref_r), ('left', self._ref_l))}
        self._uses_left = bool(np.any(self._arm_mask[:, 1]) or np.any(self._two))

    def target_weights(self, target: int) -> ScoreWeights:
        """Return the ScoreWeights of one target: its gesture's own, else the scorer's."""
        own = self.targets[target].weights
        return own if own is not None else self.weights

    @classmethod
    def for_gesture(cls, robot: RobotModel, gesture: Gesture, keyframe: int = 0,
                    weights: ScoreWeights | None = None) -> 'SimilarityScore':
        """Score against one keyframe of one gesture."""
        return cls(robot, [gesture_targets(gesture)[keyframe]], weights)

    def reference(self, target: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Return the reference angles (right, left) of a target."""
        t = self.targets[target]
        return t.q_right, t.q_left

    def tip_error(self, q_right: np.ndarray, q_left: np.ndarray,
                  target: ArrayLike) -> np.ndarray:
        """
        Return the fingertip distance (mm) from the reference, the worst of the arms used.

        This is how far a pose is from *reaching* its target (the second source paper's
        position error), whatever the other terms of the score say.
        """
        target = np.asarray(target, dtype=int)
        err = np.zeros(len(target))
        for i, (side, ref) in enumerate((('right', self._ref_r), ('left', self._ref_l))):
            q = q_right if side == 'right' else q_left
            d = np.linalg.norm(batch_forward(self.robot, q, side).tip - ref.tip[target], axis=-1)
            err = np.maximum(err, d * self._arm_mask[target, i])
        return err

    def __call__(self, q_right: ArrayLike | ArmLandmarks,
                 q_left: ArrayLike | ArmLandmarks | None = None, target: ArrayLike = 0,
                 breakdown: bool = False) -> np.ndarray | tuple[np.ndarray, dict]:
        """
        Score candidates; return totals (N,) and, with ``breakdown``, the components.

        ``q_right`` and ``q_left`` have shape (N, n) or (n,) (broadcast), n joints per
        arm; ``q_left=None`` uses each target's reference left arm.  Instead of angles,
        an arm that does not move may be given as per-target ArmLandmarks (leading shape
        (n_targets,)), which saves its forward kinematics.  ``target`` is an int or an
        (N,) array of target indices.  The breakdown is a dict of (N,) arrays keyed by
        COMPONENTS, plus the per-arm parts under ``'right'`` and ``'left'`` as (N, 4) arrays.
        """
        target = np.asarray(target, dtype=int)
        if target.ndim > 1 or np.any(target < 0) or np.any(target >= len(self.targets)):
            raise ValueError(f'target: expected indices in 0..{len(self.targets) - 1}, '
                             f'got {target!r}')
        if not isinstance(q_right, ArmLandmarks):
            q_right = np.atleast_2d(as_joint_array(q_right, 'q_right', self._n['right']))
        if q_left is not None and not isinstance(q_left, ArmLandmarks):
            q_left = np.atleast_2d(as_joint_array(q_left, 'q_left', self._n['left']))
        rows = [target.size]
        for q in (q_right, q_left):
            if q is not None and not isinstance(q, ArmLandmarks):
                rows.append(q.shape[0])
        n = max(rows)
        target = np.broadcast_to(target, (n,))
        if isinstance(q_right, ArmLandmarks):
            q_right = take_landmarks(q_right, target)
        else:
            q_right = np.broadcast_to(q_right, (n, q_right.shape[-1]))
        if isinstance(q_left, ArmLandmarks):
            q_left = take_landmarks(q_left, target)
        elif q_left is not None:
            q_left = np.broadcast_to(q_left, (n, q_left.shape[-1]))
        return self.evaluate(q_right, q_left, target, breakdown)

    def evaluate(self, q_right: np.ndarray | ArmLandmarks,
                 q_left: np.ndarray | ArmLandmarks | None, target: np.ndarray,
                 breakdown: bool = False) -> np.ndarray | tuple[np.ndarray, dict]:
        """
        Score without input checks: the hot path of the optimisers.

        ``q_right``/``q_left`` are (N, n) angle arrays, or ArmLandmarks already computed
        for each of the N rows, or None for the left arm's reference; ``target`` is an
        (N,) index array.
        """
        n = target.shape[0]
        lm_r = (q_right if isinstance(q_right, ArmLandmarks)
                else batch_forward(self.robot, q_right, 'right'))
        comps = np.zeros((n, len(COMPONENTS)))
        right = self._arm_terms(lm_r, 'right', target)
        comps[:, :ARM_COMPONENTS] += right * self._arm_mask[target, 0:1]
        left = np.zeros_like(right)
        if self._uses_left:
            if q_left is None:
                lm_l = take_landmarks(self._ref_l, target)
            elif isinstance(q_left, ArmLandmarks):
                lm_l = q_left
            else:
                lm_l = batch_forward(self.robot, q_left, 'left')
            left = self._arm_terms(lm_l, 'left', target)
            comps[:, :ARM_COMPONENTS] += left * self._arm_mask[target, 1:2]
            two = self._two[target]
            if np.any(two):
                dw = lm_r.wrist - lm_l.wrist
                dt = lm_r.tip - lm_l.tip
                wlr = np.sqrt(np.einsum('ni,ni->n', dw, dw))
                tlr = np.sqrt(np.einsum('ni,ni->n', dt, dt))
                comps[:, 4] = np.where(two, np.abs(wlr - self._ref_wlr[target]), 0.0)
                comps[:, 5] = np.where(two, np.abs(tlr - self._ref_tlr[target]), 0.0)
        total = np.einsum('nc,nc->n', comps, self._w[target])
        if not breakdown:
            return total
        parts = {c: comps[:, i] for i, c in enumerate(COMPONENTS)}
        parts['right'] = right
        parts['left'] = left
        return total, parts

    def value_and_grad(self, q_right, q_left, target: np.ndarray,
                       smooth: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Return totals (N,) and their gradients (N, n) with respect to each arm's angles.

        Arguments as for :meth:`evaluate`, and an arm may also be given as a pair
        ``(ArmLandmarks, ArmJacobian)`` computed by the caller; an arm given as landmarks
        alone (or None) does not move and gets a zero gradient.  Where a distance is
        exactly zero its derivative is taken as 0 (a subgradient).  With ``smooth`` =
        eps > 0 every distance, angle and left-right gap |t| is replaced by
        sqrt(t^2 + eps^2) - eps, which removes the kinks at zero (each term moves by
        less than eps) so that quasi-Newton polishing converges quickly.
        """
        n = target.shape[0]
        lms, jacs = self._landmarks_and_jacobians(q_right, q_left, target)
        w = self._w[target]
        total = np.zeros(n)
        grads = {side: np.zeros((n, self._n[side])) for side in ('right', 'left')}
        for k, side in enumerate(('right', 'left')):
            if k == 1 and not self._uses_left:
                break
            mask = self._arm_mask[target, k]
            terms, d_terms = self._arm_terms_grad(lms[side], side, target, jacs.get(side))
            if smooth:
                soft = np.sqrt(terms ** 2 + smooth ** 2)
                if d_terms is not None:
                    d_terms = d_terms * (terms / soft)[..., None]
                terms = soft - smooth
            total += mask * np.einsum('nc,nc->n', terms, w[:, :ARM_COMPONENTS])
            if d_terms is not None:
                grads[side] += (mask[:, None]
                                * np.einsum('nc,nci->ni', w[:, :ARM_COMPONENTS], d_terms))
        two = self._two[target]
        if self._uses_left and np.any(two):
            for c, gap, d_dist in self._gap_terms(lms, jacs, target):
                if smooth:
                    soft = np.sqrt(gap ** 2 + smooth ** 2)
                    value, slope = soft - smooth, gap / soft
                else:
                    value, slope = np.abs(gap), np.sign(gap)
                total += np.where(two, w[:, c] * value, 0.0)
                coef = np.where(two, w[:, c] * slope, 0.0)[:, None]
                for side, d in d_dist.items():
                    grads[side] += coef * d
        return total, grads['right'], grads['left']

    def residuals(self, lms: dict, jacs: dict, target: np.ndarray) -> list:
        """
        Return the score's terms as residual vectors: ``[(r (N, m), {side: J}, w (N,))]``.

        The score is ``sum w |r|`` over these blocks (each arm's elbow, wrist and
        fingertip offsets in mm and its palm rotation vector in deg, ``sin`` of the
        angle about its axis; a two-handed gesture's left-right gaps), which is what
        a least-squares method needs.  ``lms`` maps both arms to their landmarks (N
        rows), ``jacs`` the arms that move to their :class:`ArmJacobian`; ``J`` (N, m,
        n) is the block's Jacobian with respect to that arm's angles.
        """
        w = self._w[target]
        blocks = []
        for k, side in enumerate(('right', 'left')):
            mask = self._arm_mask[target, k]
            ref_pos, ref_rot = self._ref_stack[side]
            lm, jac = lms[side], jacs.get(side)
            pts = np.stack((lm.elbow, lm.wrist, lm.tip), axis=1) - ref_pos[target]
            for c in range(3):
                blocks.append((pts[:, c], {} if jac is None else
                               {side: np.swapaxes(jac.positions[:, c], 1, 2)}, w[:, c] * mask))
            a = lm.palm @ np.swapaxes(ref_rot[target], -1, -2)
            vec = 0.5 * np.stack((a[:, 2, 1] - a[:, 1, 2], a[:, 0, 2] - a[:, 2, 0],
                                  a[:, 1, 0] - a[:, 0, 1]), axis=-1)
            d_vec = {}
            if jac is not None:   # d vee(skew(R Rr^T)) / dq_i = (tr(A) I - A) z_i / 2
                m = 0.5 * (np.trace(a, axis1=1, axis2=2)[:, None, None] * np.eye(3) - a)
                d_vec[side] = np.degrees(np.einsum('nij,nkj->nik', m, jac.axes))
            blocks.append((np.degrees(vec), d_vec, w[:, 3] * mask))
        two = self._two[target]
        if self._uses_left and np.any(two):
            for c, gap, d_dist in self._gap_terms(lms, jacs, target):
                blocks.append((gap[:, None], {side: d[:, None, :] for side, d in d_dist.items()},
                               np.where(two, w[:, c], 0.0)))
        return blocks

    def _gap_terms(self, lms, jacs, target):
        """
        Yield a two-handed gesture's left-right gaps: ``(component, gap, {side: dgap})``.

        ``gap`` (N,) is the distance between the hands' wrists (then fingertips) less the
        reference's; ``dgap`` (N, n) its gradient with respect to each moving arm's
        angles (0 where the distance is exactly 0: a subgradient).
        """
        for c, row, ref in ((4, 1, self._ref_wlr), (5, 2, self._ref_tlr)):
            attr = ('elbow', 'wrist', 'tip')[row]
            diff = getattr(lms['right'], attr) - getattr(lms['left'], attr)
            dist = np.sqrt(np.einsum('ni,ni->n', diff, diff))
            unit = diff / np.where(dist > 0, dist, 1.0)[:, None]
            yield c, dist - ref[target], {
                side: sign * np.einsum('nc,nic->ni', unit, jacs[side].positions[:, row])
                for side, sign in (('right', 1.0), ('left', -1.0)) if side in jacs}

    def _landmarks_and_jacobians(self, q_right, q_left, target):
        """Return each arm's landmarks, and the Jacobians of the arms that move."""
        lms, jacs = {}, {}
        for side, q in (('right', q_right), ('left', q_left)):
            if q is None:
                lms[side] = take_landmarks(self._ref_l if side == 'left' else self._ref_r, target)
            elif isinstance(q, ArmLandmarks):
                lms[side] = q
            elif isinstance(q, tuple):
                lms[side], jacs[side] = q
            else:
                lms[side], jacs[side] = batch_forward_jacobian(self.robot, q, side)
        return lms, jacs

    def _arm_terms_grad(self, lm, side, target, jac):
        ref_pos, ref_rot = self._ref_stack[side]
        diff = np.stack((lm.elbow, lm.wrist, lm.tip), axis=1) - ref_pos[target]
        dist = np.sqrt(np.einsum('nij,nij->ni', diff, diff))
        rdiff = lm.palm - ref_rot[target]
        frob = np.sqrt(np.einsum('nij,nij->n', rdiff, rdiff))
        half = np.minimum(frob * _FROB_TO_ANGLE, 1.0)
        terms = np.empty((target.shape[0], ARM_COMPONENTS))
        terms[:, :3] = dist
        terms[:, 3] = np.degrees(2.0 * np.arcsin(half))
        if jac is None:
            return terms, None
        d_terms = np.empty((target.shape[0], ARM_COMPONENTS, jac.axes.shape[1]))
        unit = diff / np.where(dist > 0, dist, 1.0)[..., None]
        d_terms[:, :3] = np.einsum('nlc,nlic->nli', unit, jac.positions)
        # d|R - Rr|_F / dq_i = -tr([z_i]x R Rr^T) / |R - Rr|_F = -z_i . v / |R - Rr|_F.
        a = lm.palm @ np.swapaxes(ref_rot[target], -1, -2)
        v = np.stack((a[:, 1, 2] - a[:, 2, 1], a[:, 2, 0] - a[:, 0, 2],
                      a[:, 0, 1] - a[:, 1, 0]), axis=-1)
        d_frob = -np.einsum('nic,nc->ni', jac.axes, v) / np.where(frob > 0, frob, 1.0)[:, None]
        slope = np.degrees(2.0 * _FROB_TO_ANGLE) / np.sqrt(np.maximum(1.0 - half ** 2, 1e-12))
        d_terms[:, 3] = np.where(frob[:, None] > 0, slope[:, None] * d_frob, 0.0)
        return terms, d_terms

    def _arm_terms(self, lm, side, target):
        return self._arm_terms_grad(lm, side, target, None)[0]
