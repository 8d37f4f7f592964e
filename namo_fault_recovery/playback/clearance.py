"""
A played path that presses the body no deeper than its own waypoints do (no ROS).

The engine checks self-contact at a gesture's keyframes; the player joins them by a
spline in joint space, and on the way the arms can press deeper than at any keyframe.
Example: Wai with left joint 3 stuck at -45 deg, the key pose's own angle.  The arm
starts from rest with that joint already there, and the straight approach brings the
palms 11 mm through each other before the key pose, where they touch only as designed.
Or TIAGo++'s idle left arm, moved clear of the body with its elbow stuck: the straight
swing to that pose passes 93 mm through the torso.  The simulator's (and a real
robot's) bodies then collide.

:class:`PathClearance` samples a planned path every :data:`STEP` seconds with the
capsule model of :mod:`..model.self_contact`.  A pair may press as deep as the deepest
waypoint (start pose or keyframe) presses it: the engine judged the keyframes (a
designed Wai touch, or a graze it reported), and where a motion starts is not its
doing.  Where a segment goes deeper (by more than :data:`SLACK_MM`),
:meth:`PathClearance.bend` adds a via pose at the deepest instant, pushed out of the
contact along the depth's gradient in the joints that move on that segment (never a
locked one), within the joint limits.  The push is the smallest of :data:`PUSHES`
that clears that part of the path, so the path keeps close to the designed one; where
none does, the one that at least halves the excess, and the next via goes on from
there.  The keyframes and their times stay; the speed limits are applied afterwards,
as for any waypoint.  A path that no via makes shallower is played as it was.
"""

import numpy as np

from .timing import waypoint_spline
from ..model.self_contact import penetrations

STEP = 0.02              # s between the checked poses of a path
# mm a path may press deeper than its deepest waypoint: none to speak of, so that a path
# whose keyframes are within the design by the simulator's tolerance is too.
SLACK_MM = 0.05
_SCREEN_STEP = 0.04      # s between the poses that screen the pushes (then checked at STEP)
PUSHES = (0.05, 0.1, 0.15, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0)   # rad: the via's largest move
_GRADIENT_STEP = 1e-3    # rad: finite difference of the depth
_MOVING = 1e-6           # rad: a joint that moves less on a segment is left where it is
_MAX_VIAS = 4            # via poses added to one motion at most
_PROGRESS = 0.5          # a via that does not clear its part must at least halve its excess


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
        # Other played joints (not in the capsule model) are never pushed.
        self.lower, self.upper = np.full(len(names), -np.inf), np.full(len(names), np.inf)
        self.lower[self.columns] = np.concatenate([robot.arms[s].lower
                                                   for s in ('right', 'left')])
        self.upper[self.columns] = np.concatenate([robot.arms[s].upper
                                                   for s in ('right', 'left')])

    def depths(self, poses: np.ndarray) -> np.ndarray:
        """Return every pair's depth (mm) at ``poses`` (N, J) in the player's order."""
        return penetrations(self.robot, np.atleast_2d(poses)[:, self.columns])

    def excess(self, poses: np.ndarray, allowed: np.ndarray) -> np.ndarray:
        """Return how much deeper (mm, >= 0) than ``allowed`` poses press, (N,)."""
        return np.max(np.maximum(self.depths(poses) - allowed, 0.0), axis=1)

    def bend(self, motion, points, plan, locked=()):
        """
        Return (motion, via): ``motion`` with via poses where its path is too deep.

        ``motion`` is ``plan(times, points)`` for the waypoints ``points``: ``plan``
        returns the PlannedMotion of waypoints (the player's timing, its speed limits
        and locks); ``locked`` are column indices that never move; ``via`` marks the
        added rows of the returned motion's waypoints.  Each via pose clears its part of
        the path, or at least halves its excess (a deep pass through the torso may take
        several); the bent motion is returned only if it is shallower than the straight
        one, else ``motion`` itself.
        """
        current, points = motion, np.asarray(points, float)
        via = np.zeros(len(points), dtype=bool)
        allowed = self.depths(points).max(axis=0) + SLACK_MM
        straight = found = self._deepest(motion, allowed)
        for _ in range(_MAX_VIAS):
            bent = found[0] > 0.0 and self._via(
                current.waypoint_times, points, plan, allowed, found, locked)
            if not bent:
                break
            times, points, s = bent
            via = np.insert(via, s, True)
            current = plan(times, points)
            found = self._deepest(current, allowed)
        if found[0] >= straight[0]:
            return motion, np.zeros(len(motion.waypoint_times), dtype=bool)
        return current, via

    def _deepest(self, motion, allowed, between=None):
        """
        Return (excess mm, time, pose) of ``motion``'s deepest excess (0 where clear).

        ``between`` = (first, last) knot indices limits the search to those segments.
        """
        t0, t1 = (0.0, motion.duration) if between is None else \
            motion.waypoint_times[list(between)]
        t = np.append(np.arange(t0, t1, STEP), t1)
        poses = motion.command_at(t)
        over = self.excess(poses, allowed)
        k = int(np.argmax(over))
        return float(over[k]), float(t[k]), poses[k]

    def _via(self, times, points, plan, allowed, found, locked):
        """Return the waypoints with a pushed via pose at ``found``, or None."""
        excess, t, pose = found
        s = int(np.searchsorted(times, t, side='right')) - 1
        s = min(max(s, 0), len(times) - 2)
        moving = np.abs(points[s + 1] - points[s]) > _MOVING
        moving[list(locked)] = False
        direction = self._outward(pose, allowed, moving) if np.any(moving) else None
        if direction is None:
            return None
        t = float(np.clip(t, times[s] + 0.25 * (times[s + 1] - times[s]),
                          times[s] + 0.75 * (times[s + 1] - times[s])))
        new_t = np.insert(times, s + 1, t)
        samples = np.append(np.arange(times[s], times[s + 1], _SCREEN_STEP), times[s + 1])
        best = (np.inf, None)
        for pushes in np.reshape(PUSHES, (-1, 3)):    # the smallest pushes first
            tries = [np.insert(points, s + 1, np.clip(pose + push * direction, self.lower,
                                                      self.upper), axis=0)
                     for push in pushes]
            poses = np.concatenate([waypoint_spline(new_t, p)(samples) for p in tries])
            left = self.excess(poses, allowed).reshape(len(tries), len(samples)).max(axis=1)
            k = int(np.argmin(left))
            if left[k] < best[0]:
                best = (left[k], tries[k])
            if best[0] <= 0.0:
                break
        if best[0] > _PROGRESS * excess:
            return None
        return new_t, best[1], s + 1

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
