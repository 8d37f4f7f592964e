"""
Whole-motion adaptation after a structure change (the second source paper), ROS-free.

Two methods reconfigure every point of every gesture's motion:

- ``kriging`` (the paper's): vector quantisation picks K typical points per motion
  (:mod:`.vq`), only those are explored (with the batched keyframe search of
  :mod:`.keyframes`, so lock strategies, staged DOF expansion, the healthy arm and
  the collision term all apply), and the correction vectors r = theta'' - theta found
  there are spread to every point by ordinary Kriging (:mod:`.kriging`);
- ``per_point`` (the baseline): every point is explored in order, warm-started from
  the previous point's solution plus the designed step, with a penalty on joint-space
  jumps away from it, so that the motion never flips between redundant solutions.

``auto`` (the node's) runs ``kriging`` first, which is fast, then optimises every
point of each dense motion at once from the Kriging result (:mod:`.trajectory_opt`:
one batched problem per motion, analytic gradients, a smoothness term between
neighbouring points, the collision penalty when the collision check is on) until it
converges or the deadline, keeping the best trajectory so far; the notes say when the
deadline cut it short.  A motion short enough to be explored at every keyframe is left
as the keyframe engine solved it.

:func:`adapt_library` returns a :class:`~.result.LibraryResult` (the figures of each
motion come from :mod:`.figures`); it takes the run's
:class:`~.engine.RecoverySettings` unchanged and one
:class:`~namo_fault_recovery.optimize.base.Clock`.
"""

from dataclasses import replace
import time
from typing import Optional

import numpy as np

from . import keyframes as keyframe_search
from . import pacing
from .budget import FINISH_RESERVE, PUBLISH_RESERVE, TYPICAL_SHARE, VQ_SHARE
from .figures import describe_motion, no_worse_than_locked
from .keyframes import (apply_locks, free_layout, joint_bounds, joint_set, layout_columns,
                        leaned_references, locked_sets, PACED_NOTE, pose_values,
                        PoseProblem, reconfigure_library, SearchOptions)
from .kriging import OrdinaryKriging
from .locks import frozen_arms, resolve_locks
from .result import CUT_SHORT, LibraryResult
from .trajectory_opt import (designed_step_deg, optimise_motion, optimise_trajectory,
                             TrajectoryProblem)
from .vq import quantise
from ..model.gestures import GestureLibrary
from ..model.kinematics import arm_columns, batch_forward, split_arms
from ..model.robot import ARMS
from ..objective.collision import CollisionModel
from ..objective.score import gesture_targets, SimilarityScore
from ..optimize import make_algorithm, minimize
from ..optimize.base import Clock
from ..optimize.polish import polish

METHODS = ('auto', 'kriging', 'per_point')
DEFAULT_DISTORTION_MM = 60.0   # the paper's quantisation distortion threshold
DEFAULT_MIN_POINTS = 12        # shorter motions are explored at every keyframe
DEFAULT_CONTINUITY = 0.01      # penalty per deg^2 of joint-space jump
DEFAULT_STAY_CLOSE = 1e-3      # per deg^2 away from the design, at the typical points
_SETTLED_DEG = 0.5             # a consistency sweep that moves no point more has settled
_STAGE_MARGIN = 1e-4           # a later stage must lower the worst point by this share
_MAX_SWEEPS = 6                # consistency sweeps at most (5 fixed the elbow-lock circle)


