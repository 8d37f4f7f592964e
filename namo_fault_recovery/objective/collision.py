"""
Self-collision of the arms and the torso, modelled as capsules (ROS-free, batched).

Each arm is three capsules, the upper arm (shoulder-elbow), the forearm (elbow-wrist)
and the hand (wrist-fingertip), and the torso is one more; the geometry and the pairs
are :mod:`..model.self_contact`'s, the simulator's too.  Two capsules interpenetrate
when the distance between their axis segments is below the sum of their radii.  A
two-handed gesture's reference pose defines designed contact: where the reference
itself brings a right-left pair closer than their radii (the Wai palms pressed
together), that reference distance is the allowed minimum instead.  Nothing is
designed to go into the torso, nor into the resting arm of a one-handed gesture:
there the radii are the minimum whatever the reference does (the simulator's rule,
:func:`~namo_fault_recovery.sim.physics.designed_allowances`; such a reference is
refused or warned about when the library is loaded).  The penalty ``weight *
sum(max(0, allowed - d)^2)`` (mm^2) is smooth, and its gradient comes from the landmark
Jacobians.
"""

import copy

import numpy as np

from ..model.capsules import CapsuleModel
from ..model.kinematics import arm_joint_count, forward_kinematics, shoulder_position
from ..model.self_contact import (arm_segments, closest_pairs, designed_pairs, pair_ends,
                                  PAIR_NAMES, PAIRS, radius_sums, segment_distance,
                                  SEGMENTS, TOLERANCE_MM)

__all__ = ['CollisionModel', 'SEGMENTS', 'segment_distance']


