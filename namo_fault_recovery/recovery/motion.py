"""
Whole-motion adaptation after a structure change (the second source paper), ROS-free.

Two methods reconfigure every point of every gesture's motion:

- ``kriging`` (the paper's): vector quantisation picks K typical points per motion
  (:mod:`.vq`), only those are explored (with the batched engine of
  :mod:`.reconfigure`, so lock strategies, staged DOF expansion, the healthy arm and
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
"""

from dataclasses import dataclass, field, replace
import time

import numpy as np

from .budget import FINISH_RESERVE, PUBLISH_RESERVE, TYPICAL_SHARE, VQ_SHARE
from .keyframes import (apply_locks, DEFAULT_EXPANSION_THRESHOLD, free_layout, joint_set,
                        locked_sets, PoseProblem, reconfigure_library)
from .kriging import OrdinaryKriging
from .locks import check_strategy, resolve_locks
from .trajectory_opt import DEFAULT_SMOOTHNESS, optimise_motion
from .vq import quantise
from ..model.gestures import GestureLibrary, Keyframe
from ..model.kinematics import batch_forward
from ..model.robot import ARMS, N_JOINTS
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
_MAX_SWEEPS = 6                # consistency sweeps at most (5 fixed the elbow-lock circle)


@dataclass
class GestureAdaptation:
    """One adapted motion, with the figures that say how good it is."""

    name: str
    keyframes: tuple
    method: str                  # 'kriging', 'per_point' or 'keyframes' (all explored)
    typical: tuple               # indices of the explored typical points
    status: str
    nfev: int                    # objective evaluations spent on this motion
    score_before: float          # mean score of the unadapted motion (locks applied)
    score_mean: float
    score_max: float
    tip_error_before_mm: float   # mean fingertip distance to the designed path
    tip_error_mean_mm: float
    tip_error_max_mm: float
    jump_designed_deg: float     # largest joint step between successive points
    jump_before_deg: float
    jump_after_deg: float
    kriging_sigma_deg: tuple = ()   # Kriging standard deviation per point
    score_before_max: float = 0.0   # worst point of the unadapted motion
    collides: object = None         # with ``collision``: does any point of the motion?
    colliding_pairs: tuple = ()     # the capsule pairs that touch, over the motion
    expansion_stage: int = 0
    free_joints: tuple = ()
    message: str = ''

    @property
    def times(self):
        """Keyframe times from start (s)."""
        return [kf.time_from_start for kf in self.keyframes]


@dataclass
class MotionAdaptation:
    """The adapted library: per-gesture results and what the run cost."""

    gestures: list
    locks: dict
    method: str
    wall_time: float
    nfev: int
    seed: int
    deadline: object
    tool_mm: float = 0.0
    tool_arm: str = 'right'
    typical_result: object = None   # the engine's LibraryReconfiguration, if it ran
    notes: list = field(default_factory=list)

    def __getitem__(self, name):
        for g in self.gestures:
            if g.name == name:
                return g
        raise KeyError(f'unknown gesture {name!r}')

    @property
    def deadline_met(self):
        """Return True if no gesture was cut short by the deadline or a cancel."""
        return not any(g.status in ('deadline', 'cancelled') for g in self.gestures)

    @property
    def cancelled(self):
        """Return True if any gesture was cut short by a cancel request."""
        return any(g.status == 'cancelled' for g in self.gestures)