def typical_points(robot, library, vq_distortion_mm=DEFAULT_DISTORTION_MM,
                   min_points=DEFAULT_MIN_POINTS, seed=0, clock=None):
    """
    Return ``{gesture: Quantisation or None}``: the typical points of each motion.

    Motions of fewer than ``min_points`` keyframes get None (every keyframe is explored).
    The distortion is the fingertip distance (mm; both fingertips stacked for a
    two-arm motion) between a point and its typical point on the original structure,
    as in the paper.
    It depends on the designed motions only, so a caller may compute it once per
    library and pass it to :func:`adapt_library`.  With a ``clock`` (the run's
    :class:`~namo_fault_recovery.optimize.base.Clock`) the search for the fewest typical
    points gets ``VQ_SHARE`` of the time left; a motion whose search it cuts short has
    every point as a typical point (the threshold holds; only the saving is lost) and a
    ``note`` that says so; such a result is not worth caching.
    """
    clock = Clock(None) if clock is None else clock.child(share=VQ_SHARE)
    todo = [g for g in library if len(g.keyframes) >= min_points]
    out = {g.name: None for g in library}
    for n_left, gesture in zip(range(len(todo), 0, -1), todo):
        q = gesture.joint_matrix()
        tips = np.concatenate([batch_forward(robot, q[:, arm_columns(robot)[side]], side).tip
                               for side in gesture.arms], axis=1)
        # Each motion gets an equal share of what is left; unused time rolls over.
        found = quantise(np.degrees(q), vq_distortion_mm, features=tips, seed=seed,
                         clock=clock.child(share=1.0 / n_left))
        if found.note:
            found = replace(found, note=f'{gesture.name}: {found.note}')
        out[gesture.name] = found
    return out


class _Job:
    """What every adaptation run of one call shares (everything but the locks)."""

    def __init__(self, robot, library, settings, quantisations, optimizer_overrides,
                 stay_close, leans=None):
        self.robot = robot
        self.leans = leans          # gesture -> shared-joint angles held (a stuck torso)
        self.library = library
        self.settings = settings
        self.method = settings.trajectory_method
        self.quantisations = quantisations
        self.optimizer_overrides = optimizer_overrides
        self.stay_close = stay_close
        self.model = robot.changed_model(settings.tool_length_mm, settings.tool_arm)
        self.picks = {g.name: (tuple(range(len(g.keyframes)))
                               if quantisations.get(g.name) is None
                               else tuple(int(i) for i in quantisations[g.name].typical))
                      for g in library}
        self.sub = GestureLibrary(tuple(g.with_keyframes([g.keyframes[i]
                                                          for i in self.picks[g.name]])
                                        for g in library), library.source)

    def engine_options(self, lock_start=None):
        """Return the keyword arguments of the typical points' keyframe search."""
        # A motion explored at its typical points is made consistent by _consistent;
        # one explored at every keyframe shares its branches.  Only the latter are
        # published as searched: a dense motion is paced as a whole (_pace_motion), and
        # pacing its typical points took up to half of the 1 s deadline.
        shared = tuple(g.name for g in self.library if self.quantisations.get(g.name) is None)
        # A single pose has no neighbouring keyframe to stay on a branch with.
        pulled = tuple(g.name for g in self.library if len(g.keyframes) > 1)
        return {'optimizer_overrides': self.optimizer_overrides,
                'options': SearchOptions(stay_close=self.stay_close, pulled=pulled,
                                         share_branches=shared, lock_start=lock_start,
                                         pace=shared, leans=self.leans)}


