"""
A joint trajectory controller's rules on plain data: validation and sampling.

It behaves as ros2_control's JointTrajectoryController (Jazzy) does for a
``trajectory_msgs/JointTrajectory`` on its ``~/joint_trajectory`` topic, so that what
plays well on the simulator plays on the robot:

- Rejected, with the reason: joints that are not the controller's (unknown ones or the
  other arm's); fewer joints than the controller's unless partial goals are allowed;
  no points; ``time_from_start`` not strictly increasing; positions (velocities,
  accelerations) of the wrong length; effort given; a non-zero velocity at the last
  point (unless allowed); a non-zero ``header.stamp`` whose trajectory ends in the past
  (the controller's rule: a past stamp whose trajectory still runs is joined
  mid-way).
- A zero stamp means "start now".  A new trajectory replaces the current one.
- Before the first point the controller moves from the state it had when the
  trajectory began; between points it interpolates linearly (positions only), with
  cubic Hermite splines (with velocities) or quintic ones (with accelerations); after
  the last point it holds it.

Times are float seconds on the controller's clock (ROS time).
"""

from typing import NamedTuple

import numpy as np


class Rejected(ValueError):
    """A trajectory the controller refuses; the message says why."""


class Point(NamedTuple):
    """One trajectory point: time from start (s) and per-joint values (None = not given)."""

    time: float
    positions: tuple
    velocities: tuple = ()
    accelerations: tuple = ()
    effort: tuple = ()


class Command(NamedTuple):
    """A received trajectory: joint names, header stamp (s; 0 = now) and points."""

    joint_names: tuple
    stamp: float
    points: tuple


def validate(command, joints, now, allow_partial=False, allow_nonzero_end_velocity=False):
    """Raise :class:`Rejected` with the reason if ``command`` breaks a controller rule."""
    names = list(command.joint_names)
    if not allow_partial and len(names) != len(joints):
        raise Rejected(f"joints on the incoming trajectory ({', '.join(names) or 'none'}) "
                       f"don't match the controller's joints ({', '.join(joints)})")
    if not names:
        raise Rejected('empty joint names on the incoming trajectory')
    if len(set(names)) != len(names):
        raise Rejected(f"duplicate joint names on the incoming trajectory: {', '.join(names)}")
    if command.points and command.stamp != 0.0:
        end = command.stamp + command.points[-1].time
        if end < now:
            raise Rejected(f'received a trajectory with non-zero start time '
                           f'({command.stamp:.3f}) that ends in the past ({end:.3f} < '
                           f'now {now:.3f})')
    for name in names:
        if name not in joints:
            raise Rejected(f"incoming joint {name} doesn't match the controller's joints "
                           f"({', '.join(joints)})")
    if not command.points:
        raise Rejected('empty trajectory received (no points)')
    last = command.points[-1]
    if not allow_nonzero_end_velocity and any(v != 0.0 for v in last.velocities):
        raise Rejected('the velocity of the last trajectory point is not zero '
                       f'({", ".join(f"{v:g}" for v in last.velocities)})')
    previous = None
    for i, point in enumerate(command.points):
        if previous is not None and point.time <= previous:
            raise Rejected(f'time between points {i - 1} and {i} is not strictly increasing, '
                           f'it is {previous:g} s and {point.time:g} s respectively')
        if point.time < 0.0:
            raise Rejected(f'point {i}: negative time_from_start {point.time:g} s')
        previous = point.time
        if len(point.positions) != len(names):
            raise Rejected(f'mismatch between joint_names size ({len(names)}) and positions '
                           f'({len(point.positions)}) at point #{i}')
        for field in ('velocities', 'accelerations'):
            size = len(getattr(point, field))
            if size and size != len(names):
                raise Rejected(f'mismatch between joint_names size ({len(names)}) and '
                               f'{field} ({size}) at point #{i}')
        if point.effort:
            raise Rejected('trajectories with effort fields are not supported')
        values = np.concatenate([np.asarray(getattr(point, f), float) for f in
                                 ('positions', 'velocities', 'accelerations')])
        if not np.all(np.isfinite(values)):
            raise Rejected(f'point {i}: positions, velocities and accelerations must be '
                           'finite')


