"""
Self-contact of the capsules (arms and torso), and the load-time check of a library.

The geometry that the optimiser's penalty (:mod:`..objective.collision`) and the
simulator (:mod:`..sim.physics`, MuJoCo capsules built from :mod:`.urdf`) both use:
each arm is three capsules, the upper arm (shoulder-elbow), the forearm (elbow-wrist)
and the hand (wrist-fingertip), and the torso is one more (``robot.capsules``).  Two
capsules interpenetrate when the distance between their axis segments is below the
sum of their radii.  The checked pairs are each arm segment against the torso and
every right-left segment pair; adjacent links never touch by construction.

*Designed contact* is the hands of a two-handed gesture meeting (the Wai palms pressed
together: a capsule is a round stand-in for a flat palm, so pressed palms overlap):
only the right-left pairs of a two-handed gesture.  Nothing is designed to go into
the torso, and the resting arm of a one-handed gesture is not to be touched.

A reference keyframe that brings an undesigned pair closer than its radii is a pose
the robot's own body blocks: the simulated (or real) torso stops the arm short, and
the player reports a stuck joint where there is none.  :func:`check_library` reports
it when a library is loaded, deepest first:

- deeper than :data:`REFUSE_MM` (5 mm): a library error, the library is refused.  5 mm
  is where a blocked hand capsule, whose shortest lever is the 130 mm hand, is held
  more than 2 deg (the player's stuck-joint threshold) away from its command: the
  play would end in a false alarm.  The demo circle's first design went 124 mm deep;
- from the 1 mm tolerance (:data:`TOLERANCE_MM`, the objective's and the simulator's
  numerical slack) to 5 mm: a warning.  A graze of a library a user already has is
  within what the capsule stand-ins can tell and what the player tolerates, so it
  still loads, and says where to fix it.
"""

from typing import NamedTuple

import numpy as np

from .kinematics import arm_columns, forward_kinematics, shoulder_position, split_arms

SEGMENTS = ('upper_arm', 'forearm', 'hand')
# Pairs checked: each arm segment against the torso, and every right-left segment pair.
PAIRS = ([('right', i, 'torso', 0) for i in range(3)]
         + [('left', i, 'torso', 0) for i in range(3)]
         + [('right', i, 'left', k) for i in range(3) for k in range(3)])
TOLERANCE_MM = 1.0     # penetration tolerated as numerical slack (objective, simulator)
REFUSE_MM = 5.0        # a reference deeper than this is refused at load time
FIELD_SAMPLES = 5      # points along a forearm or hand axis checked against a torso field
LIPSCHITZ = 1.75       # bound on how fast the interpolated field changes per mm (sqrt 3 > it)


def pair_name(pair):
    """Return a pair's name as the results print it, e.g. ``right_upper_arm-torso``."""
    a, i, b, k = pair
    return f'{a}_{SEGMENTS[i]}-{b}' + ('' if b == 'torso' else f'_{SEGMENTS[k]}')


PAIR_NAMES = tuple(pair_name(p) for p in PAIRS)
# closest_pairs gathers all pairs' ends from one table: rows 0-5 the right arm's segments
# (two ends each), 6-11 the left arm's, 12-13 the torso capsule's top and bottom.
_END_ROWS = {'right': slice(0, 6), 'left': slice(6, 12), 'torso': slice(12, 14)}
_FIRST = np.array([(0 if a == 'right' else 6) + 2 * i for a, i, _, _ in PAIRS])
_SECOND = np.array([12 if b == 'torso' else (0 if b == 'right' else 6) + 2 * k
                    for _, _, b, k in PAIRS])


def designed_pairs(two_handed):
    """Return a bool per pair of :data:`PAIRS`: True where a reference may touch it."""
    return np.array([two_handed and b != 'torso' for _, _, b, _ in PAIRS])


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


def radius_sums(capsules):
    """Return the sum of the two radii (mm) of every pair of :data:`PAIRS`."""
    radii = capsules.radii
    return np.array([radii[i] + (capsules.torso_radius if b == 'torso' else radii[k])
                     for _, i, b, k in PAIRS])


def arm_segments(robot, lm, side):
    """Return an arm's segment end points (N, 3 segments, 2, 3) mm from its landmarks."""
    points = np.empty(lm.elbow.shape[:-1] + (4, 3))
    points[..., 0, :] = shoulder_position(robot, side)
    points[..., 1, :], points[..., 2, :], points[..., 3, :] = lm.elbow, lm.wrist, lm.tip
    return np.stack((points[..., :3, :], points[..., 1:, :]), axis=-2)


