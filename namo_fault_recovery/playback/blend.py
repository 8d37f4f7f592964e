"""
From where the arm is onto another trajectory, mid-motion (no ROS).

When a joint sticks mid-play the arm is somewhere on the old trajectory, moving, and
the reconfigured gesture is another trajectory of the same gesture.  Three pieces:

- :func:`resume`: the rest of a planned motion from one of its instants (time 0 =
  now), some joints held where they are: what the arm does while the reconfigured
  library is on its way;
- :func:`phase_time`: the instant of another plan of the same gesture at the same
  phase (the same fraction of the same segment between keyframes), so the new gesture
  goes on from where the old one was, not from its beginning;
- :func:`blend`: from the measured pose and velocity onto a target trajectory at a
  given instant.  The command is the target plus a correction that decays from the
  measured offset to zero (a quintic: zero correction, speed and acceleration at its
  end, so the command joins the target smoothly), over the shortest duration, found by
  search, for which the command stays within every joint's velocity limit and
  acceleration limit (or the target's own acceleration, where the target itself is
  harder).  A minimum-jerk correction takes 1.2 times a bang-bang one under an
  acceleration limit: time-optimal-ish, and smooth.  Held joints stay exactly where
  they are held throughout.

All three return a :class:`~.timing.PlannedMotion` that starts now, sampled so that a
controller interpolating cubic Hermite splines between its points reproduces it.
"""

from dataclasses import dataclass
import math

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from .timing import MIN_SEGMENT, sampled_motion

BLEND_STEP = 0.02         # s between the knots of a blend (the quintic, sampled)
MIN_BLEND = 0.04          # s: the shortest blend
MAX_BLEND = 10.0          # s: the longest blend searched
_GROWTH = 1.15            # the search grows the duration by this factor per try
_BISECTIONS = 6
_LIMIT_MARGIN = 1.0 + 1e-6
_AT_REST = 1e-9


@dataclass(frozen=True)
class BlendLimits:
    """Per joint (in the plan's order): speed limit (rad/s) and acceleration limit (rad/s^2)."""

    velocity: np.ndarray
    acceleration: np.ndarray

    def __post_init__(self):
        """Refuse limits that cannot time a blend."""
        for name in ('velocity', 'acceleration'):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.ndim != 1 or not np.all(value > 0) or not np.all(np.isfinite(value)):
                raise ValueError(f'blend {name} limits must be finite and > 0, got {value}')
            object.__setattr__(self, name, value)


def _hold(q, v, names, holds):
    for joint, angle in (holds or {}).items():
        if joint in names:
            q[..., names.index(joint)] = angle
            v[..., names.index(joint)] = 0.0
    return q, v


def resume(plan, t, holds=None, sample_period=0.05):
    """
    Return the rest of ``plan`` from its time ``t`` (time 0 = now), ``holds`` held.

    ``holds`` maps joint names to angles (rad) commanded at every point; the other
    joints follow ``plan`` exactly from ``t`` on (past its end: its last pose).
    """
    names = plan.joint_names
    t = float(np.clip(t, 0.0, plan.duration))
    later = plan.waypoint_times[plan.waypoint_times > t + 1e-6]
    knots = np.concatenate([[t], later]) if len(later) else np.array([t, t + MIN_SEGMENT])
    q, v = _hold(plan.command_at(knots), plan.velocity_at(knots), names, holds)
    spline = CubicHermiteSpline(knots - t, q, v, axis=0)
    return sampled_motion(names, spline, knots - t, sample_period, plan.stretch,
                          dict(plan.locks, **(holds or {})))


def phase_time(source, target, t):
    """
    Return the time of ``target`` at the phase of time ``t`` in ``source``.

    Both are plans of one gesture (the same keyframes, maybe reconfigured and timed
    otherwise): the phase is the segment between waypoints and the fraction of it.
    Plans with different numbers of waypoints map in proportion to their durations.
    """
    t = float(np.clip(t, 0.0, source.duration))
    a, b = source.waypoint_times, target.waypoint_times
    if len(a) != len(b) or len(a) < 2:
        return t * target.duration / source.duration if source.duration > 0 else 0.0
    return float(np.interp(np.interp(t, a, np.arange(len(a))), np.arange(len(b)), b))


