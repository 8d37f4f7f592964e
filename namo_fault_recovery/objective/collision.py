"""
Self-collision of the arms and the torso, modelled as capsules (ROS-free, batched).

Each arm is three capsules, the upper arm (shoulder-elbow), the forearm (elbow-wrist)
and the hand (wrist-fingertip), and the torso is one more.  Two capsules interpenetrate
when the distance between their axis segments is below the sum of their radii.  A
gesture's reference pose defines designed contact: where the reference itself brings
two capsules closer than their radii (the Wai palms pressed together), that reference
distance is the allowed minimum instead.  The penalty ``weight * sum(max(0, allowed -
d)^2)`` (mm^2) is smooth, and its gradient comes from the landmark Jacobians.
"""

import numpy as np

from ..model.capsules import CapsuleModel
from ..model.kinematics import forward_kinematics, shoulder_position

SEGMENTS = ('upper_arm', 'forearm', 'hand')
# Pairs checked: each arm segment against the torso, and every right-left segment pair.
_PAIRS = ([('right', i, 'torso', 0) for i in range(3)]
          + [('left', i, 'torso', 0) for i in range(3)]
          + [('right', i, 'left', k) for i in range(3) for k in range(3)])
_TOL = 1.0   # mm of penetration tolerated by the final check (numerical slack)


