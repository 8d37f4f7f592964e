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
unchanged.  The leans tried are a grid around upright (``LEAN_SPAN_DEG`` either way
of each shared joint, within its limits), then a grid half as wide around the best,
all copies of all gestures solved in one batched search per round, each round within
``LEAN_SHARE`` of the time left (a gesture that no lean of the first round improves is
not refined).  A lean is kept
only if it lowers the gesture's score by ``LEAN_GAIN`` and adds no collision: leaning
the torso is a larger motion for a guest than the arms' own.  A dense motion (one
explored at typical points) is not leaned.
"""

from dataclasses import replace
import itertools

import numpy as np

from .keyframes import DEFAULT_EXPANSION_THRESHOLD, reconfigure_library, SearchOptions
from .result import LibraryResult
from ..model.gestures import GestureLibrary
from ..optimize.base import Clock

LEAN_SPAN_DEG = 15.0   # the first round's lean either way of upright, per shared joint
LEAN_ROUNDS = 2        # rounds of grids, each half as wide around the best so far
LEAN_GAIN = 0.05       # a lean is kept if it lowers the gesture's score by 5 % at least
LEAN_SHARE = 0.5       # each round's share of the time left before the deadline


def lean_library(robot, library: GestureLibrary, result: LibraryResult, settings, *,
                 clock: Clock, seed: int, stay_close: float = 0.0,
                 dense: tuple = ()) -> LibraryResult:
    """
    Return ``result`` with the gestures that reach better with the torso leaned replaced.

    ``settings.expand_shared`` turns it on; a robot without shared joints, a result
    without a changed structure, or a gesture within ``DEFAULT_EXPANSION_THRESHOLD`` mm
    is returned unchanged.  ``dense`` names the motions explored at typical points (not
    leaned).  ``stay_close`` is the run's pull towards the design, as for the arms.
    The lean's search runs within ``clock``, the caller's deadline.
    """
    shared = robot.shared
    if shared is None or not settings.expand_shared or not result.locks:
        return result
    todo = [g.name for g in result.gestures
            if g.tip_error_max_mm > DEFAULT_EXPANSION_THRESHOLD and g.name not in dense]
    if not todo:
        return result
    best = {name: (np.zeros(len(shared.names)), result[name]) for name in todo}
    span = np.radians(LEAN_SPAN_DEG)
    rng = np.random.default_rng([int(result.seed or 0), 7])
    for _ in range(LEAN_ROUNDS):
        if not todo or clock.expired():
            break
        leans = {name: _grid(shared, best[name][0], span) for name in todo}
        tried = _solve_leans(robot, library, result, settings, leans,
                             clock.child(share=LEAN_SHARE), rng, stay_close)
        for name, (t, gesture) in tried.items():
            if gesture.score_after < best[name][1].score_after:
                best[name] = (t, gesture)
        # A gesture that no lean of this round improved is not refined around upright.
        todo = [name for name in todo if np.any(best[name][0])]
        span /= 2.0
    return _keep_better(shared, result, best)


def _grid(shared, centre, span):
    """
    Return the leans around ``centre``: every joint at -span, 0 or +span, within limits.

    Two shared joints give 8 leans around the centre (the 3 x 3 grid less its middle).
    """
    out = []
    for step in itertools.product((-span, 0.0, span), repeat=len(centre)):
        t = np.clip(centre + np.array(step), shared.lower, shared.upper)
        if np.any(step) and not any(np.allclose(t, u) for u in out + [centre]):
            out.append(t)
    return out


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
        if gesture.status in ('deadline', 'cancelled') and clock.expired():
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
        gestures.append(replace(
            new, name=old.name, shared=angles, wall_time=old.wall_time,
            free_joints=tuple(new.free_joints) + tuple(shared.names),
            message=f'{new.message.replace(new.name, old.name)}; the torso leans ({said})'))
        notes.append(f'{old.name}: the torso leans ({said}): score {old.score_after:.2f} -> '
                     f'{new.score_after:.2f}, fingertip {old.tip_error_max_mm:.1f} -> '
                     f'{new.tip_error_max_mm:.1f} mm')
    return replace(result, gestures=tuple(gestures), notes=tuple(notes))
