"""
A reference gesture that the robot's own body blocks: a library error, found at load time.

A gesture whose keyframes bring an arm into the torso (or, in a one-handed gesture, into
the other arm) cannot be played: the body stops the arm, and a stuck-joint detector
then sees a joint that does not follow.  That is not an actuator fault, and it should
not wait for a play to be discovered.  :func:`body_contacts` checks the reference
keyframes with the capsules of the robot model (the same capsules as the optimiser's
and the simulator's self-collision): every arm segment against the torso, and the right
against the left arm for one-handed gestures (a two-handed reference may bring the
hands together: designed contact).
"""

from typing import NamedTuple

import numpy as np

from ..model.kinematics import forward_kinematics, shoulder_position
from ..objective.collision import segment_distance

SEGMENTS = ('upper_arm', 'forearm', 'hand')
TOLERANCE_MM = 1.0        # penetration tolerated (the objective's and the simulator's)


class BodyContact(NamedTuple):
    """Where a reference keyframe goes into the body: its index, the pair, the depth (mm)."""

    keyframe: int
    pair: str
    depth_mm: float


def _segments(robot, q7, side):
    lm = forward_kinematics(robot, np.asarray(q7, dtype=float), side)
    ends = (shoulder_position(robot, side), lm.elbow, lm.wrist, lm.tip)
    return {f'{side}_{seg}': (ends[k], ends[k + 1]) for k, seg in enumerate(SEGMENTS)}


def body_contacts(robot, gesture, tolerance_mm=TOLERANCE_MM):
    """Return the BodyContacts of ``gesture``'s reference keyframes (empty: clear)."""
    cap = robot.capsules
    radius = dict(zip(SEGMENTS, cap.radii))
    torso = (np.array(cap.torso_top, dtype=float), np.array(cap.torso_bottom, dtype=float))
    found = []
    for k, frame in enumerate(gesture.keyframes):
        segs = {**_segments(robot, frame.right, 'right'), **_segments(robot, frame.left, 'left')}
        pairs = [(name, 'torso', radius[name.split('_', 1)[1]] + cap.torso_radius)
                 for name in segs]
        if not gesture.two_handed:
            pairs += [(f'right_{a}', f'left_{b}', radius[a] + radius[b])
                      for a in SEGMENTS for b in SEGMENTS]
        for a, b, reach in pairs:
            other = torso if b == 'torso' else segs[b]
            dist = float(segment_distance(*segs[a], *other)[0])
            if reach - dist > tolerance_mm:
                found.append(BodyContact(k, f'{a}-{b}', reach - dist))
    return found


def blocked_gestures(robot, library, tolerance_mm=TOLERANCE_MM):
    """Return {gesture name: (keyframes in contact, deepest BodyContact)} of a library."""
    out = {}
    for gesture in library:
        contacts = body_contacts(robot, gesture, tolerance_mm)
        if contacts:
            out[gesture.name] = (len({c.keyframe for c in contacts}),
                                 max(contacts, key=lambda c: c.depth_mm))
    return out