def segment_distance(p1, q1, p2, q2):
    """
    Closest distance between segments [p1, q1] and [p2, q2], batched over leading axes.

    Returns ``(distance, s, t)`` with the closest points ``p1 + s (q1 - p1)`` and
    ``p2 + t (q2 - p2)`` (Ericson, Real-Time Collision Detection, 5.1.9).
    """
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum('...i,...i->...', d1, d1)
    e = np.einsum('...i,...i->...', d2, d2)
    f = np.einsum('...i,...i->...', d2, r)
    c = np.einsum('...i,...i->...', d1, r)
    b = np.einsum('...i,...i->...', d1, d2)
    denom = a * e - b * b
    eps = 1e-12
    safe_a = np.where(a > eps, a, 1.0)
    safe_e = np.where(e > eps, e, 1.0)
    s = np.where(denom > eps * np.maximum(a * e, eps),
                 np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
    s = np.where(a > eps, s, 0.0)
    t = (b * s + f) / safe_e
    # t outside [0, 1]: clamp it and recompute s for the clamped t.
    s = np.where(t < 0.0, np.clip(-c / safe_a, 0.0, 1.0), s)
    s = np.where(t > 1.0, np.clip((b - c) / safe_a, 0.0, 1.0), s)
    s = np.where(a > eps, s, 0.0)
    t = np.clip(t, 0.0, 1.0)
    t = np.where(e > eps, t, 0.0)
    diff = (p1 + s[..., None] * d1) - (p2 + t[..., None] * d2)
    return np.sqrt(np.einsum('...i,...i->...', diff, diff)), s, t


class CollisionModel:
    """
    Capsule collision checks and penalty for a set of scoring targets.

    Built once per set of targets: the allowed distances of each pair come from the
    targets' reference poses (designed contact).
    """

    def __init__(self, robot, targets, capsules=None):
        self.robot = robot
        self.capsules = capsules if capsules is not None else CapsuleModel()
        self.shoulder = {side: shoulder_position(robot, side) for side in ('right', 'left')}
        self.torso = (np.array(self.capsules.torso_top, dtype=float),
                      np.array(self.capsules.torso_bottom, dtype=float))
        radii = self.capsules.radii
        self.radius_sum = np.array([
            radii[i] + (self.capsules.torso_radius if other == 'torso' else radii[k])
            for _, i, other, k in _PAIRS])
        qr = np.array([t.q_right for t in targets])
        ql = np.array([t.q_left for t in targets])
        ref = self.distances(forward_kinematics(robot, qr, 'right'),
                             forward_kinematics(robot, ql, 'left'))[0]
        self.allowed = np.minimum(self.radius_sum[None, :], ref)   # (T, pairs)

    def _segments(self, lm, side):
        """Return segment end points (N, 3 segments, 2, 3)."""
        shoulder = np.broadcast_to(self.shoulder[side], lm.elbow.shape)
        return np.stack((np.stack((shoulder, lm.elbow), axis=1),
                         np.stack((lm.elbow, lm.wrist), axis=1),
                         np.stack((lm.wrist, lm.tip), axis=1)), axis=1)

    def distances(self, lm_right, lm_left):
        """Return the axis distance of every pair, (N, pairs), with closest-point parameters."""
        seg = {'right': self._segments(lm_right, 'right'),
               'left': self._segments(lm_left, 'left')}
        n = seg['right'].shape[0]
        torso = np.broadcast_to(np.stack(self.torso)[None, None], (n, 1, 2, 3))
        seg['torso'] = torso
        p1 = np.stack([seg[a][:, i, 0] for a, i, _, _ in _PAIRS], axis=1)
        q1 = np.stack([seg[a][:, i, 1] for a, i, _, _ in _PAIRS], axis=1)
        p2 = np.stack([seg[b][:, k, 0] for _, _, b, k in _PAIRS], axis=1)
        q2 = np.stack([seg[b][:, k, 1] for _, _, b, k in _PAIRS], axis=1)
        return segment_distance(p1, q1, p2, q2)

    def penetration(self, lm_right, lm_left, target):
        """Return how far (mm) each pair is inside its allowed distance, (N, pairs) >= 0."""
        d = self.distances(lm_right, lm_left)[0]
        return np.maximum(self.allowed[target] - d, 0.0)

    def collides(self, lm_right, lm_left, target):
        """Return a bool (N,) per pose: some pair penetrates by more than 1 mm."""
        return np.any(self.penetration(lm_right, lm_left, target) > _TOL, axis=1)

    def colliding_pairs(self, lm_right, lm_left, target):
        """Return, per pose, the names of the pairs that penetrate."""
        pen = self.penetration(lm_right, lm_left, target) > _TOL
        names = [f'{a}_{SEGMENTS[i]}-{b}' + ('' if b == 'torso' else f'_{SEGMENTS[k]}')
                 for a, i, b, k in _PAIRS]
        return [[names[p] for p in np.nonzero(row)[0]] for row in pen]

    def penalty(self, lm_right, lm_left, target, jac_right=None, jac_left=None):
        """
        Return the penalty per pose, and its gradient for arms given with a Jacobian.

        The closest-point parameters are stationary, so the derivative of a distance is
        the relative velocity of the two closest points along their separation.
        """
        d, s, t = self.distances(lm_right, lm_left)
        gap = np.maximum(self.allowed[target] - d, 0.0)
        value = self.capsules.weight * np.sum(gap ** 2, axis=1)
        grads = {}
        if jac_right is None and jac_left is None:
            return value, grads
        seg = {'right': self._segments(lm_right, 'right'),
               'left': self._segments(lm_left, 'left')}
        for side, jac in (('right', jac_right), ('left', jac_left)):
            if jac is None:
                continue
            # d(endpoint)/dq for the segment ends: shoulder (fixed), elbow, wrist, tip.
            zeros = np.zeros_like(jac.positions[:, 0])
            ends = np.stack((zeros, jac.positions[:, 0], jac.positions[:, 1],
                             jac.positions[:, 2]), axis=1)                  # (N, 4, 7, 3)
            grad = np.zeros((d.shape[0], 7))
            active = np.nonzero(np.any(gap > 0, axis=0))[0]
            for p in active:
                a, i, b, k = _PAIRS[p]
                if side not in (a, b):
                    continue
                first = seg[a][:, i, 0] + s[:, p, None] * (seg[a][:, i, 1] - seg[a][:, i, 0])
                if b == 'torso':
                    second = self.torso[0] + t[:, p, None] * (self.torso[1] - self.torso[0])
                else:
                    second = (seg[b][:, k, 0]
                              + t[:, p, None] * (seg[b][:, k, 1] - seg[b][:, k, 0]))
                unit = (first - second) / np.maximum(d[:, p], 1e-9)[:, None]
                if side == a:
                    idx, frac, sign = i, s[:, p], 1.0
                else:
                    idx, frac, sign = k, t[:, p], -1.0
                vel = ((1 - frac)[:, None, None] * ends[:, idx]
                       + frac[:, None, None] * ends[:, idx + 1])            # (N, 7, 3)
                dd = sign * np.einsum('nc,nic->ni', unit, vel)
                grad += -2.0 * self.capsules.weight * gap[:, p, None] * dd
            grads[side] = grad
        return value, grads
