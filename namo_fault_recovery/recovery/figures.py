"""
The figures of an adapted motion, as a :class:`~.result.GestureResult`, and its fallback.

:func:`describe_motion` scores a motion's published points against their designs
(worst and mean score, the breakdown at the worst point, fingertip error, joint jumps,
collisions at every point, Kriging-interpolated ones included);
:func:`no_worse_than_locked` publishes the design with the locks applied instead of a
motion that scores worse, unless that design collides and the motion does not (or
collides less).  Used by :mod:`.motion`; free of ROS.
"""

from dataclasses import replace

import numpy as np

from . import pacing
from .result import CUT_SHORT, GestureResult
from ..model.kinematics import batch_forward, split_arms
from ..model.robot import ARMS
from ..objective.collision import CollisionModel
from ..objective.score import gesture_targets

LABELS = {'kriging': '{k} typical points + Kriging',
          'per_point': 'every point explored in order',
          'trajectory': '{k} typical points + Kriging, then every point optimised at once',
          'keyframes': 'every keyframe explored'}
COLLIDES_WARNING = 'WARNING: the pose still collides'


def largest_jump(q):
    """Return the largest joint step (deg) between successive rows of ``q`` (rad)."""
    if len(q) < 2:
        return 0.0
    return float(np.degrees(np.abs(np.diff(q, axis=0))).max())


def collisions(model, checker, ids, q_r, q_l):
    """Return (any point collides, the capsule pairs that touch) for a motion."""
    if checker is None:
        return False, ()
    lm_r, lm_l = batch_forward(model, q_r, 'right'), batch_forward(model, q_l, 'left')
    collides = bool(checker.collides(lm_r, lm_l, ids).any())
    pairs = tuple(dict.fromkeys(p for row in checker.colliding_pairs(lm_r, lm_l, ids)
                                for p in row))
    return collides, pairs


def describe_motion(ctx, motion, picks) -> GestureResult:
    """
    Return the :class:`GestureResult` of one adapted motion (``motion``: a ``_Motion``).

    ``ctx`` holds the run's models, scorer and collision checker; ``picks`` are the
    motion's typical points.  ``wall_time`` is the run's, set by the caller when the run
    ends (:func:`.motion.adapt_library`).
    """
    m, gesture = motion, motion.gesture
    before = ctx.scorer.evaluate(m.base_r, m.base_l, m.ids)
    after, parts = ctx.scorer.evaluate(m.q_r, m.q_l, m.ids, breakdown=True)
    worst = int(np.argmax(after))
    collides, pairs = collisions(ctx.model, ctx.checker, m.ids, m.q_r, m.q_l)
    # The fingertip's distance to the design, the larger hand's: as the score measures it
    # (on the changed model, against the design, moved back by a torso held leaned).
    err_before = ctx.scorer.tip_error(m.base_r, m.base_l, m.ids)
    err_after = ctx.scorer.tip_error(m.q_r, m.q_l, m.ids)
    searched = m.searched
    if searched is not None and m.how == 'keyframes':
        message = searched.message
    else:
        message = (f'{gesture.name}: {LABELS[m.how].format(k=len(picks))}; '
                   f'mean score {after.mean():.2f}')
        if m.status == 'deadline':
            message += '; deadline reached, best result so far used'
        elif m.cut:
            message += (f'; the whole-trajectory pass was cut short ({m.cut}), the best '
                        f'trajectory so far used')
        if collides:                  # as the keyframe search's message says it
            message += f'; {COLLIDES_WARNING}'
    return GestureResult(
        name=gesture.name, times=tuple(float(kf.time_from_start) for kf in gesture.keyframes),
        positions=tuple(tuple(float(a) for a in row)
                        for row in np.concatenate((m.q_r, m.q_l), axis=1)),
        right_joints=int(m.q_r.shape[1]),
        score_before=float(before.max()), score_after=float(after.max()),
        status=str(m.status), message=message, collides=collides,
        breakdown={c: float(v[worst]) for c, v in parts.items() if c not in ARMS},
        stage=int(searched.stage) if searched is not None else 1,
        colliding_pairs=tuple(str(p) for p in pairs), method=m.how,
        typical_points=len(picks), tip_error_mm=float(err_after.mean()),
        max_jump_deg=largest_jump(np.concatenate((m.q_r, m.q_l), axis=1)),
        score_before_mean=float(before.mean()), score_mean=float(after.mean()),
        stage1_score=None if searched is None else float(searched.stage1_score),
        expansion_stage=int(m.stage), free_joints=tuple(str(j) for j in m.free),
        nfev=int(m.nfev), typical_indices=tuple(int(i) for i in picks),
        kriging_sigma_deg=tuple(float(v) for v in m.sigma),
        tip_error_before_mm=float(err_before.mean()),
        tip_error_max_mm=float(err_after.max()),
        max_jump_designed_deg=largest_jump(m.design),
        max_jump_before_deg=largest_jump(np.concatenate((m.base_r, m.base_l), axis=1)),
        speed_ratio=motion_speed_ratio(ctx.robot, gesture,
                                       np.concatenate((m.q_r, m.q_l), axis=1)))


