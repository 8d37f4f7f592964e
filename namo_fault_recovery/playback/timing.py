"""
Time parameterisation of a gesture for playback (what play_motion2 does, plus locks).

A play starts from the measured pose: the first segment approaches the gesture's first
keyframe in ``max(t0, max|dq| / approach_velocity, approach_min_duration)`` seconds
(play_motion2's approach rule; ``t0`` is the first keyframe's own ``time_from_start``,
designed from the rest pose, so a play never runs faster than designed).  The
waypoints are joined by a C1 cubic Hermite spline: shape-preserving (PCHIP) slopes at
inner waypoints, zero velocity at both ends, so no joint overshoots a waypoint and a
joint that does not move in the waypoints (a locked one) stays exactly still.  Segments
whose peak speed exceeds a joint's ``velocity_limits`` are stretched until none does:
after a fault the free joints often travel further than designed, and only the
segments where they do are slowed down.
"""

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.interpolate import CubicHermiteSpline, PchipInterpolator

MIN_SEGMENT = 0.05          # s: shortest segment (an approach to where the arm already is)
_SPEED_SAMPLES = 24         # samples per segment when looking for its peak speed
_STRETCH_MARGIN = 1.02      # stretch a little beyond the limit ratio: converges in few passes
_MAX_PASSES = 30


@dataclass(frozen=True)
class PlayTiming:
    """The player's timing parameters (named as the node parameters)."""

    approach_velocity: float = 0.5       # rad/s, as play_motion2's default
    approach_min_duration: float = 0.0   # s
    sample_period: float = 0.05          # s between the points sent to a controller

    def __post_init__(self):
        """Refuse values that cannot time a motion."""
        if not self.approach_velocity > 0:
            raise ValueError(f'approach_velocity must be > 0, got {self.approach_velocity}')
        if not self.approach_min_duration >= 0:
            raise ValueError('approach_min_duration must be >= 0, got '
                             f'{self.approach_min_duration}')
        if not self.sample_period > 0:
            raise ValueError(f'sample_period must be > 0, got {self.sample_period}')


@dataclass(frozen=True)
class PlannedMotion:
    """
    A timed trajectory for all the played joints, sampled for the controllers.

    ``times`` start at 0 (the moment the goal is sent); ``waypoint_times`` are the times
    of the start pose and of every keyframe (a gesture's phase); ``stretch`` is the
    duration over the duration before the speed limits were applied (1.0 when nothing was
    slowed down).  ``spline_knots`` are the spline's own knots when it has more than the
    waypoints (the via poses of :mod:`.clearance`); :attr:`knots` is either.
    """

    joint_names: tuple
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    waypoint_times: np.ndarray
    waypoints: np.ndarray
    stretch: float
    locks: dict = field(default_factory=dict)
    _spline: object = field(default=None, repr=False, compare=False)
    spline_knots: object = field(default=None, repr=False, compare=False)

    @property
    def knots(self) -> np.ndarray:
        """Return the times between which the trajectory is one cubic (s)."""
        return self.waypoint_times if self.spline_knots is None else self.spline_knots

    @property
    def duration(self):
        """Return the time of the last point (s)."""
        return float(self.times[-1])

    @property
    def final(self):
        """Return the last commanded pose (rad)."""
        return self.positions[-1]

    def command_at(self, t):
        """Return the commanded pose at time(s) ``t``, held at the ends (rad)."""
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        q = self._spline(t)
        for j, angle in self._lock_columns():
            q[..., j] = angle
        return q

    def velocity_at(self, t):
        """Return the commanded velocity at time(s) ``t`` (rad/s; 0 for locked joints)."""
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        qd = self._spline.derivative()(t)
        for j, _ in self._lock_columns():
            qd[..., j] = 0.0
        return qd

    def acceleration_at(self, t):
        """Return the commanded acceleration at time(s) ``t`` (rad/s^2; 0 outside, locked)."""
        t = np.asarray(t, dtype=float)
        qdd = self._spline.derivative(2)(np.clip(t, 0.0, self.duration))
        qdd[(t < 0.0) | (t >= self.duration)] = 0.0     # held before and after
        for j, _ in self._lock_columns():
            qdd[..., j] = 0.0
        return qdd

    def _lock_columns(self):
        return [(self.joint_names.index(n), a) for n, a in self.locks.items()
                if n in self.joint_names]

    def columns(self, joints):
        """Return (positions, velocities) restricted to ``joints``, in that order."""
        index = [self.joint_names.index(j) for j in joints]
        return self.positions[:, index], self.velocities[:, index]


def _slopes(times, points):
    """PCHIP slopes at the waypoints, with zero velocity at the first and last one."""
    if len(times) < 3:
        slopes = np.zeros_like(points)
    else:
        slopes = PchipInterpolator(times, points, axis=0).derivative()(times)
    slopes[0] = 0.0
    slopes[-1] = 0.0
    return slopes


def waypoint_spline(times, points) -> CubicHermiteSpline:
    """Return the player's spline through ``points`` at ``times`` (before any stretch)."""
    return CubicHermiteSpline(times, points, _slopes(times, points), axis=0)


def _segment_ratios(spline, times, limits):
    """Return, per segment, the largest peak speed over the speed limit of any joint."""
    ratios = np.empty(len(times) - 1)
    speed = spline.derivative()
    for s in range(len(times) - 1):
        t = np.linspace(times[s], times[s + 1], _SPEED_SAMPLES)
        ratios[s] = np.max(np.abs(speed(t)) / limits)
    return ratios