def adapt_library(robot, library, faults, settings, *,
                  seed: Optional[int] = None, clock: Optional[Clock] = None, measured=None,
                  quantisations=None, optimizer_overrides=None,
                  options: Optional[SearchOptions] = None) -> LibraryResult:
    """
    Adapt every motion of ``library`` to a changed structure (faults and/or a tool).

    ``faults`` maps joint names to lock angles (rad) or None, as for
    :func:`.keyframes.reconfigure_library`, which also says how ``settings`` (the run's
    :class:`~.engine.RecoverySettings`, used unchanged), ``measured`` and
    ``optimizer_overrides`` are used; ``settings.trajectory_method`` is the method,
    ``vq_distortion_mm`` the typical points' threshold (unless ``quantisations`` are
    given, see :func:`typical_points`) and ``continuity_weight`` the penalty per deg^2
    of joint-space jump.  ``clock`` owns the deadline and the cancel flag of the whole
    run (None: ``settings.deadline_sec`` from now); every stage's budget comes from it,
    less the reserves of :mod:`.budget`.  ``lock_strategy='optimal'`` runs the
    ``average`` adaptation first (the very same run), then tries the lock angles that
    do best at the typical points, and keeps whichever adapted library has the lower
    total (the sum over motions of their worst point's score): never worse than
    ``average``.  ``options`` (:class:`~.keyframes.SearchOptions`) carries what the
    caller sets of the keyframe search: ``stay_close`` (per deg^2, default
    ``DEFAULT_STAY_CLOSE``) draws the typical points towards their design, and ``leans``
    holds a torso's lean through the gestures (a shared joint stuck).  Returns a
    :class:`~.result.LibraryResult`; a pure function of the inputs and ``seed`` up to
    where the deadline cuts the search.
    """
    start = time.monotonic()
    clock = Clock(settings.deadline_sec) if clock is None else clock
    faults = dict(faults or {})
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    if quantisations is None:
        quantisations = typical_points(robot, library, settings.vq_distortion_mm,
                                       clock=clock)
    notes = [q.note for q in quantisations.values() if q is not None and q.note]
    # Kriging, the figures and the caller's publishing run after the search.
    search = clock.child(reserve=FINISH_RESERVE + PUBLISH_RESERVE)
    options = options or SearchOptions(stay_close=DEFAULT_STAY_CLOSE)
    job = _Job(robot, library, settings, quantisations, optimizer_overrides,
               options.stay_close, options.leans)
    if settings.lock_strategy == 'optimal':
        out = _adapt_optimal(job, faults, measured, seed, search)
    else:
        # Lock angles come from the whole motions, not from their typical points.
        locks, lock_notes = resolve_locks(robot, library, faults, settings.lock_strategy,
                                          measured)
        out = _with_notes(_adapt(job, locks, seed, search), lock_notes)
    out = _with_notes(out, notes)
    wall = float(time.monotonic() - start)
    gestures = tuple(replace(no_worse_than_locked(robot, library[g.name], g, out.locks,
                                                  settings), wall_time=wall)
                     for g in out.gestures)
    budget = None if clock.end is None else float(clock.end - clock.start)
    return replace(out, gestures=gestures, faults=faults, wall_time=wall, deadline=budget,
                   success=out.success and all(np.isfinite(g.score_after) for g in gestures),
                   origin='unbounded' if budget is None else 'deadline')


def _with_notes(result, before=(), after=()):
    """Return ``result`` with notes added before and after its own."""
    return replace(result, notes=tuple(before) + tuple(result.notes) + tuple(after))


def library_total(adaptation):
    """Return an adapted library's total: the sum over motions of the worst point's score."""
    return float(sum(g.score_after for g in adaptation.gestures))


