"""
The joints' velocity limits between keyframes, as constraints of the search.

The player (:mod:`~namo_fault_recovery.playback.timing`) joins a gesture's keyframes
by a C1 cubic Hermite spline, with PCHIP slopes at the inner waypoints and zero
velocity at both ends, and stretches every segment on which a joint's speed exceeds
its limit (``robot.joint_velocity_limits``): such a gesture is not played as designed.  The
engine publishes only gestures the player does not stretch, at any seed and budget.

Why a step bound suffices: a PCHIP slope at an inner waypoint is zero or a weighted
harmonic mean of the secant slopes on either side, so it lies between them; on a
segment whose secant slope is ``d`` and whose end slopes lie between 0 and ``m`` (with
the sign of ``d``), the Hermite cubic's speed never exceeds ``max(m, 1.5 |d|)``.  So
when every joint's keyframe-to-keyframe speed ``|dq| / dt`` stays within its limit over
:data:`PEAK_FACTOR` (1.5), the spline's speed stays within the limit everywhere (a
wave that turns back at every keyframe, Namo's Bye, reaches exactly 1.5 times its
secant speed).  The approach from the measured pose is the player's, at its
``approach_velocity`` (0.5 rad/s, below every Namo limit over 1.5).

The constraint on a motion of keyframes ``q`` (K, J) is therefore
``|q[k + 1, j] - q[k, j]| <= limits[k, j]`` (:func:`step_limits`), a convex set.  A
design that itself steps further keeps its own steps as their limits, so that the
locked design (failed joints at their locks, clipped into the joint limits) is always
feasible: constants and clipping never lengthen a step.  The search keeps to it with
three constructions, each feasible by construction: :func:`chain_clip` (each keyframe
clipped into its predecessor's reach), :func:`shifted` (the design's steps carried from
one solved keyframe) and :func:`tube` (a box per keyframe around a feasible motion
within which every choice stays feasible).  The robot gives no acceleration limits, so
there are none to keep.  Free of ROS.
"""

import numpy as np

PEAK_FACTOR = 1.5     # the player's spline peaks at most 1.5 x the keyframe-to-keyframe speed
_TOLERANCE = 1e-9     # rad: rounding allowed on a step limit


def _gaps(times):
    return np.maximum(np.diff(np.asarray(times, dtype=float)), 0.0)


def step_limits(velocity_limits, times, design):
    """
    Return the largest step (rad) each joint may take between keyframes, (K - 1, J).

    ``velocity_limits`` (rad/s: one per column of ``design``, as
    :attr:`~..model.robot.RobotJoints.joint_velocity_limits`),
    ``times`` (K,) the keyframes' time_from_start and ``design`` (K, J) the designed
    angles: ``dt * limit / PEAK_FACTOR``, or the designed step where that is larger.
    """
    design = np.asarray(design, dtype=float)
    limits = _per_column(velocity_limits, design.shape[1])
    reach = _gaps(times)[:, None] * limits / PEAK_FACTOR
    return np.maximum(reach, np.abs(np.diff(design, axis=0)))


def _per_column(velocity_limits, width):
    """Return the limits as (width,), or raise ValueError: one per column, none repeated."""
    limits = np.asarray(velocity_limits, dtype=float).ravel()
    if len(limits) != width:
        raise ValueError(f'velocity_limits: expected one per joint column ({width}), got '
                         f'{len(limits)}; pass robot.joint_velocity_limits')
    return limits