def pair_ends(capsules, seg) -> tuple:
    """
    Return ``(p1, q1, p2, q2)``, (N, pairs, 3) each: the ends of every pair's two segments.

    ``seg`` maps 'right' and 'left' to arm segments (N, 3, 2, 3) mm; the torso's are
    its capsule's top and bottom.
    """
    n = seg['right'].shape[0]
    ends = np.empty((n, 14, 3))      # every segment's two ends, then the torso's: _END_ROWS
    ends[:, _END_ROWS['right']] = seg['right'].reshape(n, 6, 3)
    ends[:, _END_ROWS['left']] = seg['left'].reshape(n, 6, 3)
    ends[:, _END_ROWS['torso']] = (capsules.torso_top, capsules.torso_bottom)
    return ends[:, _FIRST], ends[:, _FIRST + 1], ends[:, _SECOND], ends[:, _SECOND + 1]


def closest_pairs(capsules, ends, field=True):
    """
    Return ``(d, s, t, normal)`` of every pair of PAIRS: (N, pairs) each, normal (N, pairs, 3).

    ``ends`` is :func:`pair_ends`' answer for the arms' segments (the caller keeps it
    for the distances' derivatives, ``CollisionModel``).  ``d`` is the axis distance,
    ``s`` and ``t`` the closest points' parameters on the first and second segment.
    With a ``capsules.torso_field``, a forearm or hand must clear the torso's own shape
    as well as its capsule: where the field is nearer, ``d`` is the
    field's distance at the nearest of ``FIELD_SAMPLES`` points along the segment's
    axis, read against the torso capsule's radius (``dist + r_torso``, so that
    :func:`radius_sums` holds), ``s`` that point's parameter, and ``normal`` the
    field's gradient there, the derivative of that distance (about unit length; zero
    for every other pair: their closest points give the direction; None where no pair
    is nearer the field).  An upper arm hangs from a shoulder on the torso: it meets the
    capsule only.  ``field=False`` leaves the field out.
    """
    p1, q1, p2, q2 = ends
    d, s, t = segment_distance(p1, q1, p2, q2)
    normal = None
    shape = capsules.torso_field if field else None
    if shape is not None:
        normal = _field_pairs(capsules, shape, (p1, q1), d, s)
    return d, s, t, normal


def _field_pairs(capsules, shape, axes, d, s):
    """
    Read the forearm and hand torso pairs against the torso's shape too (in ``d``, ``s``).

    ``axes`` is (p1, q1), the pairs' first segments (N, pairs, 3); return the normals
    (N, pairs, 3) of the pairs the shape decides, or None (see :func:`closest_pairs`).
    """
    p1, q1 = axes
    normal = None
    lower = np.nonzero([b == 'torso' and i > 0 for _, i, b, _ in PAIRS])[0]
    radius = capsules.radii[[PAIRS[p][1] for p in lower]]
    # A segment beyond the field's reach from the torso axis, or wholly beyond one
    # face of the box around its inside, cannot touch it.
    lo, hi = shape.box
    a, b = p1[:, lower], q1[:, lower]
    r = radius[:, None]
    apart = np.any(((a > hi + r) & (b > hi + r)) | ((a < lo - r) & (b < lo - r)), axis=-1)
    rows, cols = np.nonzero((d[:, lower] < shape.reach + radius) & ~apart)
    if len(rows):
        # Nor one whose middle is farther from it than half its length plus its
        # radius (a distance field changes by at most the distance moved).
        mid = (p1[rows, lower[cols]] + q1[rows, lower[cols]]) / 2.0
        half = np.linalg.norm(q1[rows, lower[cols]] - p1[rows, lower[cols]], axis=1) / 2.0
        close = shape.lookup(mid)[0] - LIPSCHITZ * half < radius[cols] + 1.0
        rows, cols = rows[close], cols[close]
    if len(rows):
        pairs = lower[cols]
        frac = np.linspace(0.0, 1.0, FIELD_SAMPLES)
        start, end = p1[rows, pairs], q1[rows, pairs]                 # (M, 3)
        pts = start[:, None] + frac[:, None] * (end - start)[:, None]  # (M, S, 3)
        dist, grad = shape.lookup(pts)
        best = np.argmin(dist, axis=1)
        m = np.arange(len(rows))
        near = dist[m, best] + capsules.torso_radius
        closer = near < d[rows, pairs]
        rows, pairs, best, m = rows[closer], pairs[closer], best[closer], m[closer]
        d[rows, pairs] = near[closer]
        s[rows, pairs] = frac[best]
        g = grad[m, best]
        if len(rows):
            normal = np.zeros(d.shape + (3,))
            normal[rows, pairs] = g
    return normal