def _adapt_optimal(job, faults, measured, seed, search):
    """
    Adapt with ``optimal`` locks: the average run, then the best other angles, if better.

    The lock angles are searched at the typical points by the keyframe engine (on the
    problem its final result solves, starting from the whole-motion averages); the
    angles it finds are then adapted exactly as the averages were, and the adapted
    library with the lower total is returned, the average one on ties.
    """
    robot = job.robot
    averages, notes = resolve_locks(robot, job.library, faults, 'average', measured)
    first = _with_notes(_adapt(job, averages, seed, search), notes)
    joints = [j for j, a in faults.items() if a is None]
    if not joints:
        return first
    first_total = library_total(first)
    at_average = ', '.join(f'{j} = {np.degrees(averages[j]):.2f} deg' for j in joints)
    if first_total <= 0.0:   # scores are distances: nothing can do better than 0
        return _with_notes(first, after=[f'optimal lock: the average lock {at_average} '
                                         f'already scores 0 on every motion'])
    if search.expired():
        return _with_notes(first, after=[
            f'optimal lock: no time left to try other angles; the average lock '
            f'{at_average} is kept (library total {first_total:.3f})'])
    # The engine starts from the same averages, over the whole motions.
    screen = reconfigure_library(
        robot, job.sub, {j: (None if a is None else averages[j]) for j, a in faults.items()},
        job.settings, clock=search.child(share=0.5),
        seed=int(np.random.default_rng([seed, 1]).integers(2 ** 63)),
        **job.engine_options(lock_start=averages))
    chosen = screen.locks
    if all(chosen[j] == averages[j] for j in joints):
        cut = any(n.startswith('optimal lock') and 'deadline' in n for n in screen.notes)
        return _with_notes(first, after=[
            f'optimal lock: the average lock {at_average} is best (library total '
            f'{first_total:.3f})'
            + ('; the deadline cut the search for other angles short' if cut else '')])
    at_chosen = ', '.join(f'{j} = {np.degrees(chosen[j]):.2f} deg' for j in joints)
    if search.expired():
        return _with_notes(first, after=[
            f'optimal lock: no time left to adapt the motions at {at_chosen}; the average '
            f'lock {at_average} is kept (library total {first_total:.3f})'])
    second = _adapt(job, chosen, seed, search)
    second_total = library_total(second)
    if second_total < first_total:
        return _with_notes(second, notes, [
            f'optimal lock: {at_chosen} (library total {second_total:.3f}; at the average '
            f'lock {at_average}: {first_total:.3f})'])
    return _with_notes(first, after=[
        f'optimal lock: the average lock {at_average} is kept (library total '
        f'{first_total:.3f}; at {at_chosen}: {second_total:.3f})'])


class _Context:
    """What every motion of one adaptation run shares: the locks, models and scorer."""

    def __init__(self, job, locks):
        robot, model = job.robot, job.model
        self.robot, self.model, self.locks = robot, model, locks
        self.locked = locked_sets(robot, locks)
        self.faulted = {s for s in ARMS if self.locked[s] or model.changed(s) or job.leans}
        targets = [t for g in job.library for t in gesture_targets(g)]
        owners = [i for i, g in enumerate(job.library) for _ in g.keyframes]
        self.scorer = SimilarityScore(model, targets, job.settings.weights,
                                      reference_robot=robot,
                                      reference_landmarks=leaned_references(
                                          robot, targets, owners, list(job.library),
                                          job.leans))
        # Every point of the final motions is checked, Kriging-interpolated ones included.
        self.checker = None
        if job.settings.collision_check:
            self.checker = CollisionModel(model, targets, robot.capsules)
        self.algo = make_algorithm(job.settings.optimizer, job.settings.optimizer_preset,
                                   **(job.optimizer_overrides or {}))


class _Motion:
    """One motion being adapted: its design, the locked start and the solution so far."""

    def __init__(self, ctx, gesture, ids):
        self.gesture, self.ids = gesture, ids
        self.design = design = gesture.joint_matrix()
        base_r, base_l = apply_locks(ctx.robot, *split_arms(ctx.robot, design),
                                     ctx.locks)
        self.base_r = ctx.model.arms['right'].clip(base_r)
        self.base_l = ctx.model.arms['left'].clip(base_l)
        self.affected = any(s in ctx.faulted for s in gesture.arms)
        self.status, self.nfev, self.sigma, self.stage, self.how = 'unchanged', 0, (), 0, \
            'keyframes'
        self.free = ()
        self.q_r, self.q_l = self.base_r.copy(), self.base_l.copy()
        self.searched = None   # the keyframe search's GestureResult of its typical points
        self.cut = None        # 'deadline' or 'cancelled': the whole-trajectory pass cut short