def _stretch(times, points, limits):
    """Stretch the segments too fast for ``limits``; return the times and their spline."""
    for _ in range(_MAX_PASSES):
        spline = waypoint_spline(times, points)
        ratios = _segment_ratios(spline, times, limits)
        if np.all(ratios <= 1.0):
            return times, spline
        scale = np.where(ratios > 1.0, ratios * _STRETCH_MARGIN, 1.0)
        times = np.concatenate([[0.0], np.cumsum(np.diff(times) * scale)])
    # The slopes of neighbouring segments interact; a last uniform stretch bounds all.
    times = times * (np.max(ratios) * _STRETCH_MARGIN)
    return times, waypoint_spline(times, points)


def plan_motion(joint_names, start, keyframe_times, keyframes, velocity_limits,
                locks=None, lower=None, upper=None, timing=PlayTiming(), clearance=None):
    """
    Return the PlannedMotion that plays ``keyframes`` from the measured pose ``start``.

    ``joint_names`` names the columns of ``start`` (J,), ``keyframes`` (K, J) and
    ``velocity_limits`` (J,) rad/s.  ``locks`` maps joint names to lock angles: those
    columns are commanded at the lock angle at every point, the approach included,
    whatever the keyframes and the measured pose say.  ``lower``/``upper`` clip every
    waypoint into the joint limits.  With a :class:`~.clearance.PathClearance`, a path
    that presses the body deeper than its waypoints do is bent out of the contact.
    """
    names = tuple(joint_names)
    start = np.asarray(start, dtype=float).copy()
    frames = np.atleast_2d(np.asarray(keyframes, dtype=float)).copy()
    kf_times = np.asarray(keyframe_times, dtype=float)
    limits = np.asarray(velocity_limits, dtype=float)
    _check_shapes(names, start, frames, kf_times, limits)
    locks = {j: float(a) for j, a in (locks or {}).items() if j in names}
    for joint, angle in locks.items():
        start[names.index(joint)] = angle
        frames[:, names.index(joint)] = angle
    if lower is not None:
        frames = np.clip(frames, lower, upper)

    approach = float(np.max(np.abs(frames[0] - start)))
    first = max(kf_times[0], approach / timing.approach_velocity,
                timing.approach_min_duration, MIN_SEGMENT)
    times = np.concatenate([[0.0], first + kf_times - kf_times[0]])
    points = np.vstack([start, frames])
    # Merge keyframes closer than MIN_SEGMENT (a repeated time) into one waypoint.
    keep = np.concatenate([[True], np.diff(times) >= MIN_SEGMENT - 1e-12])
    times, points = times[keep], points[keep]

    def timed(knots, poses):
        stretched, spline = _stretch(knots, poses, limits)
        return sampled_motion(names, spline, stretched, timing.sample_period,
                              float(stretched[-1] / times[-1]), locks, poses)

    motion = timed(times, points)
    if clearance is None:
        return motion
    locked = [names.index(j) for j in locks]
    bent, via = clearance.bend(motion, points, timed, locked)
    if not np.any(via):
        return motion
    return replace(bent, waypoint_times=bent.waypoint_times[~via],
                   waypoints=bent.waypoints[~via], spline_knots=bent.waypoint_times)


def _check_shapes(names, start, frames, kf_times, limits):
    if frames.shape[1] != len(names) or start.shape != (len(names),):
        raise ValueError(f'expected {len(names)} joints, got start {start.shape} and '
                         f'keyframes {frames.shape}')
    if len(kf_times) != len(frames) or np.any(np.diff(kf_times) < 0):
        raise ValueError('keyframe times must be one per keyframe and non-decreasing')
    if limits.shape != (len(names),) or not np.all(limits > 0):
        raise ValueError('velocity_limits must be one positive speed per joint')


def sampled_motion(joint_names, spline, knots, sample_period, stretch=1.0, locks=None,
                   waypoints=None):
    """
    Return the PlannedMotion of a C1 piecewise-cubic ``spline`` with waypoints ``knots``.

    The controllers get a point every ``sample_period`` and at every knot, so that one
    interpolating cubic Hermite splines between the points reproduces ``spline`` exactly
    (each piece of a cubic spline is the cubic of its two ends' values and slopes).
    ``locks`` columns are commanded at their angle at every point, still.
    ``waypoints`` are the poses at the knots (default: the spline's).
    """
    names = tuple(joint_names)
    knots = np.asarray(knots, dtype=float)
    locks = {j: float(a) for j, a in (locks or {}).items() if j in names}
    grid = np.arange(knots[0], knots[-1], sample_period)[1:]
    sample_t = np.union1d(grid, knots)
    sample_t = sample_t[np.concatenate([[True], np.diff(sample_t) > 1e-6])]
    sample_t[-1] = knots[-1]
    positions = spline(sample_t)
    velocities = spline.derivative()(sample_t)
    velocities[-1] = 0.0
    for joint, angle in locks.items():
        positions[:, names.index(joint)] = angle
        velocities[:, names.index(joint)] = 0.0
    waypoints = spline(knots) if waypoints is None else np.asarray(waypoints, dtype=float)
    return PlannedMotion(names, sample_t, positions, velocities, knots, waypoints,
                         float(stretch), locks, spline)