def _quintic(e0, ed0, duration, tau):
    """Return (e, e', e'') at ``tau`` (n,) of the correction from (e0, ed0) to rest at zero."""
    s = np.clip(np.asarray(tau, dtype=float) / duration, 0.0, 1.0)[:, None]
    g = 1 - 10 * s**3 + 15 * s**4 - 6 * s**5
    g1 = (-30 * s**2 + 60 * s**3 - 30 * s**4) / duration
    g2 = (-60 * s + 180 * s**2 - 120 * s**3) / duration**2
    h = (s - 6 * s**3 + 8 * s**4 - 3 * s**5) * duration
    h1 = 1 - 18 * s**2 + 32 * s**3 - 15 * s**4
    h2 = (-36 * s + 96 * s**2 - 60 * s**3) / duration
    return e0 * g + ed0 * h, e0 * g1 + ed0 * h1, e0 * g2 + ed0 * h2


def _knots(target, t0, duration):
    """Knots of a blend of ``duration``: a BLEND_STEP grid plus the target's own knots."""
    n = max(2, int(math.ceil(duration / BLEND_STEP)) + 1)
    inner = target.waypoint_times - t0
    inner = inner[(inner > 1e-6) & (inner < duration - 1e-6)]
    return np.union1d(np.linspace(0.0, duration, n), inner)


def _within_limits(target, t0, e0, ed0, duration, limits):
    """Return True if the blend of ``duration`` stays within the limits (checked densely)."""
    knots = _knots(target, t0, duration)
    tau = np.union1d(knots, (knots[:-1] + knots[1:]) / 2)
    e, e1, e2 = _quintic(e0, ed0, duration, tau)
    speed = np.abs(target.velocity_at(t0 + tau) + e1)
    own = np.abs(target.acceleration_at(t0 + tau))
    accel = np.abs(own + e2)
    return bool(np.all(speed <= limits.velocity * _LIMIT_MARGIN)
                and np.all(accel <= np.maximum(limits.acceleration, own) * _LIMIT_MARGIN))


def blend(target, t0, q0, v0, limits, holds=None, sample_period=0.05):
    """
    Return (motion, duration): from ``q0`` at ``v0`` onto ``target`` at its time ``t0``.

    ``motion`` starts now at the measured pose and velocity, follows ``target`` from
    ``t0 + duration`` on (time ``duration`` of ``motion``), and ends where ``target``
    ends; ``holds`` (joint -> angle) are commanded at their angle throughout.  When no
    duration up to MAX_BLEND fits the limits, MAX_BLEND is used and ``duration`` is
    returned negative (so that a caller can say so).
    """
    names = target.joint_names
    t0 = float(np.clip(t0, 0.0, target.duration))
    r0, rd0 = target.command_at(t0), target.velocity_at(t0)
    e0, ed0 = np.asarray(q0, dtype=float) - r0, np.asarray(v0, dtype=float) - rd0
    e0, ed0 = _hold(e0, ed0, names, dict.fromkeys(holds or {}, 0.0))
    if np.all(np.abs(e0) < _AT_REST) and np.all(np.abs(ed0) < _AT_REST):
        return resume(target, t0, holds, sample_period), 0.0
    duration, fits = _search(target, t0, e0, ed0, limits)
    knots = _knots(target, t0, duration)
    e, e1, _ = _quintic(e0, ed0, duration, knots)
    q, v = _hold(target.command_at(t0 + knots) + e, target.velocity_at(t0 + knots) + e1,
                 names, holds)
    later = target.waypoint_times[target.waypoint_times > t0 + duration + 1e-6]
    if len(later):       # then the target itself: its pieces are cubics, kept as they are
        q_later, v_later = _hold(target.command_at(later), target.velocity_at(later),
                                 names, holds)
        q, v = np.vstack([q, q_later]), np.vstack([v, v_later])
        knots = np.concatenate([knots, later - t0])
    spline = CubicHermiteSpline(knots, q, v, axis=0)
    motion = sampled_motion(names, spline, knots, sample_period, target.stretch,
                            dict(target.locks, **(holds or {})))
    return motion, duration if fits else -duration


def _search(target, t0, e0, ed0, limits):
    """
    Return (duration, fits): the shortest duration found within the limits, else MAX_BLEND.

    Grows the duration from MIN_BLEND until the blend fits, then bisects between the
    last misfit and it.
    """
    low = high = MIN_BLEND
    while not _within_limits(target, t0, e0, ed0, high, limits):
        if high >= MAX_BLEND:
            return MAX_BLEND, False
        low, high = high, min(MAX_BLEND, high * _GROWTH)
    if high == low:
        return high, True
    for _ in range(_BISECTIONS):
        middle = 0.5 * (low + high)
        if _within_limits(target, t0, e0, ed0, middle, limits):
            high = middle
        else:
            low = middle
    return high, True
