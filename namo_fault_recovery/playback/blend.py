"""
From where the arm is onto another trajectory, mid-motion (no ROS).

When a joint sticks mid-play the arm is somewhere on the old trajectory, moving, and
the reconfigured gesture is another trajectory of the same gesture.  The pieces:

- :func:`resume`: the rest of a planned motion from one of its instants (time 0 =
  now), some joints held where they are; :func:`stop`: the time-optimal stop of a
  motion at one of its instants (what the arm does while the reconfigured library is
  on its way);
- :func:`phase_time`: the instant of another plan of the same gesture at the same
  phase (the same fraction of the same segment between keyframes), so the new gesture
  goes on from where the old one was, not from its beginning;
- :func:`blend`: from the measured pose and velocity onto a target trajectory at a
  given instant.  The command is the target plus a correction that takes each joint
  from its measured offset and speed difference to zero, at rest: per joint the
  time-optimal one of a double integrator (full acceleration, a coast at the speed
  cap if reached, full deceleration), with the acceleration and speed the target
  leaves to spare under the joint's limits, so that the command stays within every
  joint's velocity limit and acceleration limit (or the target's own acceleration,
  where the target itself is harder), checked on the command itself.  A joint where it
  does not gets less, a few times; failing that, one minimum-jerk (quintic) correction
  for all joints of the shortest duration that fits, found by search.  Held joints
  stay exactly where they are held throughout.

They return a :class:`~.timing.PlannedMotion` that starts now, sampled so that a
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
_GROWTH = 1.15            # the quintic search grows the duration by this factor per try
_BISECTIONS = 6
_BANG_TRIES = 8           # bang-bang tries, each with less acceleration where it misfits
_BANG_SHRINK = 0.8
_HORIZON_TRIES = 4        # the spare-speed horizon grown to the correction this often
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


def stop(plan, t, limits, holds=None, sample_period=0.05):
    """
    Return a motion that stops ``plan`` at its time ``t`` (time 0 = now), ``holds`` held.

    From the command at ``t`` (position and speed), each joint decelerates at its
    acceleration limit to rest (the time-optimal stop), then stays there.
    """
    t = float(np.clip(t, 0.0, plan.duration))
    q, v = _hold(plan.command_at(t), plan.velocity_at(t), plan.joint_names, holds)
    rest = q + v * np.abs(v) / (2 * limits.acceleration)
    still = sampled_motion(plan.joint_names, CubicHermiteSpline(
        [0.0, MIN_SEGMENT], np.vstack([rest, rest]), np.zeros((2, len(q))), axis=0),
        [0.0, MIN_SEGMENT], sample_period, plan.stretch, dict(plan.locks, **(holds or {})))
    return blend(still, 0.0, q, v, limits, holds, sample_period)[0]


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


class _Trapezoid:
    """
    Per joint, the minimum-time correction from (e0, ed0) to rest at zero.

    Under an acceleration ``accel`` and a speed ``cap`` (per joint): full acceleration
    towards the target, a coast at the cap if it is reached, full deceleration, at rest
    at zero at ``t_end`` (a joint with nothing to correct has ``t_end`` 0): the double
    integrator's time-optimal solution.  Each piece is a quadratic, so the command (the
    target's cubic plus it) is a cubic between knots that include the switches, which a
    cubic Hermite controller reproduces exactly.
    """

    def __init__(self, e0, ed0, accel, cap):
        a, cap = np.asarray(accel, dtype=float), np.asarray(cap, dtype=float)
        sigma = e0 + ed0 * np.abs(ed0) / (2 * a)
        self.sign = np.where(sigma >= 0, 1.0, -1.0)     # solved as if towards -inf
        x, v = self.sign * e0, self.sign * ed0
        peak = np.sqrt(np.maximum(v * v / 2 + a * x, 0.0))     # without a cap
        cap = np.maximum(np.minimum(peak, cap), np.maximum(-v, 0.0))
        t1 = np.maximum((v + cap) / a, 0.0)
        x1 = x + v * t1 - a * t1 ** 2 / 2
        coast = np.maximum(x1 - cap ** 2 / (2 * a), 0.0) / np.maximum(cap, 1e-12)
        self.breaks = np.stack([t1, t1 + coast, t1 + coast + cap / a])   # (3, J)
        self.accel, self.x, self.v = a, x, v
        self.t_end = self.breaks[2]
        self.duration = float(np.max(self.t_end))
        self.switches = self.breaks.ravel()

    def __call__(self, tau):
        """Return (e, e', e'') (n, J) at times ``tau`` (n,)."""
        tau = np.asarray(tau, dtype=float)[:, None]
        a = self.accel
        x, v = self.x * np.ones_like(tau), self.v * np.ones_like(tau)
        e2 = np.zeros_like(x)
        start = np.zeros_like(self.x)
        for end, u in zip(self.breaks, (-a, 0.0 * a, a)):     # the three phases in turn
            d = np.clip(tau - start, 0.0, end - start)
            inside = (tau >= start) & (tau < end)
            x, v = x + v * d + u * d ** 2 / 2, v + u * d
            e2 = np.where(inside, u, e2)
            start = end
        done = tau >= self.t_end
        return tuple(np.where(done, 0.0, self.sign * y) for y in (x, v, e2))


class _Quintic:
    """
    One minimum-jerk correction of ``duration`` for every joint.

    Zero correction, speed and acceleration at its end: the fallback when no
    time-optimal one fits the limits.
    """

    def __init__(self, e0, ed0, duration):
        self.e0, self.ed0, self.duration = e0, ed0, float(duration)
        self.switches = np.array([])

    def __call__(self, tau):
        """Return (e, e', e'') (n, J) at times ``tau`` (n,)."""
        T = self.duration
        s = np.clip(np.asarray(tau, dtype=float) / T, 0.0, 1.0)[:, None]
        g = 1 - 10 * s**3 + 15 * s**4 - 6 * s**5
        g1 = (-30 * s**2 + 60 * s**3 - 30 * s**4) / T
        g2 = (-60 * s + 180 * s**2 - 120 * s**3) / T**2
        h = (s - 6 * s**3 + 8 * s**4 - 3 * s**5) * T
        h1 = 1 - 18 * s**2 + 32 * s**3 - 15 * s**4
        h2 = (-36 * s + 96 * s**2 - 60 * s**3) / T
        e0, ed0 = self.e0, self.ed0
        return e0 * g + ed0 * h, e0 * g1 + ed0 * h1, e0 * g2 + ed0 * h2


def _knots(target, t0, correction):
    """Knots of a blend: a BLEND_STEP grid, the target's own knots and the switches."""
    duration = correction.duration
    n = max(2, int(math.ceil(duration / BLEND_STEP)) + 1)
    inner = np.concatenate([target.waypoint_times - t0, correction.switches])
    inner = inner[(inner > 1e-6) & (inner < duration - 1e-6)]
    return np.union1d(np.linspace(0.0, duration, n), inner)


def _excess(target, t0, correction, limits):
    """Return per joint whether the blend leaves the limits anywhere (checked densely)."""
    knots = _knots(target, t0, correction)
    tau = np.union1d(knots, (knots[:-1] + knots[1:]) / 2)
    tau = np.union1d(tau, np.maximum(knots - 1e-7, 0.0))    # both sides of each knot
    _, e1, e2 = correction(tau)
    speed = np.abs(target.velocity_at(t0 + tau) + e1)
    own = target.acceleration_at(t0 + tau)
    accel = np.abs(own + e2)
    return (np.any(speed > limits.velocity * _LIMIT_MARGIN, axis=0)
            | np.any(accel > np.maximum(limits.acceleration, np.abs(own)) * _LIMIT_MARGIN,
                     axis=0))


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
    # A joint measured faster than its limit (a controller's overshoot at the limit)
    # cannot start slower: its limit is where it starts, and the correction slows it.
    limits = BlendLimits(np.maximum(limits.velocity, np.abs(np.asarray(v0, dtype=float))),
                         limits.acceleration)
    correction, fits = _correction(target, t0, e0, ed0, limits)
    duration = correction.duration
    knots = _knots(target, t0, correction)
    e, e1, _ = correction(knots)
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


def _spare(target, t0, limits, horizon):
    """Return (acceleration, speed) per joint the target leaves to spare over ``horizon``."""
    ahead = np.linspace(t0, min(target.duration, t0 + horizon), 50)
    accel = np.maximum(limits.acceleration - np.max(np.abs(target.acceleration_at(ahead)),
                                                    axis=0), 0.05 * limits.acceleration)
    cap = np.maximum(limits.velocity - np.max(np.abs(target.velocity_at(ahead)), axis=0),
                     0.05 * limits.velocity)
    return accel, cap


def _correction(target, t0, e0, ed0, limits):
    """
    Return (correction, fits): the fastest correction found within the limits.

    First the bang-bang one at each joint's acceleration limit; a joint whose blend
    leaves a limit (its speed, or the target's own acceleration adding up) gets a
    smaller acceleration, a few times.  If none fits, the quintic one of the shortest
    duration that fits (growing it from MIN_BLEND, then bisecting); MAX_BLEND and
    ``fits`` False if none does.
    """
    # What the target leaves to spare while the correction runs (not over the rest of
    # the gesture: a wave near the speed limit later would leave a crawl now): found
    # over a horizon grown to the correction's own duration.
    horizon = MIN_BLEND
    for _ in range(_HORIZON_TRIES):
        accel, cap = _spare(target, t0, limits, horizon)
        correction = _Trapezoid(e0, ed0, accel, cap)
        if correction.duration <= horizon:
            break
        horizon = correction.duration * 1.25
    for _ in range(_BANG_TRIES):
        correction = _Trapezoid(e0, ed0, accel, cap)
        bad = _excess(target, t0, correction, limits)
        if not np.any(bad):
            return correction, True
        accel = np.where(bad, accel * _BANG_SHRINK, accel)
        cap = np.where(bad, cap * _BANG_SHRINK, cap)

    def fits(duration):
        return not np.any(_excess(target, t0, _Quintic(e0, ed0, duration), limits))
    low = high = MIN_BLEND
    while not fits(high):
        if high >= MAX_BLEND:
            return _Quintic(e0, ed0, MAX_BLEND), False
        low, high = high, min(MAX_BLEND, high * _GROWTH)
    for _ in range(_BISECTIONS if high > low else 0):
        middle = 0.5 * (low + high)
        low, high = (low, middle) if fits(middle) else (middle, high)
    return _Quintic(e0, ed0, high), True
