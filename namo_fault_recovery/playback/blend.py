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
  given instant (:class:`Blend`).  Each joint rejoins the target on its own
  (:class:`Rejoin`): a limit-bound motion (full acceleration to a cruise speed, the
  cruise, full acceleration to the target's speed) that meets the target's position
  and speed at the earliest instant it can (:func:`reachable` decides whether a joint
  can be at a given state at a given time), then follows it.  The target itself may
  accelerate beyond the limit (a wave), which no longer starves the blend: the blend
  is bound by the joint's own limits, not by what the target leaves to spare.  The
  target's timeline may wait at the blend's instant (up to ``max_wait``) where that
  brings the last joint onto it sooner: a far joint then does not chase a target that
  moves away.  Where no rejoin fits (not expected), one minimum-jerk (quintic)
  correction for all joints of the shortest duration that fits, found by search.
  Held joints stay exactly where they are held throughout.

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
REJOIN_STEP = 0.01        # s: the grid on which each joint's first reachable instant is sought
REJOIN_SLACK = 3.0        # s searched beyond the target's end (at rest at its last pose)
WAIT_STEP = 0.05          # s: the phase waits tried
_GROWTH = 1.15            # the quintic search grows the duration by this factor per try
_BISECTIONS = 6
_BISECT_TIME = 30         # bisections of a joint's first reachable instant within a step
_BISECT_SPEED = 60        # bisections of a joint's cruise speed
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
    later = plan.knots[plan.knots > t + 1e-6]
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
    return blend(still, 0.0, q, v, limits, holds, sample_period).motion


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


def _covered(speed, v0, v1, accel, duration):
    """Return the distance of: accelerate, cruise at ``speed``, match ``v1`` (``duration``)."""
    return (speed * duration - (speed - v0) * np.abs(speed - v0) / (2 * accel)
            - (speed - v1) * np.abs(speed - v1) / (2 * accel))


def _cruise_range(v0, v1, accel, cap, duration):
    """
    Return (ok, low, high): the cruise speeds that leave time to cruise in ``duration``.

    Reaching a cruise speed and then ``v1`` takes ``(|c - v0| + |c - v1|) / accel``; the
    speeds for which that fits ``duration`` are an interval, clipped to the speed cap.
    ``ok`` is False where even going straight from ``v0`` to ``v1`` does not fit.
    """
    lo, hi = np.minimum(v0, v1), np.maximum(v0, v1)
    span = accel * duration
    low = np.maximum((lo + hi - span) / 2, -cap)
    high = np.minimum((lo + hi + span) / 2, cap)
    return (hi - lo <= span * _LIMIT_MARGIN + _AT_REST) & (low <= high), low, high


def reachable(q0, v0, q1, v1, duration, accel, cap, slack=_AT_REST):
    """
    Return where a joint can go from (q0, v0) to (q1, v1) in exactly ``duration`` seconds.

    Under ``|acceleration| <= accel`` and ``|speed| <= cap`` (arrays broadcast).  Every
    such motion can be one that accelerates to a cruise speed, cruises, and accelerates
    to ``v1``, each at full acceleration; its displacement grows with the cruise speed
    (the derivative is the time left to cruise), so the reachable displacements are the
    interval between those of the slowest and the fastest cruise that fit (within
    ``slack`` rad).
    """
    ok, low, high = _cruise_range(v0, v1, accel, cap, duration)
    d = q1 - q0
    return (ok & (_covered(low, v0, v1, accel, duration) <= d + slack)
            & (d <= _covered(high, v0, v1, accel, duration) + slack))


class Rejoin:
    """
    Per joint, the limit-bound motion onto a trajectory at the earliest instant it can.

    Joint ``j`` goes from (``q0``, ``v0``) to the target's state at its time
    ``t0 + at[j] - wait`` at play time ``at[j]`` (accelerate, cruise, match the target's
    speed, every part at the joint's acceleration limit and within its speed cap), then
    follows the target.  The target's own timeline waits ``wait`` seconds at ``t0``
    first (its phase then goes on), so that a far joint need not chase a target that
    moves away.  Each piece is a quadratic or the target's cubic, so a cubic Hermite
    controller reproduces the command exactly between knots that include ``switches``.
    """

    def __init__(self, target, t0, q0, v0, at, wait, accel, cap):
        """Solve each joint's cruise speed (it exists: ``at`` was found reachable)."""
        self.target, self.t0, self.wait = target, float(t0), float(wait)
        self.q0, self.v0 = np.asarray(q0, dtype=float), np.asarray(v0, dtype=float)
        self.at, self.accel = np.asarray(at, dtype=float), np.asarray(accel, dtype=float)
        joints = np.arange(len(self.q0))
        s = self.target_time(self.at)
        self.q1 = target.command_at(s)[joints, joints]
        self.v1 = target.velocity_at(s)[joints, joints]
        _, low, high = _cruise_range(self.v0, self.v1, self.accel, cap, self.at)
        d = self.q1 - self.q0
        for _ in range(_BISECT_SPEED):      # the displacement is monotone in the cruise
            middle = 0.5 * (low + high)
            short = _covered(middle, self.v0, self.v1, self.accel, self.at) < d
            low, high = np.where(short, middle, low), np.where(short, high, middle)
        self.cruise = 0.5 * (low + high)
        t1 = np.abs(self.cruise - self.v0) / self.accel
        t3 = np.abs(self.v1 - self.cruise) / self.accel
        self.breaks = np.stack([np.minimum(t1, self.at),
                                np.maximum(self.at - t3, np.minimum(t1, self.at)), self.at])
        self.duration = float(np.max(self.at)) if len(self.at) else 0.0
        self.switches = np.concatenate([self.breaks.ravel(), [self.wait]])

    def target_time(self, tau):
        """Return the target's time at play time(s) ``tau`` (its timeline waits first)."""
        return self.t0 + np.maximum(np.asarray(tau, dtype=float) - self.wait, 0.0)

    def __call__(self, tau):
        """Return the command (q, q', q'') (n, J) at play times ``tau`` (n,)."""
        tau = np.asarray(tau, dtype=float)
        on = self.target_time(tau)
        q, v, a = (self.target.command_at(on), self.target.velocity_at(on),
                   self.target.acceleration_at(on))
        t = tau[:, None]
        x, y = self.q0 + 0.0 * t, self.v0 + 0.0 * t
        u_now = np.zeros_like(x)
        start = np.zeros_like(self.q0)
        pieces = (np.sign(self.cruise - self.v0) * self.accel, 0.0 * self.accel,
                  np.sign(self.v1 - self.cruise) * self.accel)
        for end, u in zip(self.breaks, pieces):
            d = np.clip(t - start, 0.0, end - start)
            x, y = x + y * d + u * d ** 2 / 2, y + u * d
            u_now = np.where((t >= start) & (t < end), u, u_now)
            start = end
        rejoining = t < self.at
        return np.where(rejoining, x, q), np.where(rejoining, y, v), np.where(rejoining, u_now, a)


def _first_feasible(target, t0, q0, v0, accel, cap, waits):
    """Return (at (J,), wait) of the earliest rejoin over the phase waits tried, or None."""
    times = np.arange(0.0, max(target.duration - t0, 0.0) + REJOIN_SLACK, REJOIN_STEP)
    q1, v1 = target.command_at(t0 + times), target.velocity_at(t0 + times)     # (n, J)
    best = None
    for wait in waits:
        ok = reachable(q0, v0, q1, v1, (wait + times)[:, None], accel, cap)    # (n, J)
        if not np.all(np.any(ok, axis=0)):
            continue
        first = np.argmax(ok, axis=0)
        at = wait + times[first]
        if best is None or np.max(at) < np.max(best[0]) - 1e-9:
            best = (at, wait, first)
    if best is None:
        return None
    at, wait, first = best
    return _refine(target, t0, q0, v0, accel, cap, wait, times, first), wait


def _refine(target, t0, q0, v0, accel, cap, wait, times, first):
    """Bisect each joint's first reachable instant between its grid point and the one before."""
    joints = np.arange(len(q0))
    low, high = times[np.maximum(first - 1, 0)], times[first]
    for _ in range(_BISECT_TIME if np.any(first > 0) else 0):
        middle = np.where(first > 0, 0.5 * (low + high), high)
        s = t0 + middle
        ok = reachable(q0, v0, target.command_at(s)[joints, joints],
                       target.velocity_at(s)[joints, joints], wait + middle, accel, cap, 0.0)
        low, high = np.where(ok, low, middle), np.where(ok, middle, high)
    return wait + high


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


class _Corrected:
    """The target from ``t0`` plus a correction (the quintic fallback), as a command."""

    def __init__(self, target, t0, correction):
        """Keep the target and the correction; the target does not wait."""
        self.target, self.t0, self.correction, self.wait = target, float(t0), correction, 0.0
        self.duration, self.switches = correction.duration, correction.switches

    def target_time(self, tau):
        """Return the target's time at play time(s) ``tau``."""
        return self.t0 + np.asarray(tau, dtype=float)

    def __call__(self, tau):
        """Return the command (q, q', q'') (n, J) at play times ``tau`` (n,)."""
        on = self.target_time(tau)
        e, e1, e2 = self.correction(tau)
        return (self.target.command_at(on) + e, self.target.velocity_at(on) + e1,
                self.target.acceleration_at(on) + e2)


def _knots(command):
    """Knots of a blend: a BLEND_STEP grid, the target's own knots and the switches."""
    duration = command.duration
    n = max(2, int(math.ceil(duration / BLEND_STEP)) + 1)
    shifted = command.wait + command.target.knots - command.t0
    inner = np.concatenate([shifted, command.switches])
    inner = inner[(inner > 1e-6) & (inner < duration - 1e-6)]
    return np.union1d(np.linspace(0.0, duration, n), inner)


def _excess(command, limits, cap):
    """Return per joint whether a command leaves the limits anywhere (checked densely)."""
    knots = _knots(command)
    tau = np.union1d(knots, (knots[:-1] + knots[1:]) / 2)
    tau = np.union1d(tau, np.maximum(knots - 1e-7, 0.0))    # both sides of each knot
    _, speed, accel = command(tau)
    own = np.abs(command.target.acceleration_at(command.target_time(tau)))
    return (np.any(np.abs(speed) > cap * _LIMIT_MARGIN, axis=0)
            | np.any(np.abs(accel) > np.maximum(limits.acceleration, own) * _LIMIT_MARGIN,
                     axis=0))


@dataclass(frozen=True)
class Blend:
    """
    A blend onto a trajectory: the ``motion`` to command from now on, and its timing.

    ``duration`` (s) is when the last joint is on the target (negative when no blend
    within the limits was found up to MAX_BLEND, so that a caller can say so); the
    target's timeline waited ``wait`` seconds at the blend's instant first, so its time
    at play time ``tau`` is ``t0 + max(tau - wait, 0)``.
    """

    motion: object
    duration: float
    wait: float = 0.0


def blend(target, t0, q0, v0, limits, holds=None, sample_period=0.05, max_wait=0.0):
    """
    Return the :class:`Blend` from ``q0`` at ``v0`` onto ``target`` at its time ``t0``.

    Its motion starts now at the measured pose and velocity; each joint rejoins the
    target at the earliest instant it can (:class:`Rejoin`), the target's timeline
    waiting up to ``max_wait`` seconds at ``t0`` where that brings the last joint on it
    sooner; then the target to its end.  ``holds`` (joint -> angle) are commanded at their
    angle throughout.
    """
    names = target.joint_names
    t0 = float(np.clip(t0, 0.0, target.duration))
    q0, v0 = _hold(np.array(q0, dtype=float), np.array(v0, dtype=float), names, holds)
    e0, ed0 = q0 - target.command_at(t0), v0 - target.velocity_at(t0)
    if np.all(np.abs(e0) < _AT_REST) and np.all(np.abs(ed0) < _AT_REST):
        return Blend(resume(target, t0, holds, sample_period), 0.0)
    # A joint measured faster than its limit (a controller's overshoot at the limit)
    # cannot start slower: its limit is where it starts, and the blend slows it.
    cap = np.maximum(limits.velocity, np.abs(v0))
    waits = np.arange(0.0, max(max_wait, 0.0) + 1e-9, WAIT_STEP)
    found = _first_feasible(target, t0, q0, v0, limits.acceleration, cap, waits)
    command = fits = None
    if found is not None:
        command = Rejoin(target, t0, q0, v0, found[0], found[1], limits.acceleration, cap)
        fits = not np.any(_excess(command, limits, cap))
    if not fits:
        correction, fits = _quintic(target, t0, e0, ed0, limits, cap)
        command = _Corrected(target, t0, correction)
    return Blend(_motion(command, names, holds, sample_period),
                 command.duration if fits else -command.duration, command.wait)


def _motion(command, names, holds, sample_period):
    """Return the PlannedMotion of ``command`` and then the rest of its target."""
    target = command.target
    knots = _knots(command)
    q, v, _ = command(knots)
    q, v = _hold(q, v, names, holds)
    rejoined = command.target_time(command.duration)
    later = target.knots[target.knots > rejoined + 1e-6]
    if len(later):       # then the target itself: its pieces are cubics, kept as they are
        q_later, v_later = _hold(target.command_at(later), target.velocity_at(later),
                                 names, holds)
        q, v = np.vstack([q, q_later]), np.vstack([v, v_later])
        knots = np.concatenate([knots, command.wait + later - command.t0])
    spline = CubicHermiteSpline(knots, q, v, axis=0)
    return sampled_motion(names, spline, knots, sample_period, target.stretch,
                          dict(target.locks, **(holds or {})))


def _quintic(target, t0, e0, ed0, limits, cap):
    """
    Return (correction, fits): the shortest minimum-jerk correction within the limits.

    The fallback where no rejoin fits: grown from MIN_BLEND, then bisected; MAX_BLEND and
    ``fits`` False if none does.
    """
    def fits(duration):
        command = _Corrected(target, t0, _Quintic(e0, ed0, duration))
        return not np.any(_excess(command, limits, cap))
    low = high = MIN_BLEND
    while not fits(high):
        if high >= MAX_BLEND:
            return _Quintic(e0, ed0, MAX_BLEND), False
        low, high = high, min(MAX_BLEND, high * _GROWTH)
    for _ in range(_BISECTIONS if high > low else 0):
        middle = 0.5 * (low + high)
        low, high = (low, middle) if fits(middle) else (middle, high)
    return _Quintic(e0, ed0, high), True