def speed_ratio(velocity_limits, times, q):
    """
    Return the playability figure of a motion: its peak speed bound over the limit.

    The largest ``PEAK_FACTOR * |dq| / (dt * limit)`` over the joints and segments of
    ``q`` (K, J) at ``times`` (K,): at most 1 means the player plays the motion as
    timed; 0 for a single keyframe.  A step over no time is infinitely fast.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if len(q) < 2:
        return 0.0
    step = np.abs(np.diff(q, axis=0))
    room = _gaps(times)[:, None] * _per_column(velocity_limits, q.shape[1])
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = np.where(step > _TOLERANCE, PEAK_FACTOR * step / room, 0.0)
    return float(np.max(ratio))


def excess(q, limits):
    """Return the largest step of ``q`` (K, J) beyond ``limits`` (K - 1, J), in rad (<= 0: ok)."""
    q = np.asarray(q, dtype=float)
    if len(q) < 2:
        return 0.0
    return float(np.max(np.abs(np.diff(q, axis=0)) - limits))


def feasible(q, limits):
    """Return True if no step of ``q`` (K, J) is beyond ``limits`` (K - 1, J)."""
    return excess(q, limits) <= _TOLERANCE


def chain_clip(q, limits, lower, upper):
    """
    Return ``q`` (K, J) with each keyframe clipped into its predecessor's reach.

    The first keyframe is kept; keyframe k is clipped into ``q'[k - 1] +- limits[k - 1]``
    and the joint limits ``lower``/``upper`` (J,), which contain ``q'[k - 1]``, so the
    result is feasible and equals ``q`` where ``q`` already was.
    """
    out = np.clip(np.array(q, dtype=float), lower, upper)
    for k in range(1, len(out)):
        near = np.clip(out[k], out[k - 1] - limits[k - 1], out[k - 1] + limits[k - 1])
        out[k] = np.clip(near, lower, upper)
    return out


def shifted(base, q, m, lower, upper):
    """
    Return the feasible motion ``base`` (K, J) moved to pass through ``q[m]``.

    ``base + (q[m] - base[m])``, clipped into the joint limits: every step is a step of
    ``base``, so it is feasible whenever ``base`` is; where the design locks a joint
    (``q[m] == base[m]``) it stays locked.
    """
    return np.clip(base + (q[m] - base[m]), lower, upper)


def tube(q, limits, lower, upper):
    """
    Return per-keyframe boxes (lower, upper), (K, J), around a feasible motion ``q``.

    Each keyframe may move by half the slack of its tighter neighbouring step, so any
    choice of one point per box is feasible (and ``q`` lies in every box).
    """
    q = np.asarray(q, dtype=float)
    slack = np.maximum(limits - np.abs(np.diff(q, axis=0)), 0.0)
    half = np.full(q.shape, np.inf)
    half[:-1] = np.minimum(half[:-1], slack)
    half[1:] = np.minimum(half[1:], slack)
    half = 0.5 * np.where(np.isfinite(half), half, 0.0)
    return np.clip(q - half, lower, upper), np.clip(q + half, lower, upper)


def candidates(q, base, limits, lower, upper, picks=None):
    """
    Return feasible motions near ``q`` (K, J), (N, K, J): the starts of a repair.

    :func:`chain_clip` of ``q`` forwards and backwards, the feasible ``base`` (K, J)
    itself, and ``base`` :func:`shifted` through each keyframe of ``q`` in ``picks``
    (None: all): every one feasible by construction.
    """
    q = np.asarray(q, dtype=float)
    base = np.asarray(base, dtype=float)
    picks = range(len(q)) if picks is None else picks
    cands = [chain_clip(q, limits, lower, upper),
             chain_clip(q[::-1], limits[::-1], lower, upper)[::-1], base]
    cands += [shifted(base, q, m, lower, upper) for m in picks]
    return np.stack(cands)


def repair(q, base, limits, lower, upper, value, picks=None, extra=()):
    """
    Return the best feasible motion near ``q`` (K, J) and its keyframe values (K,).

    The candidates are those of :func:`candidates`, and ``extra`` motions (e.g. the
    candidates polished keyframe by keyframe) clipped into reach by :func:`chain_clip`:
    every one feasible.  ``value`` maps candidates (N, K, J) to keyframe values (N, K)
    in one call; the candidate with the lowest worst keyframe wins (then the lowest
    sum; the earlier on ties).
    """
    cands = list(candidates(q, base, limits, lower, upper, picks))
    cands += [chain_clip(c, limits, lower, upper) for c in extra]
    cands = np.stack(cands)
    values = np.asarray(value(cands), dtype=float)
    values = np.where(np.isnan(values), np.inf, values)
    best = int(np.lexsort((np.arange(len(cands)), values.sum(axis=1), values.max(axis=1)))[0])
    return cands[best], values[best]


def reach_boxes(q, limits, lower, upper, parity):
    """
    Return boxes for every other keyframe of ``q`` (K, J) within its neighbours' reach.

    The keyframes ``parity``, ``parity + 2``, ... may each move anywhere within
    ``lower``/``upper`` and ``limits`` of both its (kept) neighbours: any choice in
    these boxes, with the other keyframes kept, is a feasible motion.  Returns (rows,
    low, high) with boxes (len(rows), J), or None where the kept neighbours of a
    keyframe are too far apart for any box.
    """
    q = np.asarray(q, dtype=float)
    rows = np.arange(parity, len(q), 2)
    low = np.broadcast_to(lower, (len(rows), q.shape[1])).copy()
    high = np.broadcast_to(upper, (len(rows), q.shape[1])).copy()
    for i, k in enumerate(rows):
        if k > 0:
            low[i] = np.maximum(low[i], q[k - 1] - limits[k - 1])
            high[i] = np.minimum(high[i], q[k - 1] + limits[k - 1])
        if k + 1 < len(q):
            low[i] = np.maximum(low[i], q[k + 1] - limits[k])
            high[i] = np.minimum(high[i], q[k + 1] + limits[k])
    if len(rows) == 0 or np.any(low > high):
        return None
    return rows, low, high