def pair_distances(robot, lm_right, lm_left):
    """Return the axis distance (mm) of every pair, (N, pairs), and the closest points' s, t."""
    seg = {'right': arm_segments(robot, lm_right, 'right'),
           'left': arm_segments(robot, lm_left, 'left')}
    return closest_pairs(robot.capsules, pair_ends(robot.capsules, seg))[:3]


def penetrations(robot, q14):
    """Return how deep (mm, >= 0) every pair interpenetrates at poses ``q14`` (N, J) rad."""
    right, left = split_arms(robot, np.atleast_2d(np.asarray(q14, dtype=float)))
    d = pair_distances(robot, forward_kinematics(robot, right, 'right'),
                       forward_kinematics(robot, left, 'left'))[0]
    return np.maximum(radius_sums(robot.capsules)[None, :] - d, 0.0)


def pressed_joints(robot, joint_names, q, tolerance_mm=TOLERANCE_MM):
    """
    Return (n, J) bool: the joints of an arm that poses ``q`` (n, J) press into the torso.

    ``q`` is in ``joint_names`` order; an arm goes into the torso when one of its
    segments is deeper than ``tolerance_mm``.  The torso is never designed contact.
    Joints of an arm that ``joint_names`` do not cover whole are never pressed (the
    pose of that arm is not known).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    names = list(joint_names)
    out = np.zeros(q.shape, dtype=bool)
    q14 = np.zeros((len(q), len(robot.joint_names)))
    whole = {}
    for side, cols in arm_columns(robot).items():
        arm = list(robot.arms[side].joint_names)
        whole[side] = all(j in names for j in arm)
        if whole[side]:
            q14[:, cols] = q[:, [names.index(j) for j in arm]]
    if not any(whole.values()):
        return out
    pen = penetrations(robot, q14)
    for k, side in enumerate(('right', 'left')):
        if whole[side]:
            deep = pen[:, 3 * k:3 * k + 3].max(axis=1) > tolerance_mm   # PAIRS: arm-torso
            for j in robot.arms[side].joint_names:
                out[:, names.index(j)] = deep
    return out


class ReferenceContact(NamedTuple):
    """The deepest undesigned contact of one gesture's reference keyframes."""

    gesture: str
    keyframe: int
    time: float
    pair: str
    depth_mm: float
    keyframes_touching: int

    @property
    def refused(self):
        """Return True when it is too deep to load (:data:`REFUSE_MM`)."""
        return self.depth_mm > REFUSE_MM

    def problem(self):
        """Return the one-line problem text (without the file and key)."""
        more = (f' (and {self.keyframes_touching - 1} more keyframe(s))'
                if self.keyframes_touching > 1 else '')
        verdict = (f'refused: deeper than {REFUSE_MM:g} mm' if self.refused else
                   f'loaded: a graze of at most {REFUSE_MM:g} mm')
        return (f'gesture {self.gesture!r} keyframe {self.keyframe} (t = {self.time:g} s): '
                f'{self.pair} interpenetrate by {self.depth_mm:.1f} mm{more}; the '
                f"robot's own body blocks this reference ({verdict})")


def undesigned_depth(robot, reference, poses) -> float:
    """
    Return how deep (mm, >= 0) poses (N, J) press any pair beyond ``reference``'s design.

    A played motion is checked along its whole path, not only at its keyframes: a
    two-handed gesture's designed pairs may go as deep as its reference keyframes do
    (the deepest of them, as the simulator allows), every other pair not at all; nor
    deeper than the first pose already does (where a motion starts is not its doing:
    a locked arm at rest may lie on the torso).
    """
    pen = penetrations(robot, poses)
    allowed = pen[0].copy()
    designed = designed_pairs(reference.two_handed)
    if np.any(designed):
        ref = penetrations(robot, reference.joint_matrix()).max(axis=0)
        allowed[designed] = np.maximum(allowed[designed], ref[designed])
    return float(max(np.max(pen - allowed[None, :]), 0.0))


def reference_contact(robot, gesture):
    """Return the deepest undesigned contact of ``gesture`` beyond the tolerance, or None."""
    pen = penetrations(robot, gesture.joint_matrix())
    pen[:, designed_pairs(gesture.two_handed)] = 0.0
    worst = pen.max(axis=1)
    touching = np.nonzero(worst > TOLERANCE_MM)[0]
    if not touching.size:
        return None
    k = int(np.argmax(worst))
    return ReferenceContact(gesture.name, k, float(gesture.keyframes[k].time_from_start),
                            PAIR_NAMES[int(np.argmax(pen[k]))], float(worst[k]),
                            int(touching.size))