def _adapt(job, locks, seed, search):
    """
    Adapt every motion with the lock angles ``locks``, within the ``search`` clock.

    Returns a :class:`~.result.LibraryResult` whose wall time, deadline and faults are
    the caller's to set, and whose ``success`` does not yet check that the scores are
    finite (:func:`adapt_library` does, after :func:`~.figures.no_worse_than_locked`).
    """
    robot, library, method, settings = job.robot, job.library, job.method, job.settings
    rng = np.random.default_rng(seed)
    notes = []
    typical = None
    if method != 'per_point':
        share = 1.0 if method == 'kriging' else TYPICAL_SHARE
        # The smallest corrections keep the typical points on one redundant branch, so
        # that Kriging interpolates between neighbours of the same kind.
        typical = reconfigure_library(robot, job.sub, locks, settings,
                                      clock=search.child(share=share),
                                      seed=int(rng.integers(2 ** 63)),
                                      **job.engine_options())
        locks = typical.locks
        notes += typical.notes
    ctx = _Context(job, locks)
    results = []
    offset = 0
    n_left = sum(1 for g in library if job.quantisations.get(g.name) is not None)
    for gesture in library:
        m = _Motion(ctx, gesture, np.arange(offset, offset + len(gesture.keyframes)))
        offset += len(gesture.keyframes)
        if typical is not None:
            _from_typical(job, ctx, m, typical, search)
        if method == 'auto' and m.how == 'kriging' and m.affected and m.free:
            # Every point at once, from the Kriging result; each dense motion left gets
            # an equal share of the time left (unused time rolls over).
            n_left -= 1
            _whole_trajectory(ctx, m, search.child(share=1.0 / (n_left + 1)), notes)
        if m.affected and method == 'per_point':
            _per_point(job, ctx, m, search, rng, notes)
        if m.affected:
            _pace_motion(ctx, m, job.picks[gesture.name], search, notes)
        # Every angle published lies within its limits, bit for bit (the locks are
        # clamped into theirs, so clipping leaves them as they are).
        m.q_r, m.q_l = ctx.model.arms['right'].clip(m.q_r), ctx.model.arms['left'].clip(m.q_l)
        results.append(describe_motion(ctx, m, job.picks[gesture.name]))
    deadline_met = not any(g.status in CUT_SHORT for g in results)
    return LibraryResult(
        gestures=tuple(results), locks={j: float(a) for j, a in locks.items()},
        frozen_arms=frozen_arms(robot, locks), deadline_met=deadline_met,
        success=deadline_met and (typical is None or typical.success),
        cancelled=any(g.status == 'cancelled' for g in results), settings=settings.public(),
        tool_mm=float(settings.tool_length_mm), tool_arm=settings.tool_arm, seed=seed,
        notes=tuple(notes), nfev=int(sum(g.nfev for g in results)))


def _from_typical(job, ctx, m, typical, search):
    """Take a motion's typical points from the keyframe search; Kriging does the rest."""
    robot, gesture, picks = job.robot, m.gesture, job.picks
    m.searched = gres = typical[gesture.name]
    m.status, m.stage = gres.status, gres.expansion_stage
    m.free = gres.free_joints
    layout = free_layout(robot, gesture.arms, ctx.locked, ctx.faulted,
                         joint_set(robot, m.free))
    m.how = 'keyframes' if job.quantisations.get(gesture.name) is None else 'kriging'
    m.nfev = int(round(typical.nfev * len(picks[gesture.name])
                       / max(1, sum(len(p) for p in picks.values()))))
    solved = np.array([kf.positions() for kf in gres.keyframes])
    mine = list(picks[gesture.name])
    if m.how == 'kriging' and m.affected and m.free:
        solved, used = _consistent(ctx, m.ids[mine], m.design[mine], solved, layout,
                                   job.settings.continuity_weight, search)
        m.nfev += used
    m.q_r, m.q_l, m.sigma = _spread(robot, gesture, mine, solved, ctx.locks)