class CollisionModel:
    """
    Capsule collision checks and penalty for a set of scoring targets.

    Built once per set of targets: the allowed distances of each pair come from the
    targets' reference poses (designed contact).
    """

    def __init__(self, robot, targets, capsules=None):
        self.robot = robot
        self.capsules = capsules if capsules is not None else CapsuleModel()
        self.field_penalty = False      # the torso's shape in the penalty: see shaped()
        self.shoulder = {side: shoulder_position(robot, side) for side in ('right', 'left')}
        self.torso = (np.array(self.capsules.torso_top, dtype=float),
                      np.array(self.capsules.torso_bottom, dtype=float))
        self.radius_sum = radius_sums(self.capsules)
        qr = np.array([t.q_right for t in targets]).reshape(-1, arm_joint_count(robot, 'right'))
        ql = np.array([t.q_left for t in targets]).reshape(-1, arm_joint_count(robot, 'left'))
        ref = self.distances(forward_kinematics(robot, qr, 'right'),
                             forward_kinematics(robot, ql, 'left'))[0]
        designed = np.array([designed_pairs(t.two_handed) for t in targets],
                            dtype=bool).reshape(-1, len(PAIRS))
        self.allowed = np.where(designed, np.minimum(self.radius_sum[None, :], ref),
                                self.radius_sum[None, :])              # (T, pairs)

    def _segments(self, lm, side):
        """Return segment end points (N, 3 segments, 2, 3)."""
        return arm_segments(self.robot, lm, side)

    def distances(self, lm_right, lm_left):
        """Return the axis distance of every pair, (N, pairs), with closest-point parameters."""
        return self.closest(lm_right, lm_left)[:3]

    def closest(self, lm_right, lm_left, field=True):
        """Return ``(d, s, t, normal)`` (:func:`~..model.self_contact.closest_pairs`)."""
        return closest_pairs(self.capsules, self._ends(lm_right, lm_left), field)

    def shaped(self):
        """
        Return this model with the torso's shape in its penalty too (it is in every check).

        The shape (:mod:`..model.torso_field`) costs a quarter more time in the search's
        every evaluation; the searches run on the capsules, and the repair of the poses
        that the checks find touching (the shape included), and the search that moves
        an idle arm clear, on this one.
        """
        if self.capsules.torso_field is None:
            return self
        model = copy.copy(self)
        model.field_penalty = True
        return model

    def penetration(self, lm_right, lm_left, target):
        """Return how far (mm) each pair is inside its allowed distance, (N, pairs) >= 0."""
        d = self.distances(lm_right, lm_left)[0]
        return np.maximum(self.allowed[target] - d, 0.0)

    def collides(self, lm_right, lm_left, target):
        """Return a bool (N,) per pose: some pair penetrates by more than 1 mm."""
        return self.verdicts(lm_right, lm_left, target)[0]

    def shape_hits(self, lm_right, lm_left, target):
        """Return a bool (N,) per pose: an arm is in the torso's shape (not its capsule)."""
        return self.verdicts(lm_right, lm_left, target)[1]

    def verdicts(self, lm_right, lm_left, target):
        """Return :meth:`collides` and :meth:`shape_hits` of the poses, from one check."""
        d, _, _, normal = self.closest(lm_right, lm_left)
        deep = np.maximum(self.allowed[target] - d, 0.0) > TOLERANCE_MM
        if normal is None:
            return np.any(deep, axis=1), np.zeros(d.shape[0], dtype=bool)
        return np.any(deep, axis=1), np.any(deep & np.any(normal != 0.0, axis=-1), axis=1)

    def colliding_pairs(self, lm_right, lm_left, target):
        """Return, per pose, the names of the pairs that penetrate."""
        pen = self.penetration(lm_right, lm_left, target) > TOLERANCE_MM
        return [[PAIR_NAMES[p] for p in np.nonzero(row)[0]] for row in pen]

    def penalty(self, lm_right, lm_left, target, jac_right=None, jac_left=None):
        """
        Return the penalty per pose, and its gradient for arms given with a Jacobian.

        The closest-point parameters are stationary, so the derivative of a distance is
        the relative velocity of the two closest points along their separation
        (:meth:`clearance` gives those derivatives pair by pair).
        """
        ends = self._ends(lm_right, lm_left)
        closest = closest_pairs(self.capsules, ends, self.field_penalty)
        gap = np.maximum(self.allowed[target] - closest[0], 0.0)
        value = self.capsules.weight * np.sum(gap ** 2, axis=1)
        grads = {}
        active = np.nonzero(np.any(gap > 0, axis=0))[0]
        for side, jac in (('right', jac_right), ('left', jac_left)):
            if jac is not None and not active.size:
                grads[side] = np.zeros((gap.shape[0], jac.axes.shape[1]))
            elif jac is not None:
                rates = self._rates(ends, closest, side, jac, active)      # (N, A, n)
                grads[side] = np.einsum('na,nai->ni', -2.0 * self.capsules.weight
                                        * gap[:, active], rates)
        return value, grads

    def clearance(self, lm_right, lm_left, target, jac_right=None,
                  jac_left=None) -> tuple:
        """
        Return how far (mm) each pair is outside its allowed distance, and its derivatives.

        ``margin`` (N, pairs) is the axis distance less the allowed one (negative: the
        pair penetrates); ``rates`` maps each arm given with a Jacobian to (N, pairs, n),
        d(margin)/dq.  The constraints of a constrained local solve
        (:mod:`..recovery.constrained`), with the torso's shape as :meth:`penalty` has it.
        """
        ends = self._ends(lm_right, lm_left)
        closest = closest_pairs(self.capsules, ends, self.field_penalty)
        every = np.arange(len(PAIRS))
        rates = {side: self._rates(ends, closest, side, jac, every)
                 for side, jac in (('right', jac_right), ('left', jac_left)) if jac is not None}
        return closest[0] - self.allowed[target], rates

    def _ends(self, lm_right, lm_left):
        """Return every pair's segment ends (:func:`~..model.self_contact.pair_ends`)."""
        return pair_ends(self.capsules, {'right': self._segments(lm_right, 'right'),
                                         'left': self._segments(lm_left, 'left')})

    def _rates(self, ends, closest, side, jac, pairs):
        """
        Return d(distance)/dq (N, len(pairs), n) of ``pairs`` for the joints of ``side``.

        ``closest`` is :func:`closest_pairs`' answer for ``ends``; a pair not involving
        ``side`` moves at rate 0.  All pairs at once: the closest points, their unit
        separation (the torso's shape's normal where it decides), and the velocity of
        ``side``'s closest point, interpolated between its segment's end velocities.
        """
        d, s, t, normal = closest
        pairs = np.asarray(pairs, dtype=int)
        p1, q1, p2, q2 = (e[:, pairs] for e in ends)
        sp, tp = s[:, pairs], t[:, pairs]
        unit = ((p1 + sp[..., None] * (q1 - p1)) - (p2 + tp[..., None] * (q2 - p2))) \
            / np.maximum(d[:, pairs], 1e-9)[..., None]
        if normal is not None:      # the torso's shape is nearer: its distance's gradient
            shaped = np.any(normal[:, pairs] != 0.0, axis=-1)
            unit = np.where(shaped[..., None], normal[:, pairs], unit)
        first = _FIRST_SIDE[pairs] == side
        sign = np.where(first, 1.0, np.where(_SECOND_SIDE[pairs] == side, -1.0, 0.0))
        idx = np.where(first, _FIRST_SEGMENT[pairs], _SECOND_SEGMENT[pairs])
        frac = np.where(first, sp, tp)                                    # (N, A)
        # d(endpoint)/dq for the segment ends: shoulder (fixed), elbow, wrist, tip.
        zeros = np.zeros_like(jac.positions[:, 0])
        ends = np.stack((zeros, jac.positions[:, 0], jac.positions[:, 1],
                         jac.positions[:, 2]), axis=1)                    # (N, 4, n, 3)
        vel = ((1 - frac)[..., None, None] * ends[:, idx]
               + frac[..., None, None] * ends[:, idx + 1])              # (N, A, n, 3)
        return sign[None, :, None] * np.einsum('nac,naic->nai', unit, vel)


# Per pair of PAIRS: each segment's arm and index (the torso's 0, never moved by an arm).
_FIRST_SIDE = np.array([a for a, _, _, _ in PAIRS])
_SECOND_SIDE = np.array([b for _, _, b, _ in PAIRS])
_FIRST_SEGMENT = np.array([i for _, i, _, _ in PAIRS])
_SECOND_SEGMENT = np.array([k for _, _, _, k in PAIRS])