def _interpolate(t0, a, t1, b, t):
    """Return (q, qd) at t between knots a and b (Points in controller order)."""
    T = t1 - t0
    s = min(max(t - t0, 0.0), T)
    p0, p1 = np.asarray(a.positions, float), np.asarray(b.positions, float)
    if T <= 0.0:
        return p1, np.zeros_like(p1)
    if not (len(a.velocities) and len(b.velocities)):
        return p0 + (p1 - p0) * s / T, (p1 - p0) / T
    v0, v1 = np.asarray(a.velocities, float), np.asarray(b.velocities, float)
    if not (len(a.accelerations) and len(b.accelerations)):
        c2 = (3 * (p1 - p0) - (2 * v0 + v1) * T) / T ** 2
        c3 = (2 * (p0 - p1) + (v0 + v1) * T) / T ** 3
        return (p0 + v0 * s + c2 * s ** 2 + c3 * s ** 3,
                v0 + 2 * c2 * s + 3 * c3 * s ** 2)
    a0, a1 = np.asarray(a.accelerations, float), np.asarray(b.accelerations, float)
    c3 = (20 * (p1 - p0) - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T ** 2) / (2 * T ** 3)
    c4 = (-30 * (p1 - p0) + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T ** 2) / (2 * T ** 4)
    c5 = (12 * (p1 - p0) - 6 * (v1 + v0) * T - (a0 - a1) * T ** 2) / (2 * T ** 5)
    q = p0 + v0 * s + a0 / 2 * s ** 2 + c3 * s ** 3 + c4 * s ** 4 + c5 * s ** 5
    qd = v0 + a0 * s + 3 * c3 * s ** 2 + 4 * c4 * s ** 3 + 5 * c5 * s ** 4
    return q, qd


def _reorder(values, index, fill):
    """Return per-controller-joint values from message order (``fill`` for missing)."""
    if not len(values):
        return ()
    out = np.array(fill, dtype=float)
    for i, k in enumerate(index):
        out[k] = values[i]
    return tuple(out)


class ActiveTrajectory:
    """
    An accepted trajectory, in the controller's joint order, ready to be sampled.

    ``start`` is when its time 0 falls (the stamp, or the receipt time for a zero
    stamp); ``state`` is the (positions, velocities) the controller had when it took
    the trajectory on at time ``begin``: the segment before the first point starts
    there (at ``start`` for a stamp in the future; the controller holds until then).
    Joints a partial goal leaves out hold ``state``'s positions.
    """

    def __init__(self, command, joints, begin, state):
        self.joints = tuple(joints)
        index = [self.joints.index(n) for n in command.joint_names]
        hold = np.asarray(state[0], float)
        zeros = np.zeros(len(self.joints))
        self.start = command.stamp if command.stamp != 0.0 else begin
        self.points = [Point(p.time, _reorder(p.positions, index, hold),
                             _reorder(p.velocities, index, zeros),
                             _reorder(p.accelerations, index, zeros))
                       for p in command.points]
        self.begin = max(begin, self.start)
        self.before = Point(0.0, tuple(hold), tuple(np.asarray(state[1], float)))
        self.end = self.start + self.points[-1].time

    def sample(self, t):
        """Return the desired (positions, velocities) at time t, or None before start."""
        if t < self.start:
            return None
        first = self.start + self.points[0].time
        if t < first:
            return _interpolate(self.begin, self.before, first, self.points[0], t)
        if t >= self.end:
            return np.asarray(self.points[-1].positions, float), np.zeros(len(self.joints))
        times = [self.start + p.time for p in self.points]
        k = int(np.searchsorted(times, t, side='right')) - 1
        return _interpolate(times[k], self.points[k], times[k + 1], self.points[k + 1], t)