def _pace_motion(ctx, m, picks, clock, notes):
    """
    Keep one adapted motion within the joints' velocity limits (as the keyframe search).

    Kriging, the whole-trajectory pass and the per-point chain each place every point of
    a motion; one whose steps break :func:`.pacing.step_limits` is replaced by the best
    of :func:`.pacing.repair`'s feasible candidates (the design carried through each
    typical point ``picks`` among them), which needs no time, and then, while ``clock``
    allows, optimised again as a whole with every point held in its
    :func:`.pacing.tube` box, where every choice stays feasible.
    """
    robot, model = ctx.robot, ctx.model
    limits = pacing.step_limits(robot.joint_velocity_limits,
                                [kf.time_from_start for kf in m.gesture.keyframes], m.design)
    lower, upper = joint_bounds(model)
    q = np.clip(np.concatenate((m.q_r, m.q_l), axis=1), lower, upper)
    if pacing.feasible(q, limits):
        return
    base = np.concatenate((m.base_r, m.base_l), axis=1)
    best, _ = pacing.repair(q, base, limits, lower, upper,
                            lambda c: pose_values(model, ctx.scorer, ctx.checker, c, m.ids),
                            picks)
    m.q_r, m.q_l = split_arms(model, best)
    note = f'{m.gesture.name}: {PACED_NOTE}'
    if note not in notes:      # the typical points' search may have said it already
        notes.append(note)
    layout = free_layout(robot, m.gesture.arms, ctx.locked, ctx.faulted,
                         joint_set(robot, m.free))
    if not layout or clock.expired():
        return
    problem = TrajectoryProblem(model, ctx.scorer, m.ids, (m.q_r, m.q_l), layout,
                                step_cap_deg=designed_step_deg(m.design),
                                collision=ctx.checker)
    col = layout_columns(model, layout)
    low, high = pacing.tube(best, limits, lower, upper)
    problem.restrict(low[:, col], high[:, col])
    out = optimise_trajectory(problem, clock)
    m.nfev += out.nfev
    if out.value < out.value_start:
        m.q_r, m.q_l = out.q_right, out.q_left


def _whole_trajectory(ctx, m, budget, notes):
    """
    Optimise every point of a motion at once from its Kriging result, per stage.

    The first pass is kept if it lowers its own objective (the sum of the points'
    scores and the step and collision terms); a later expansion stage's pass only if
    it also lowers what the gesture is scored by, the worst point (after any contact),
    since a lower sum may well raise the worst point.
    """
    robot = ctx.robot
    passes = expansion_layouts(robot, m.gesture, ctx.locked, ctx.faulted, m.free, m.stage)
    for k, (level, lay) in enumerate(passes):
        if k and budget.expired():
            break
        out = optimise_motion(ctx.model, ctx.scorer, m.ids, m.q_r, m.q_l, lay, m.design,
                              budget, collision=ctx.checker)
        better = out.value < out.value_start
        if better and k:
            (touch, worst), (was_touch, was) = (_worst_point(ctx, m, out.q_right, out.q_left),
                                                _worst_point(ctx, m, m.q_r, m.q_l))
            # Equal worst points (within rounding): the fewer joints moved.
            better = (touch, worst * (1.0 + _STAGE_MARGIN)) < (was_touch, was)
        if better:
            m.q_r, m.q_l, m.how = out.q_right, out.q_left, 'trajectory'
            if k:
                m.stage, m.free = level, tuple(robot.arms[s].joint_names[j] for s, j in lay)
        m.nfev += out.nfev
        if out.status in CUT_SHORT:
            m.cut = out.status          # the message says so; the library's status stays
            notes.append(f'{m.gesture.name}: the whole-trajectory pass was cut short '
                         f'({out.status}) after {out.nfev} evaluations; the best '
                         f'trajectory so far is used')
            break


def _worst_point(ctx, m, q_r, q_l):
    """Return (any point in contact, the worst point's score) of a motion's angles."""
    collides = False
    if ctx.checker is not None:
        lm_r = batch_forward(ctx.model, q_r, 'right')
        lm_l = batch_forward(ctx.model, q_l, 'left')
        collides = bool(ctx.checker.collides(lm_r, lm_l, m.ids).any())
    return collides, float(ctx.scorer.evaluate(q_r, q_l, m.ids).max())


