"""
A played path that presses the body no deeper than its own waypoints do (no ROS).

The engine checks self-contact at a gesture's keyframes; the player joins them by a
spline in joint space, and on the way the arms can press deeper than at any keyframe.
Example: Wai with left joint 3 locked.  The optimiser reaches the palms-together pose
with other joints than the design does, and the straight approach from rest brings the
palms 11 mm through each other before they part again to the key pose, which touches
only as designed.  The simulator's (and a real robot's) palms then collide.

:class:`PathClearance` samples a planned path every :data:`STEP` seconds with the
capsule model of :mod:`..model.self_contact`.  A pair may press as deep as the deepest
waypoint (start pose or keyframe) presses it: the engine judged the keyframes (a
designed Wai touch, or a graze it reported), and where a motion starts is not its
doing.  Where a segment goes deeper by more than :data:`~..model.self_contact.
TOLERANCE_MM`, :meth:`PathClearance.bend` adds one via pose at the deepest instant.
The pose is pushed out of the contact along the depth's gradient in the joints that
move on that segment, never a locked one.  The push is the smallest of
:data:`PUSHES` that leaves the whole path clear, so the path keeps close to the
designed one.  The speed limits are applied afterwards, as for any waypoint.
"""

import numpy as np

from ..model.self_contact import penetrations, TOLERANCE_MM

STEP = 0.02              # s between the checked poses of a path
PUSHES = (0.05, 0.1, 0.15, 0.2, 0.3, 0.45, 0.6)   # rad: largest joint move of the via pose
_GRADIENT_STEP = 1e-3    # rad: finite difference of the depth
_MOVING = 1e-6           # rad: a joint that moves less on a segment is left where it is
_MAX_VIAS = 3            # via poses added to one motion at most


class PathClearance:
    """The capsule model's depths along poses in the player's joint order."""

    def __init__(self, robot, joint_names):
        """Map ``joint_names`` (the player's columns) onto the robot's two arms."""
        self.robot = robot
        names = list(joint_names)
        order = [j for side in ('right', 'left') for j in robot.arms[side].joint_names]
        missing = [j for j in order if j not in names]
        if missing:
            raise ValueError(f'a path can be checked only with both arms played; '
                             f'{missing[0]!r} is not among the played joints')
        self.columns = np.array([names.index(j) for j in order])

    def depths(self, poses: np.ndarray) -> np.ndarray:
        """Return every pair's depth (mm) at ``poses`` (N, J) in the player's order."""
        return penetrations(self.robot, np.atleast_2d(poses)[:, self.columns])

    def excess(self, poses: np.ndarray, allowed: np.ndarray) -> np.ndarray:
        """Return how much deeper (mm, >= 0) than ``allowed`` poses press, (N,)."""
        return np.max(np.maximum(self.depths(poses) - allowed, 0.0), axis=1)

    def bend(self, times, points, plan, locked=()):
        """
        Return (times, points, via) with via poses where the path of ``plan`` is too deep.

        ``plan(times, points)`` returns the PlannedMotion of those waypoints (the
        player's timing, its speed limits and locks); ``locked`` are column indices
        that never move; ``via`` marks the added rows.  Unchanged when the path is clear,
        or when no push clears it (the path the engine would have played, as before).
        """
        times, points = np.asarray(times, float), np.asarray(points, float)
        via = np.zeros(len(times), dtype=bool)
        allowed = self.depths(points).max(axis=0) + TOLERANCE_MM
        for _ in range(_MAX_VIAS):
            found = self._deepest(plan(times, points), allowed)
            bent = found and self._via(times, points, plan, allowed, found, locked)
            if bent is None:
                break
            times, points, s = bent
            via = np.insert(via, s, True)
        return times, points, via

    def _deepest(self, motion, allowed, between=None):
        """
        Return (time, pose) of ``motion``'s deepest excess, or None if it is clear.

        ``between`` = (first, last) knot indices limits the search to those segments.
        """
        t0, t1 = (0.0, motion.duration) if between is None else \
            motion.waypoint_times[list(between)]
        t = np.append(np.arange(t0, t1, STEP), t1)
        poses = motion.command_at(t)
        over = self.excess(poses, allowed)
        k = int(np.argmax(over))
        return None if over[k] <= 0.0 else (float(t[k]), poses[k])

    def _via(self, times, points, plan, allowed, found, locked):
        """Return the waypoints with a pushed via pose at ``found``, or None."""
        t, pose = found
        s = int(np.searchsorted(times, t, side='right')) - 1
        s = min(max(s, 0), len(times) - 2)
        moving = np.abs(points[s + 1] - points[s]) > _MOVING
        moving[list(locked)] = False
        if not np.any(moving):
            return None
        direction = self._outward(pose, allowed, moving)
        if direction is None:
            return None
        t = float(np.clip(t, times[s] + 0.25 * (times[s + 1] - times[s]),
                          times[s] + 0.75 * (times[s + 1] - times[s])))
        for push in PUSHES:
            new_t = np.insert(times, s + 1, t)
            new_p = np.insert(points, s + 1, pose + push * direction, axis=0)
            if self._deepest(plan(new_t, new_p), allowed, (s, s + 2)) is None:
                return new_t, new_p, s + 1
        return None

    def _outward(self, pose, allowed, moving):
        """Return the joint direction (largest move 1 rad) that most reduces the excess."""
        cols = np.nonzero(moving)[0]
        probes = np.repeat(pose[None, :], 2 * len(cols), axis=0)
        probes[np.arange(len(cols)), cols] += _GRADIENT_STEP
        probes[len(cols) + np.arange(len(cols)), cols] -= _GRADIENT_STEP
        over = np.sum(np.maximum(self.depths(probes) - allowed, 0.0), axis=1)
        gradient = np.zeros_like(pose)
        gradient[cols] = (over[:len(cols)] - over[len(cols):]) / (2 * _GRADIENT_STEP)
        size = np.max(np.abs(gradient))
        return None if size == 0.0 else -gradient / size