def typical_points(robot, library, distortion_mm=DEFAULT_DISTORTION_MM,
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
        tips = np.concatenate([batch_forward(robot, q[:, _cols(side)], side).tip
                               for side in gesture.arms], axis=1)
        # Each motion gets an equal share of what is left; unused time rolls over.
        found = quantise(np.degrees(q), distortion_mm, features=tips, seed=seed,
                         clock=clock.child(share=1.0 / n_left))
        if found.note:
            found = replace(found, note=f'{gesture.name}: {found.note}')
        out[gesture.name] = found
    return out


class _Job:
    """What every adaptation run of one call shares (everything but the locks)."""

    def __init__(self, robot, library, **options):
        self.robot = robot
        self.library = library
        self.__dict__.update(options)
        self.model = robot.with_tool(self.tool_mm, self.tool_arm)
        quantisations = self.quantisations
        self.picks = {g.name: (tuple(range(len(g.keyframes)))
                               if quantisations.get(g.name) is None
                               else tuple(int(i) for i in quantisations[g.name].typical))
                      for g in library}
        self.sub = GestureLibrary(tuple(g.with_keyframes([g.keyframes[i]
                                                          for i in self.picks[g.name]])
                                        for g in library), library.source)

    def engine_options(self):
        """Return the keyword arguments of the typical points' keyframe engine."""
        return dict(algorithm=self.algorithm, preset=self.preset, settings=self.settings,
                    weights=self.weights, expansion_threshold=self.expansion_threshold,
                    tool_mm=self.tool_mm, tool_arm=self.tool_arm,
                    stay_close=self.stay_close, **self.engine,
                    # A motion explored at its typical points is made consistent by
                    # _consistent; one explored at every keyframe shares its branches.
                    share_branches=tuple(g.name for g in self.library
                                         if self.quantisations.get(g.name) is None))


def adapt_library(robot, library, faults=None, *, method='auto', tool_mm=0.0,
                  tool_arm='right', distortion_mm=DEFAULT_DISTORTION_MM,
                  min_points=DEFAULT_MIN_POINTS, continuity=DEFAULT_CONTINUITY,
                  deadline=1.0, seed=None, algorithm='abc', preset='default',
                  settings=None, lock_strategy='average', measured=None, weights=None,
                  expansion_threshold=DEFAULT_EXPANSION_THRESHOLD, cancel=None,
                  quantisations=None, stay_close=DEFAULT_STAY_CLOSE, clock=None,
                  smoothness=DEFAULT_SMOOTHNESS, **engine):
    """
    Adapt every motion of ``library`` to a changed structure (faults and/or a tool).

    ``faults`` maps joint names to lock angles (rad) or None, as for
    :func:`.keyframes.reconfigure_library`; extra keyword arguments (``bimanual``,
    ``collision``...) go to that engine.  ``clock`` (a
    :class:`~namo_fault_recovery.optimize.base.Clock`) owns the deadline and the cancel
    flag of the whole run; without one, ``deadline`` (s) and ``cancel`` make it.  Every
    stage's budget comes from that clock, less the reserves of :mod:`.budget`.
    ``lock_strategy='optimal'`` runs the ``average`` adaptation first (the very same
    run), then tries the lock angles that do best at the typical points, and keeps
    whichever adapted library has the lower total (the sum over motions of their worst
    point's score): never worse than ``average``.
    ``smoothness`` (per deg^2 of joint step between consecutive points) weights the
    coupling term of ``auto``'s whole-trajectory pass.
    Returns a :class:`MotionAdaptation`; a pure function of the inputs and ``seed`` up
    to where the deadline cuts the search.
    """
    start = time.monotonic()
    if method not in METHODS:
        raise ValueError(f'unknown adaptation method {method!r}; expected one of '
                         f'{", ".join(METHODS)}')
    if not (np.isfinite(continuity) and continuity >= 0):
        raise ValueError(f'continuity: expected a finite number >= 0, got {continuity!r}')
    check_strategy(lock_strategy)
    if clock is None:
        clock = Clock(deadline, cancel)
    elif cancel is not None:
        raise ValueError('adapt_library: pass the cancel flag in the clock')
    faults = dict(faults or {})
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    if quantisations is None:
        quantisations = typical_points(robot, library, distortion_mm, min_points,
                                       clock=clock)
    notes = [q.note for q in quantisations.values() if q is not None and q.note]
    # Kriging, the figures and the caller's publishing run after the search.
    search = clock.child(reserve=FINISH_RESERVE + PUBLISH_RESERVE)
    job = _Job(robot, library, method=method, tool_mm=tool_mm, tool_arm=tool_arm,
               continuity=continuity, algorithm=algorithm, preset=preset,
               settings=settings, weights=weights, expansion_threshold=expansion_threshold,
               quantisations=quantisations, stay_close=stay_close, engine=engine,
               lock_strategy=lock_strategy, smoothness=smoothness)
    if lock_strategy == 'optimal':
        out = _adapt_optimal(job, faults, measured, seed, search)
    else:
        # Lock angles come from the whole motions, not from their typical points.
        locks, lock_notes = resolve_locks(robot, library, faults, lock_strategy, measured)
        out = _adapt(job, locks, seed, search)
        out.notes[:0] = lock_notes
    out.notes[:0] = notes
    out.wall_time = time.monotonic() - start
    out.deadline = None if clock.end is None else clock.end - clock.start
    return out


def library_total(adaptation):
    """Return an adapted library's total: the sum over motions of the worst point's score."""
    return float(sum(g.score_max for g in adaptation.gestures))


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
    first = _adapt(job, averages, seed, search)
    first.notes[:0] = notes
    joints = [j for j, a in faults.items() if a is None]
    if not joints:
        return first
    first_total = library_total(first)
    at_average = ', '.join(f'{j} = {np.degrees(averages[j]):.2f} deg' for j in joints)
    if first_total <= 0.0:   # scores are distances: nothing can do better than 0
        first.notes.append(f'optimal lock: the average lock {at_average} already scores '
                           f'0 on every motion')
        return first
    if search.expired():
        first.notes.append(f'optimal lock: no time left to try other angles; the average '
                           f'lock {at_average} is kept (library total {first_total:.3f})')
        return first
    # The engine starts from the same averages, over the whole motions.
    screen = reconfigure_library(
        robot, job.sub, {j: (None if a is None else averages[j]) for j, a in faults.items()},
        lock_strategy='optimal', lock_start=averages, clock=search.child(share=0.5),
        seed=int(np.random.default_rng([seed, 1]).integers(2 ** 63)),
        **job.engine_options())
    chosen = screen.locks
    if all(chosen[j] == averages[j] for j in joints):
        cut = any(n.startswith('optimal lock') and 'deadline' in n for n in screen.notes)
        first.notes.append(f'optimal lock: the average lock {at_average} is best '
                           f'(library total {first_total:.3f})'
                           + ('; the deadline cut the search for other angles short'
                              if cut else ''))
        return first
    at_chosen = ', '.join(f'{j} = {np.degrees(chosen[j]):.2f} deg' for j in joints)
    if search.expired():
        first.notes.append(f'optimal lock: no time left to adapt the motions at '
                           f'{at_chosen}; the average lock {at_average} is kept (library '
                           f'total {first_total:.3f})')
        return first
    second = _adapt(job, chosen, seed, search)
    second_total = library_total(second)
    if second_total < first_total:
        second.notes[:0] = notes
        second.notes.append(f'optimal lock: {at_chosen} (library total {second_total:.3f}; '
                            f'at the average lock {at_average}: {first_total:.3f})')
        return second
    first.notes.append(f'optimal lock: the average lock {at_average} is kept (library '
                       f'total {first_total:.3f}; at {at_chosen}: {second_total:.3f})')
    return first


def _adapt(job, locks, seed, search):
    """
    Adapt every motion with the lock angles ``locks``, within the ``search`` clock.

    Returns a :class:`MotionAdaptation` (its wall time and deadline are the caller's).
    """
    robot, library, model, method = job.robot, job.library, job.model, job.method
    quantisations, picks = job.quantisations, job.picks
    rng = np.random.default_rng(seed)
    notes = []
    typical_res = None
    if method != 'per_point':
        share = 1.0 if method == 'kriging' else TYPICAL_SHARE
        # The smallest corrections keep the typical points on one redundant branch, so
        # that Kriging interpolates between neighbours of the same kind.
        typical_res = reconfigure_library(robot, job.sub, locks, lock_strategy=job.lock_strategy,
                                          clock=search.child(share=share),
                                          seed=int(rng.integers(2 ** 63)),
                                          **job.engine_options())
        locks = typical_res.locks
        notes += typical_res.notes

    locked = locked_sets(robot, locks)
    faulted = {s for s in ARMS if locked[s] or model.tool_length(s) > 0}
    targets = [t for g in library for t in gesture_targets(g)]
    scorer = SimilarityScore(model, targets, job.weights, reference_robot=robot)
    # Every point of the final motions is checked, Kriging-interpolated ones included.
    checker = None
    if job.engine.get('collision'):
        checker = CollisionModel(model, targets, job.engine.get('capsules') or robot.capsules)
    algo = make_algorithm(job.algorithm, job.preset, **(job.settings or {}))
    results = []
    offset = 0
    n_left = sum(1 for g in library if quantisations.get(g.name) is not None)
    for gesture in library:
        n = len(gesture.keyframes)
        ids = np.arange(offset, offset + n)
        offset += n
        design = gesture.joint_matrix()
        base_r, base_l = apply_locks(robot, design[:, :N_JOINTS], design[:, N_JOINTS:], locks)
        base_r, base_l = model.arms['right'].clip(base_r), model.arms['left'].clip(base_l)
        affected = any(s in faulted for s in gesture.arms)
        status, nfev, sigma, stage, how = 'unchanged', 0, (), 0, 'keyframes'
        free = ()
        q_r, q_l = base_r.copy(), base_l.copy()
        if typical_res is not None:
            gres = typical_res[gesture.name]
            status, stage = gres.status, gres.expansion_stage
            free = gres.free_joints
            layout = free_layout(robot, gesture.arms, locked, faulted, joint_set(robot, free))
            how = 'keyframes' if quantisations.get(gesture.name) is None else 'kriging'
            nfev = int(round(typical_res.nfev * len(picks[gesture.name])
                             / max(1, sum(len(p) for p in picks.values()))))
            solved = np.array([kf.positions() for kf in gres.keyframes])
            if how == 'kriging' and affected and free:
                solved, used = _consistent(model, scorer, ids[list(picks[gesture.name])],
                                           design[list(picks[gesture.name])], solved, layout,
                                           job.continuity, search)
                nfev += used
            q_r, q_l, sigma = _spread(robot, gesture, picks[gesture.name], solved, locks)
        if method == 'auto' and how == 'kriging' and affected and free:
            # Every point at once, from the Kriging result; each dense motion left gets
            # an equal share of the time left (unused time rolls over).
            n_left -= 1
            budget = search.child(share=1.0 / (n_left + 1))
            passes = expansion_layouts(robot, gesture, locked, faulted, free, stage)
            for k, (level, lay) in enumerate(passes):
                if k and budget.expired():
                    break
                out = optimise_motion(model, scorer, ids, q_r, q_l, lay, design, budget,
                                      smoothness=job.smoothness, collision=checker)
                if out.value < out.value_start:
                    q_r, q_l, how = out.q_right, out.q_left, 'trajectory'
                    if k:
                        stage, free = level, tuple(robot.arms[s].joint_names[j]
                                                   for s, j in lay)
                nfev += out.nfev
                if out.status in ('deadline', 'cancelled'):
                    notes.append(f'{gesture.name}: the whole-trajectory pass was cut short '
                                 f'({out.status}) after {out.nfev} evaluations; the best '
                                 f'trajectory so far is used')
                    break
        if affected and method == 'per_point':
            designed = joint_set(robot, gesture.joints) if gesture.joints else None
            layouts = [free_layout(robot, gesture.arms, locked, faulted, designed)]
            allowed = set(designed) if designed else None
            for extra in gesture.expand:
                allowed |= joint_set(robot, extra)
                layouts.append(free_layout(robot, gesture.arms, locked, faulted, allowed))
            out = _chain_with_expansion(model, scorer, ids, base_r, base_l, design, layouts,
                                        algo, job.continuity, job.expansion_threshold, search,
                                        rng, q_r, q_l, True)
            if out is None:
                notes.append(f'{gesture.name}: the per-point pass could not finish by the '
                             f'deadline; the motion is published unadapted (locks applied)')
                status = 'deadline'
            else:
                q_r, q_l, extra_nfev, chain_stage, chain_free, chain_status = out
                nfev = extra_nfev
                how = 'per_point'
                stage = chain_stage
                free = tuple(robot.arms[s].joint_names[j] for s, j in chain_free)
                status = chain_status     # the published motion is the chain's
        # Every angle published lies within its limits, bit for bit (the locks are
        # clamped into theirs, so clipping leaves them as they are).
        q_r, q_l = model.arms['right'].clip(q_r), model.arms['left'].clip(q_l)
        results.append(_describe(robot, model, scorer, gesture, ids, design, base_r, base_l,
                                 q_r, q_l, how, picks[gesture.name], status, nfev, sigma,
                                 stage, free, checker))
    total = sum(g.nfev for g in results)
    return MotionAdaptation(results, locks, method, 0.0, int(total), seed, None,
                            float(job.tool_mm), job.tool_arm, typical_res, notes)


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


def _cols(side):
    return slice(0, N_JOINTS) if side == 'right' else slice(N_JOINTS, 2 * N_JOINTS)


def _consistent(model, scorer, ids, design, solved, layout, continuity, clock):
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
    col = np.array([j + (0 if s == 'right' else N_JOINTS) for s, j in layout])
    nfev = 0
    rest = slice(1, None)
    for _ in range(min(len(ids) - 1, _MAX_SWEEPS)):
        if clock.expired():
            break
        before = solved[rest].copy()
        anchor = design[rest, col] + solved[:-1, col] - design[:-1, col]
        problem = PoseProblem(model, scorer, ids[rest], solved[rest, :N_JOINTS],
                              solved[rest, N_JOINTS:], layout, x0=solved[rest][:, col],
                              anchor=anchor, continuity=continuity)
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
    cols = np.concatenate([np.arange(2 * N_JOINTS)[_cols(s)] for s in ARMS])
    x = np.degrees(design[:, cols])
    r = np.degrees(solved - design[list(picks)])
    if len(picks) == len(design):
        out, sigma = solved, ()
    else:
        est = OrdinaryKriging(x[list(picks)], r).predict(x)
        out = design + np.radians(est.values)
        sigma = tuple(float(s) for s in np.sqrt(est.variance))
    q_r, q_l = apply_locks(robot, out[:, :N_JOINTS], out[:, N_JOINTS:], locks)
    q_r = robot.arms['right'].clip(q_r)
    q_l = robot.arms['left'].clip(q_l)
    return apply_locks(robot, q_r, q_l, locks) + (sigma,)


def _chain_with_expansion(model, scorer, ids, base_r, base_l, design, layouts, algo,
                          continuity, threshold, clock, rng, start_r, start_l, expand):
    """
    Run the per-point chain, then its staged expansion while the worst point is poor.

    Returns None if the deadline cut the first pass, else (right, left, nfev, stage,
    layout, status); status is 'deadline' when a later expansion stage was cut short.
    """
    nfev = 0
    best = None
    for stage, layout in enumerate(layouts):
        if not layout:
            continue
        out = _chain(model, scorer, ids, base_r, base_l, design, layout, algo, continuity,
                     clock, rng, start_r, start_l)
        if out is None:
            # A later stage was cut short: keep the best completed stage, say so.
            return None if best is None else best[:2] + (nfev,) + best[3:5] + ('deadline',)
        q_r, q_l, used, f = out
        nfev += used
        reach = scorer.tip_error(q_r, q_l, ids).max()
        if best is None or f.mean() < best[6]:
            best = (q_r, q_l, nfev, stage, layout, 'converged', f.mean())
        if not expand or reach <= threshold:
            break
        start_r, start_l = q_r, q_l
    if best is None:
        return start_r, start_l, 0, 0, (), 'frozen'
    return best[:2] + (nfev,) + best[3:6]


def _chain(model, scorer, ids, base_r, base_l, design, layout, algo, continuity, clock,
           rng, start_r, start_l):
    """
    Explore every point in order, warm-started from the previous point's solution.

    Point t starts at (and is penalised for moving away from) the previous solution
    plus the designed step theta(t) - theta(t-1).  Returns None if the deadline or a
    cancel cut it short, else (right, left, nfev, scores).
    """
    q_r, q_l = base_r.copy(), base_l.copy()
    col = np.array([j + (0 if s == 'right' else N_JOINTS) for s, j in layout])
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
        problem = PoseProblem(model, scorer, ids[t:t + 1], base_r[t:t + 1], base_l[t:t + 1],
                              layout, x0=[x0], anchor=None if anchor is None else [anchor],
                              continuity=continuity)
        if clock.remaining() <= 0:
            return None
        res = minimize(problem, algo, clock=clock, seed=int(rng.integers(2 ** 63)))
        if res.status != 0:
            return None
        nfev += res.nfev
        x = np.atleast_2d(res.x)
        r, left = problem.assemble(x)
        q_r[t], q_l[t] = r[0], left[0]
        scores[t] = scorer.evaluate(q_r[t:t + 1], q_l[t:t + 1], ids[t:t + 1])[0]
    return q_r, q_l, nfev, scores


def _jump(q):
    if len(q) < 2:
        return 0.0
    return float(np.degrees(np.abs(np.diff(q, axis=0))).max())


def _describe(robot, model, scorer, gesture, ids, design, base_r, base_l, q_r, q_l, how,
              picks, status, nfev, sigma, stage, free, checker=None):
    """Compute a motion's figures: score, fingertip error, joint jumps and collisions."""
    before = scorer.evaluate(base_r, base_l, ids)
    after = scorer.evaluate(q_r, q_l, ids)
    collides, pairs = None, ()
    if checker is not None:
        lm_r, lm_l = batch_forward(model, q_r, 'right'), batch_forward(model, q_l, 'left')
        collides = bool(checker.collides(lm_r, lm_l, ids).any())
        pairs = tuple(dict.fromkeys(p for row in checker.colliding_pairs(lm_r, lm_l, ids)
                                    for p in row))
    err_before = np.zeros(len(ids))
    err_after = np.zeros(len(ids))
    for side in gesture.arms:
        want = batch_forward(robot, design[:, _cols(side)], side).tip
        qb, qa = (base_r, q_r) if side == 'right' else (base_l, q_l)
        err_before = np.maximum(err_before, np.linalg.norm(
            batch_forward(model, qb, side).tip - want, axis=1))
        err_after = np.maximum(err_after, np.linalg.norm(
            batch_forward(model, qa, side).tip - want, axis=1))
    adapted = np.concatenate((q_r, q_l), axis=1)
    frames = tuple(Keyframe(kf.time_from_start, q_r[i].copy(), q_l[i].copy())
                   for i, kf in enumerate(gesture.keyframes))
    label = {'kriging': f'{len(picks)} typical points + Kriging',
             'per_point': 'every point explored in order',
             'trajectory': f'{len(picks)} typical points + Kriging, then every point '
                           f'optimised at once',
             'keyframes': 'every keyframe explored'}[how]
    message = f'{gesture.name}: {label}; mean score {after.mean():.2f}'
    if status == 'deadline':
        message += '; deadline reached, best result so far used'
    return GestureAdaptation(
        name=gesture.name, keyframes=frames, method=how, typical=tuple(picks),
        status=status, nfev=int(nfev), score_before=float(before.mean()),
        score_mean=float(after.mean()), score_max=float(after.max()),
        tip_error_before_mm=float(err_before.mean()),
        tip_error_mean_mm=float(err_after.mean()),
        tip_error_max_mm=float(err_after.max()),
        jump_designed_deg=_jump(design),
        jump_before_deg=_jump(np.concatenate((base_r, base_l), axis=1)),
        jump_after_deg=_jump(adapted), kriging_sigma_deg=tuple(sigma),
        score_before_max=float(before.max()), collides=collides, colliding_pairs=pairs,
        expansion_stage=int(stage), free_joints=tuple(free), message=message)