def _per_point(job, ctx, m, search, rng, notes):
    """Explore every point of a motion in order, with its staged DOF expansion."""
    robot, gesture = ctx.robot, m.gesture
    designed = joint_set(robot, gesture.joints) if gesture.joints else None
    layouts = [free_layout(robot, gesture.arms, ctx.locked, ctx.faulted, designed)]
    allowed = set(designed) if designed else None
    for extra in gesture.expand:
        allowed |= joint_set(robot, extra)
        layouts.append(free_layout(robot, gesture.arms, ctx.locked, ctx.faulted, allowed))
    out = _chain_with_expansion(ctx, m, layouts, job.settings.continuity_weight, search, rng)
    if out is None:
        notes.append(f'{gesture.name}: the per-point pass could not finish by the '
                     f'deadline; the motion is published unadapted (locks applied)')
        m.status = 'deadline'
        return
    m.q_r, m.q_l, m.nfev, m.stage, chain_free, m.status = out
    m.how = 'per_point'
    m.free = tuple(robot.arms[s].joint_names[j] for s, j in chain_free)


def expansion_layouts(robot, gesture, locked, faulted, free, stage):
    """
    Return ``[(expansion stage, free-joint layout)]``: a motion's trajectory passes.

    The first is the layout the typical points were solved with (``free``, joint names,
    at expansion ``stage``); each further one adds the gesture's next ``expand`` stage.
    The typical points' search expands only while one of *them* misses the fingertip
    threshold, which on a motion whose worst point is set by the posture terms (the
    circle, right joint 2 locked) was a coin toss of the seed: the passes at the later
    stages, warm-started from the previous pass and kept only if they lower its
    objective, make the joints the motion may use independent of the seed.
    """
    allowed = joint_set(robot, free)
    out = [(stage, free_layout(robot, gesture.arms, locked, faulted, allowed))]
    for level, extra in enumerate(gesture.expand[stage:], start=stage + 1):
        allowed = allowed | joint_set(robot, extra)
        lay = free_layout(robot, gesture.arms, locked, faulted, allowed)
        if lay != out[-1][1]:
            out.append((level, lay))
    return out


def _consistent(ctx, ids, design, solved, layout, continuity_weight, clock):
    """
    Put the typical points on one redundant branch before Kriging interpolates them.

    Independently explored typical points may land on different branches of a
    redundant arm, and interpolating between branches leaves the path.  Each typical
    point is polished from its own solution and from its design plus the previous
    typical point's correction, with the continuity penalty towards the latter; the
    lower penalised value wins.  All points are polished in one batch per sweep (a
    sequential pass cost the node ~0.2 s); a branch choice moves one point along the
    motion per sweep, so sweeps repeat until no point moves
    (or ``_MAX_SWEEPS``).  Returns (solved, nfev).
    """
    solved = solved.copy()
    if len(ids) < 2:
        return solved, 0
    col = layout_columns(ctx.model, layout)
    nfev = 0
    rest = slice(1, None)
    for _ in range(min(len(ids) - 1, _MAX_SWEEPS)):
        if clock.expired():
            break
        before = solved[rest].copy()
        anchor = design[rest, col] + solved[:-1, col] - design[:-1, col]
        problem = PoseProblem(ctx.model, ctx.scorer, ids[rest],
                              split_arms(ctx.model, solved[rest]), layout,
                              x0=solved[rest][:, col], anchor=anchor,
                              continuity=continuity_weight)
        starts = problem.clip(np.stack((solved[rest][:, col], anchor), axis=1))
        x, f = polish(problem, starts, clock, maxiter=20, ftol=1e-6)
        nfev += problem.nfev
        pick = np.argmin(f, axis=1)
        r, left = problem.assemble(x[np.arange(len(x)), pick][:, None])
        solved[rest] = np.concatenate((r[:, 0], left[:, 0]), axis=1)
        if np.degrees(np.abs(solved[rest] - before).max()) < _SETTLED_DEG:
            break
    return solved, nfev


