"""
The engine's one entry point: a fault set and settings in, an adapted library out.

:func:`recover` is what the node, ``namo-recovery solve``, the benchmarks and the Python
API call.  It takes the robot, the reference library, the fault set, a
:class:`RecoverySettings` (one field per node parameter, with the node's defaults), a
seed and a :class:`~namo_fault_recovery.optimize.base.Clock` that owns the deadline and
the cancel flag, and returns one :class:`~.result.LibraryResult`.  With the same inputs,
the same seed and no deadline it returns the same library whoever asks.  Free of ROS::

    from namo_fault_recovery.recovery.engine import recover, RecoverySettings
    result = recover(robot, library, {'right_arm_joint2': None}, seed=0)
    result.locks, result['wai'].score_after, result.total_score
"""

from dataclasses import replace
import math
import time

import numpy as np

from .locks import frozen_arms
from .motion import adapt_library, DEFAULT_STAY_CLOSE, typical_points
from .result import GestureResult, LibraryResult, reference_result
from .settings import RecoverySettings
from ..model.kinematics import batch_forward
from ..model.robot import ARMS, N_JOINTS
from ..objective.collision import CollisionModel
from ..objective.score import gesture_targets, SimilarityScore
from ..optimize.base import Clock


def structure_changed(faults, settings):
    """Return True if the library must be adapted: a fault, or a tool in a hand."""
    return bool(faults) or settings.tool_length_mm > 0


def recover(robot, library, faults=None, settings=None, *, seed=None, clock=None,
            measured=None, quantisations=None, optimizer_overrides=None):
    """
    Adapt ``library`` to a fault set (and a tool); return a :class:`LibraryResult`.

    ``faults`` maps joint names to a lock angle (rad) or None (the lock strategy chooses).
    ``measured`` maps joints to their measured angles, for the ``measured`` strategy.
    ``clock`` owns the deadline and the cancel flag; None runs with
    ``settings.deadline_sec`` from now, and ``Clock(None)`` runs without a deadline.
    ``quantisations`` are the library's typical points, if the caller keeps them (they
    depend on the library and ``vq_distortion_mm`` only).  ``seed`` None draws one; the
    result records it.  ``optimizer_overrides`` change settings of the optimiser's
    preset (e.g. ``{'max_cycles': 10 ** 9}`` so that a deadline binds); they are for
    benchmarks, not node parameters.

    A library of single poses is the paper's problem and is solved as such; when the
    library holds a motion (a gesture of several keyframes) the explored keyframes are
    also drawn gently towards their designed poses (``DEFAULT_STAY_CLOSE`` per deg^2),
    so that neighbouring keyframes stay on one redundant branch.
    """
    settings = settings or RecoverySettings()
    faults = dict(faults or {})
    if clock is None:
        clock = Clock(settings.deadline_sec)
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    seed = int(seed)
    public = settings.public()
    budget = None if clock.end is None else float(clock.end - clock.start)
    if not structure_changed(faults, settings):
        return reference_result(library, budget, public, seed)
    began = time.monotonic()
    if quantisations is None:
        quantisations = typical_points(robot, library, settings.vq_distortion_mm, clock=clock)
    motion = any(len(g.keyframes) > 1 for g in library)
    report = adapt_library(
        robot, library, faults, method=settings.trajectory_method,
        tool_mm=settings.tool_length_mm, tool_arm=settings.tool_arm,
        distortion_mm=settings.vq_distortion_mm, continuity=settings.continuity_weight,
        quantisations=quantisations, algorithm=settings.optimizer,
        preset=settings.optimizer_preset, settings=optimizer_overrides or None,
        clock=clock, seed=seed, weights=settings.weights,
        lock_strategy=settings.lock_strategy, measured=measured,
        bimanual=settings.bimanual, collision=settings.collision_check,
        stay_close=DEFAULT_STAY_CLOSE if motion else 0.0)
    wall = time.monotonic() - began
    engine = report.typical_result
    breakdowns = worst_breakdowns(robot, library, report.gestures, settings)
    gestures = []
    for g, breakdown in zip(report.gestures, breakdowns):
        e = engine[g.name] if engine is not None else None
        gestures.append(GestureResult(
            name=g.name,
            times=tuple(float(kf.time_from_start) for kf in g.keyframes),
            positions=tuple(tuple(float(a) for a in kf.positions()) for kf in g.keyframes),
            score_before=float(g.score_before_max),
            score_after=float(g.score_max),
            wall_time=float(wall), status=str(g.status),
            message=str(e.message if e and g.method == 'keyframes' else g.message),
            collides=bool(g.collides),
            breakdown=breakdown,
            stage=int(e.stage if e else 1),
            colliding_pairs=tuple(str(p) for p in g.colliding_pairs),
            method=g.method, typical_points=len(g.typical),
            tip_error_mm=float(g.tip_error_mean_mm),
            max_jump_deg=float(g.jump_after_deg),
            score_before_mean=float(g.score_before), score_mean=float(g.score_mean),
            stage1_score=None if e is None else float(e.stage1_score),
            expansion_stage=int(g.expansion_stage),
            free_joints=tuple(str(j) for j in g.free_joints), nfev=int(g.nfev),
            typical_indices=tuple(int(i) for i in g.typical),
            kriging_sigma_deg=tuple(float(v) for v in g.kriging_sigma_deg),
            tip_error_before_mm=float(g.tip_error_before_mm),
            tip_error_max_mm=float(g.tip_error_max_mm),
            max_jump_designed_deg=float(g.jump_designed_deg),
            max_jump_before_deg=float(g.jump_before_deg)))
    gestures = [no_worse_than_locked(robot, library[g.name], g, report.locks, settings)
                for g in gestures]
    # ``per_point`` runs no typical-point engine: its statuses say it all.
    success = (report.deadline_met and (engine is None or engine.success)
               and all(math.isfinite(g.score_after) for g in gestures))
    return LibraryResult(
        gestures=tuple(gestures), faults=faults,
        locks={j: float(a) for j, a in report.locks.items()},
        frozen_arms=frozen_arms(robot, report.locks),
        wall_time=float(wall), deadline=budget,
        deadline_met=bool(report.deadline_met), success=bool(success),
        cancelled=report.cancelled, settings=public,
        tool_mm=settings.tool_length_mm, tool_arm=settings.tool_arm,
        seed=seed, notes=tuple(str(n) for n in report.notes), nfev=int(report.nfev),
        origin='unbounded' if budget is None else 'deadline')


