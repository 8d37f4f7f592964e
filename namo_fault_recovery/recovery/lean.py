"""
The staged DOF expansion into the joints shared by both arms: the torso leans.

The second source paper expands the DOF in stages when the designed joints cannot
reach a motion.  After the arms' own stages (a gesture's ``expand`` joints, stage 2's
healthy arm) a robot whose arms hang from shared joints (a torso or waist, the
profile's ``shared``; :class:`~..model.shared_joints.SharedJoints`) has one more: a
gesture whose fingertip still stays more than ``DEFAULT_EXPANSION_THRESHOLD`` mm off
is searched again with the torso leaned, one lean held through the whole gesture.

A lean is a rigid motion of both arms and the chest, so the keyframe search runs on
the upright arms against the gesture's references moved back by the lean
(``SearchOptions.leans``): the score is the leaned robot's, and self-contact is
unchanged.  The leans are screened first (:func:`screen_leans`): every lean of a grid
(``LEAN_STEPS_DEG`` per shared joint, within its limits) polishes the published arms
of the gesture's worst keyframe a little; the ``LEAN_KEPT`` best that promise
``LEAN_GAIN`` are then solved in full (every keyframe, every stage), all copies of all
gestures in one batched search.  A lean is kept only if it lowers the gesture's score
by ``LEAN_GAIN`` and adds no collision: leaning the torso is a larger motion for a
guest than the arms' own.  A dense motion (one explored at typical points) is not
leaned.
"""

from dataclasses import replace
import itertools

import numpy as np

from .budget import PUBLISH_RESERVE
from .keyframes import (DEFAULT_EXPANSION_THRESHOLD, PoseProblem, reconfigure_library,
                        SearchOptions)
from .locks import clamp_lock
from .result import CUT_SHORT, LibraryResult
from ..model.gestures import GestureLibrary
from ..model.kinematics import batch_forward
from ..model.robot import ARMS
from ..objective.collision import CollisionModel
from ..objective.score import gesture_targets, SimilarityScore
from ..optimize.base import Clock
from ..optimize.polish import polish

LEAN_STEPS_DEG = (-15.0, -7.5, 0.0, 7.5, 15.0)   # the leans screened, per shared joint
SCREEN_MAXITER = 15    # polish iterations of each lean's screen, from the published arms
LEAN_KEPT = 2          # the best-screened leans of each gesture that are solved in full
LEAN_GAIN = 0.05       # a lean is kept if it lowers the gesture's score by 5 % at least
SCREEN_SHARE = 0.3     # the screen's share of the time left before the deadline


def lean_library(robot, library: GestureLibrary, result: LibraryResult, settings, *,
                 clock: Clock, seed: int, stay_close: float = 0.0,
                 dense: tuple = ()) -> LibraryResult:
    """
    Return ``result`` with the gestures that reach better with the torso leaned replaced.

    ``settings.expand_shared`` turns it on; a robot without shared joints, or a gesture
    within ``DEFAULT_EXPANSION_THRESHOLD`` mm, is returned unchanged (a fault or a tool:
    whatever changed the structure).  ``dense`` names the motions explored at typical points (not
    leaned).  ``stay_close`` is the run's pull towards the design, as for the arms.
    The lean's search runs within ``clock``, the caller's deadline.
    """
    shared = robot.shared
    if shared is None or not settings.expand_shared:
        return result
    todo = [g.name for g in result.gestures
            if g.tip_error_max_mm > DEFAULT_EXPANSION_THRESHOLD and g.name not in dense
            and g.free_joints]
    if not todo or clock.expired():
        return result
    clock = clock.child(reserve=PUBLISH_RESERVE)     # recover() builds, the node publishes
    screen = clock.child(share=SCREEN_SHARE)
    leans = {name: screen_leans(robot, library[name], result[name], settings, screen)
             for name in todo}
    rng = np.random.default_rng([int(seed), 7])
    tried = _solve_leans(robot, library, result, settings, leans, clock, rng, stay_close)
    return _keep_better(shared, result, tried)


def lean_grid(shared) -> np.ndarray:
    """Return the leans screened (L, S): every joint at each of LEAN_STEPS_DEG, in limits."""
    steps = np.radians(LEAN_STEPS_DEG)
    grid = np.array(list(itertools.product(steps, repeat=len(shared.names))))
    grid = np.clip(grid, shared.lower, shared.upper)
    return np.unique(grid, axis=0)


def screen_leans(robot, gesture, published, settings, clock) -> list:
    """
    Return the LEAN_KEPT best leans (nonzero) for one gesture, screened locally.

    The gesture's worst keyframe (as published) is the one screened: for every lean of
    :func:`lean_grid` its published arm angles are polished (SCREEN_MAXITER iterations,
    every lean in one batch) against its reference moved back by that lean.  A lean
    that does not promise LEAN_GAIN over the upright row, polished alike, is dropped.
    """
    grid = lean_grid(robot.shared)
    moving = robot.changed_model(settings.tool_length_mm, settings.tool_arm)
    split = published.right_columns(len(published.positions[0]))
    rows = np.array(published.positions)
    scorer = SimilarityScore(moving, gesture_targets(gesture), settings.weights,
                             reference_robot=robot)
    k = int(np.argmax(scorer.evaluate(rows[:, :split], rows[:, split:],
                                      np.arange(len(rows)))))
    targets = gesture_targets(gesture, [k]) * len(grid)
    design = {'right': np.array([t.q_right for t in targets]),
              'left': np.array([t.q_left for t in targets])}
    ref = tuple(robot.shared.back(batch_forward(robot, design[side], side), grid)
                for side in ARMS)
    scorer = SimilarityScore(moving, targets, settings.weights, reference_landmarks=ref)
    collision = (CollisionModel(moving, targets, robot.capsules)
                 if settings.collision_check else None)
    base = np.repeat(rows[k:k + 1], len(grid), axis=0)
    problem = PoseProblem(moving, scorer, np.arange(len(grid)),
                          (base[:, :split], base[:, split:]),
                          tuple(robot.locate_joint(j) for j in published.free_joints),
                          collision)
    f = polish(problem, problem.x0[:, None, :], clock, maxiter=SCREEN_MAXITER)[1][:, 0]
    zero = ~np.any(grid, axis=1)
    if not zero.any():           # a shared joint whose limits exclude upright: not leaned
        return []
    upright = float(f[zero][0])
    order = [i for i in np.argsort(f) if np.any(grid[i]) and f[i] < (1.0 - LEAN_GAIN) * upright]
    return [grid[i] for i in order[:LEAN_KEPT]]