def motion_speed_ratio(robot, gesture, q):
    """Return :func:`.pacing.speed_ratio` of angles ``q`` (K, J) at ``gesture``'s times."""
    return pacing.speed_ratio(robot.joint_velocity_limits,
                              [kf.time_from_start for kf in gesture.keyframes], q)


def no_worse_than_locked(robot, gesture, result, locks, settings) -> GestureResult:
    """
    Return ``result``, or the locked design if that scores better and collides no more.

    A run that the deadline (or a cancel) stops early can end with a motion that scores
    worse than no adaptation at all (typical points half-solved, then Kriging spreads
    the half-made corrections).  The design with the failed joints at their locks
    (``score_before``) is then published instead, checked for collisions like any
    other result, and the message says so.  A search can also end worse than the
    locked design on purpose: when the locks drive that design into a self-collision,
    the keyframe search keeps the best collision-free candidate (``keyframes._solve``).
    So the locked design is taken by the rule of ``_solve``: if it is clear, or if both
    collide and it penetrates no deeper (summed over the points and pairs); a clear
    result is never traded for a colliding design.
    """
    if not result.score_after > result.score_before:
        return result
    cols = {robot.joint_names.index(j): float(a) for j, a in locks.items()}
    positions = tuple(tuple(cols.get(k, float(a)) for k, a in enumerate(kf.positions()))
                      for kf in gesture.keyframes)
    collides, pairs = result.collides, result.colliding_pairs
    if settings.collision_check:
        model = robot.changed_model(settings.tool_length_mm, settings.tool_arm)
        checker = CollisionModel(model, gesture_targets(gesture), robot.capsules)
        hit_result, pen_result, _ = contact(model, checker, result.positions)
        collides, pen, pairs = contact(model, checker, positions)
        if collides and (not hit_result or pen > pen_result):
            deeper = ' deeper' if hit_result else ''
            note = (f'the design with the locks applied scores better '
                    f'({result.score_before:.2f}) but collides{deeper} '
                    f'({", ".join(pairs)}); not published')
            return replace(result, message=_joined(result.message, note))
    return replace(result, positions=positions, score_after=result.score_before,
                   score_mean=result.score_before_mean,
                   tip_error_mm=result.tip_error_before_mm,
                   max_jump_deg=result.max_jump_before_deg, collides=collides,
                   speed_ratio=motion_speed_ratio(robot, gesture, np.array(positions)),
                   colliding_pairs=pairs, breakdown={},
                   message=_locked_message(result, collides))


def contact(model, checker, positions):
    """Return (any point collides, total penetration in mm, the pairs that touch)."""
    q = np.array(positions, dtype=float)
    q_r, q_l = split_arms(model, q)
    lm_r = batch_forward(model, q_r, 'right')
    lm_l = batch_forward(model, q_l, 'left')
    rows = np.arange(len(q))
    collides = bool(np.any(checker.collides(lm_r, lm_l, rows)))
    pen = float(checker.penetration(lm_r, lm_l, rows).sum())
    pairs = tuple(sorted({str(p) for names in checker.colliding_pairs(lm_r, lm_l, rows)
                          for p in names}))
    return collides, pen, pairs


def _joined(message, note):
    """Return ``message`` with ``note`` appended."""
    return f'{message}; {note}' if message else note


def _locked_message(result, collides):
    """Return ``result``'s message for publishing the locked design in its place."""
    parts = [p for p in (result.message or '').split('; ') if p and p != COLLIDES_WARNING]
    if result.status in CUT_SHORT:
        parts.append('the search was cut short before it beat the design with the locks '
                     'applied; that design is published')
    else:
        parts.append('the adapted pose scored worse than the design with the locks '
                     'applied; that design is published')
    if collides:
        parts.append(COLLIDES_WARNING)
    return '; '.join(parts)