def no_worse_than_locked(robot, gesture, result, locks, settings):
    """
    Return ``result``, or the locked design if a cut-short search left it worse.

    A run that the deadline (or a cancel) stops early can end with a motion that scores
    worse than no adaptation at all (typical points half-solved, then Kriging spreads
    the half-made corrections).  The design with the failed joints at their locks
    (``score_before``) is then published instead, checked for collisions like any
    other result, and the message says so.
    """
    if not result.score_after > result.score_before:
        return result
    columns = {robot.joint_names.index(j): float(a) for j, a in locks.items()}
    positions = tuple(tuple(columns.get(k, float(a)) for k, a in enumerate(kf.positions()))
                      for kf in gesture.keyframes)
    collides, pairs = result.collides, result.colliding_pairs
    if settings.collision_check:
        model = robot.with_tool(settings.tool_length_mm, settings.tool_arm)
        checker = CollisionModel(model, gesture_targets(gesture), robot.capsules)
        q = np.array(positions)
        lm_r = batch_forward(model, q[:, :N_JOINTS], 'right')
        lm_l = batch_forward(model, q[:, N_JOINTS:], 'left')
        rows = np.arange(len(q))
        collides = bool(np.any(checker.collides(lm_r, lm_l, rows)))
        pairs = tuple(sorted({str(p) for names in checker.colliding_pairs(lm_r, lm_l, rows)
                              for p in names}))
    note = ('the search was cut short before it beat the design with the locks applied; '
            'that design is published')
    return replace(result, positions=positions, score_after=result.score_before,
                   score_mean=result.score_before_mean,
                   tip_error_mm=result.tip_error_before_mm,
                   max_jump_deg=result.max_jump_before_deg, collides=collides,
                   colliding_pairs=pairs, breakdown={},
                   message=f'{result.message}; {note}' if result.message else note)


def worst_breakdowns(robot, library, adapted, settings):
    """
    Return per gesture the score's components at its worst published keyframe.

    ``adapted`` are the adapted gestures (with ``keyframes``), in library order.  The
    scorer is the engine's: the tool's hand, references on the original structure.
    """
    model = robot.with_tool(settings.tool_length_mm, settings.tool_arm)
    targets = [t for g in library for t in gesture_targets(g)]
    scorer = SimilarityScore(model, targets, settings.weights, reference_robot=robot)
    q = np.array([kf.positions() for g in adapted for kf in g.keyframes])
    total, parts = scorer.evaluate(q[:, :N_JOINTS], q[:, N_JOINTS:], np.arange(len(q)),
                                   breakdown=True)
    out, offset = [], 0
    for g in adapted:
        worst = offset + int(np.argmax(total[offset:offset + len(g.keyframes)]))
        offset += len(g.keyframes)
        out.append({c: float(v[worst]) for c, v in parts.items() if c not in ARMS})
    return out