def _solve_leans(robot, library, result, settings, leans, clock, rng, stay_close):
    """Solve every gesture copy of every lean in one search; return the best per gesture."""
    copies, names = [], {}
    for name, ts in leans.items():
        for i, t in enumerate(ts):
            copy = f'{name}@lean{i}'
            copies.append(replace(library[name], name=copy))
            names[copy] = (name, t)
    if not copies:
        return {}
    sub = GestureLibrary(tuple(copies), library.source)
    pulled = tuple(g.name for g in copies if len(g.keyframes) > 1)
    options = SearchOptions(stay_close=stay_close, pulled=pulled,
                            leans={copy: t for copy, (_, t) in names.items()})
    out = reconfigure_library(robot, sub, dict(result.locks), settings,
                              seed=int(rng.integers(2 ** 63)), clock=clock,
                              options=options)
    found = {}
    for gesture in out.gestures:
        name, t = names[gesture.name]
        if gesture.status in CUT_SHORT:    # cut short: not published
            continue
        if name not in found or gesture.score_after < found[name][1].score_after:
            found[name] = (t, gesture)
    return found


def _keep_better(shared, result, best):
    """Replace the gestures whose best lean lowers the score enough and adds no collision."""
    gestures, notes = [], list(result.notes)
    for old in result.gestures:
        t, new = best.get(old.name, (None, None))
        if (new is None or not np.any(t) or (new.collides and not old.collides)
                or new.score_after > (1.0 - LEAN_GAIN) * old.score_after):
            gestures.append(old)
            continue
        angles = {n: float(a) for n, a in zip(shared.names, t)}
        said = ', '.join(f'{n} {np.degrees(a):+.1f} deg' for n, a in angles.items())
        # The "before" figures are the locked design's upright, as every gesture's are.
        gestures.append(replace(
            new, name=old.name, shared=angles, wall_time=old.wall_time,
            score_before=old.score_before, score_before_mean=old.score_before_mean,
            tip_error_before_mm=old.tip_error_before_mm,
            max_jump_before_deg=old.max_jump_before_deg,
            free_joints=tuple(new.free_joints) + tuple(shared.names),
            message=f'{new.message.replace(new.name, old.name)}; the torso leans ({said})'))
        notes.append(f'{old.name}: the torso leans ({said}): score {old.score_after:.2f} -> '
                     f'{new.score_after:.2f}, fingertip {old.tip_error_max_mm:.1f} -> '
                     f'{new.tip_error_max_mm:.1f} mm')
    return replace(result, gestures=tuple(gestures), notes=tuple(notes))


def held_lean(robot, faults: dict, measured: dict | None = None) -> tuple[dict, dict]:
    """
    Split ``faults`` into ``(the arms' faults, {shared joint: lock angle})``.

    A joint both arms hang from (a torso) that fails holds the lean where it stuck:
    its reported angle, else its measured one, else 0 (upright, as designed).  Raises
    ValueError (one line) for an angle outside the joint's limits.
    """
    shared = robot.shared
    arms, held = {}, {}
    for joint, angle in dict(faults).items():
        if shared is None or joint not in shared.names:
            arms[joint] = angle
            continue
        if angle is None:
            angle = (measured or {}).get(joint)
        angle = 0.0 if angle is None else float(angle)
        if not (np.isfinite(angle) and robot.joint_within_limits(joint, angle)):
            lower, upper, _ = robot.joint_bounds(joint)
            raise ValueError(f'lock angle of {joint}: {angle!r} rad is outside the joint '
                             f'limits [{lower:.6g}, {upper:.6g}] rad')
        held[joint] = clamp_lock(robot, joint, angle)
    return arms, held


def held_angles(robot, held: dict):
    """Return the shared joints' angles (S,) that ``held`` locks, or None if all upright."""
    if robot.shared is None or not held:
        return None
    t = np.array([held.get(n, 0.0) for n in robot.shared.names])
    return t if np.any(t) else None


def with_held(robot, result: LibraryResult, held: dict, given: dict) -> LibraryResult:
    """
    Return ``result`` with the torso held where it stuck: its locks, faults and leans.

    ``given`` are the shared joints' faults as reported (angle or None).  Every gesture
    holds the lean: the arms were searched against the references moved back by it.
    """
    t = held_angles(robot, held)
    gestures, notes = result.gestures, list(result.notes)
    if t is not None:
        angles = {n: float(a) for n, a in zip(robot.shared.names, t)}
        gestures = tuple(replace(g, shared=angles) for g in gestures)
        said = ', '.join(f'{n} {np.degrees(a):+.1f} deg' for n, a in angles.items())
        notes.append(f'the torso is held where it stuck ({said}): every gesture was '
                     'searched for the arms to make up for it')
    return replace(result, gestures=gestures, notes=tuple(notes),
                   locks=dict(result.locks, **held), faults=dict(result.faults, **given))