def _spread(robot, gesture, picks, solved, locks):
    """Kriging of the typical points' corrections to every point of one motion."""
    design = gesture.joint_matrix()
    cols = np.concatenate([np.arange(design.shape[1])[arm_columns(robot)[s]] for s in ARMS])
    x = np.degrees(design[:, cols])
    r = np.degrees(solved - design[list(picks)])
    if len(picks) == len(design):
        out, sigma = solved, ()
    else:
        est = OrdinaryKriging(x[list(picks)], r).predict(x)
        out = design + np.radians(est.values)
        sigma = tuple(float(s) for s in np.sqrt(est.variance))
    q_r, q_l = apply_locks(robot, *split_arms(robot, out), locks)
    q_r = robot.arms['right'].clip(q_r)
    q_l = robot.arms['left'].clip(q_l)
    return apply_locks(robot, q_r, q_l, locks) + (sigma,)


def _chain_with_expansion(ctx, m, layouts, continuity_weight, clock, rng):
    """
    Run the per-point chain, then its staged expansion while the worst point is poor.

    Returns None if the deadline cut the first pass, else (right, left, nfev, stage,
    layout, status); status is 'deadline' when a later expansion stage was cut short.
    """
    nfev = 0
    best = None
    start_r, start_l = m.q_r, m.q_l
    for stage, layout in enumerate(layouts):
        if not layout:
            continue
        out = _chain(ctx, m, layout, continuity_weight, clock, rng, start_r, start_l)
        if out is None:
            # A later stage was cut short: keep the best completed stage, say so.
            return None if best is None else best[:2] + (nfev,) + best[3:5] + ('deadline',)
        q_r, q_l, used, f = out
        nfev += used
        reach = ctx.scorer.tip_error(q_r, q_l, m.ids).max()
        if best is None or f.mean() < best[6]:
            best = (q_r, q_l, nfev, stage, layout, 'converged', f.mean())
        # Read at the call: one threshold for both searches (a test may change it).
        if reach <= keyframe_search.DEFAULT_EXPANSION_THRESHOLD:
            break
        start_r, start_l = q_r, q_l
    if best is None:
        return start_r, start_l, 0, 0, (), 'frozen'
    return best[:2] + (nfev,) + best[3:6]


def _chain(ctx, m, layout, continuity_weight, clock, rng, start_r, start_l):
    """
    Explore every point in order, warm-started from the previous point's solution.

    Point t starts at (and is penalised for moving away from) the previous solution
    plus the designed step theta(t) - theta(t-1).  Returns None if the deadline or a
    cancel cut it short, else (right, left, nfev, scores).
    """
    scorer, ids, base_r, base_l, design = ctx.scorer, m.ids, m.base_r, m.base_l, m.design
    q_r, q_l = base_r.copy(), base_l.copy()
    col = layout_columns(ctx.model, layout)
    design_free = design[:, col]
    full = np.concatenate((start_r, start_l), axis=1)
    nfev = 0
    scores = np.empty(len(ids))
    began = time.monotonic()
    for t in range(len(ids)):
        if clock.end is not None and t >= 1:
            # Give up early when the pace so far says the chain cannot finish in time.
            pace = (time.monotonic() - began) / t
            if time.monotonic() + pace * (len(ids) - t) > clock.end:
                return None
        if t == 0:
            anchor = None
            x0 = full[0, col]
        else:
            prev = np.concatenate((q_r[t - 1], q_l[t - 1]))[col]
            anchor = prev + design_free[t] - design_free[t - 1]
            x0 = anchor
        problem = PoseProblem(ctx.model, scorer, ids[t:t + 1],
                              (base_r[t:t + 1], base_l[t:t + 1]), layout, x0=[x0],
                              anchor=None if anchor is None else [anchor],
                              continuity=continuity_weight)
        if clock.remaining() <= 0:
            return None
        res = minimize(problem, ctx.algo, clock=clock, seed=int(rng.integers(2 ** 63)))
        if res.status != 0:
            return None
        nfev += res.nfev
        x = np.atleast_2d(res.x)
        r, left = problem.assemble(x)
        q_r[t], q_l[t] = r[0], left[0]
        scores[t] = scorer.evaluate(q_r[t:t + 1], q_l[t:t + 1], ids[t:t + 1])[0]
    return q_r, q_l, nfev, scores
