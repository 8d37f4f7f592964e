"""
The one result type of a recovery: what the engine returns and the node publishes.

:class:`LibraryResult` is one version of the gesture library, :class:`GestureResult` one
gesture of it.  The engine (:func:`.engine.recover`), the node, the persisted state, the
ROS messages, ``/diagnostics``, ``namo-recovery solve`` and the benchmarks all read
these two types, and each field means one thing everywhere (the class docstrings list
them all).  The main ones:

- ``score_before``: the worst (largest) keyframe score of the gesture as designed, with
  the failed joints moved to their lock angles and nothing re-optimised;
- ``score_after``: the worst keyframe score of the published gesture;
- ``wall_time``: seconds from the start of the run to the end of the engine's work (the
  same value for every gesture of one library);
- ``deadline`` / ``deadline_met``: the deadline a fault set was answered within; a
  refined version keeps its deadline result's, and ``refined_after`` says how long after
  that result the refinement found it;
- ``status``: ``converged``, ``deadline``, ``cancelled``, ``frozen`` or ``unchanged``
  (:data:`CUT_SHORT`: the two of a search cut short).

The stages of the engine build these types too: the keyframe search
(:func:`.keyframes.reconfigure_library`) and the motion adaptation
(:func:`.motion.adapt_library`) return a :class:`LibraryResult`, so there is no other
result shape to copy from.  A mean and a worst over keyframes always have two names
(``score_before_mean`` / ``score_before``, ``score_mean`` / ``score_after``).
Free of ROS; JSON round trip with :meth:`LibraryResult.to_dict` / ``from_dict``, where
every field added later has a default so that older state files still load.
"""

from dataclasses import dataclass, field
import math
from typing import Optional

import numpy as np

from . import pacing

# The statuses of a search the deadline or a cancel request cut short (its best so far).
CUT_SHORT = ('deadline', 'cancelled')


class MalformedResult(ValueError):
    """A serialised result that cannot be read back (names what is wrong)."""


def number(value):
    """Return ``value`` as a float, or raise MalformedResult if it is not a number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MalformedResult(f'expected a number, got {value!r}'[:200])
    return float(value)


def finite_number(value, what):
    """Return ``value`` as a finite float, or raise MalformedResult naming ``what``."""
    value = number(value)
    if not math.isfinite(value):
        raise MalformedResult(f'{what}: expected a finite number, got {value!r}')
    return value


def optional_number(value):
    """Return ``value`` as a float, None as None; raise MalformedResult otherwise."""
    return None if value is None else number(value)


def arm_split(value, positions) -> int:
    """Return a stored ``right_joints``: an int from 0 to a row's length (ValueError)."""
    if isinstance(value, bool) or not isinstance(value, int) or not (
            0 <= value <= min(len(p) for p in positions)):
        raise ValueError(f'right_joints: expected a whole number of columns from 0 to '
                         f'{min(len(p) for p in positions)}, got {value!r}')
    return value


@dataclass(frozen=True)
class GestureResult:
    """
    One gesture of a published library version, with its reconfiguration figures.

    Scores are the similarity score (lower is better, 0 = the reference).  Over the
    gesture's keyframes (every point of a motion, Kriging-interpolated ones included):

    - ``times``: time_from_start (s) per keyframe; ``positions``: per keyframe the J
      joint angles (rad), the right arm's joints then the left arm's (see
      ``right_joints``), as published;
    - ``score_before`` / ``score_before_mean``: worst / mean keyframe score as designed
      with the locks applied and nothing re-optimised;
    - ``score_after`` / ``score_mean``: worst / mean keyframe score as published;
    - ``breakdown``: the score's components (unweighted: mm, palm in deg) at the worst
      published keyframe, the one ``score_after`` is the score of (empty for the
      reference library);
    - ``stage``: 2 if the healthy arm moved too (two-handed gestures), else 1;
      ``stage1_score``: worst explored keyframe score at the end of stage 1, before
      the healthy arm joined (None when no keyframe search ran for this gesture);
    - ``expansion_stage``: staged DOF expansion stages used (0: the designed joints);
      ``free_joints``: the joint names searched (after any expansion or stage 2);
    - ``nfev``: objective evaluations spent on this gesture (a batched evaluation of
      the whole library counts for each gesture in proportion to its rows);
    - ``wall_time``: seconds of the whole run (the same for every gesture);
    - ``status``: ``converged``, ``deadline``, ``cancelled``, ``frozen`` or
      ``unchanged``; ``message``: one line for a person;
    - ``collides`` / ``colliding_pairs``: with the collision check on, whether any
      keyframe's capsules touch and which pairs (False / () when the check is off);
    - ``method``: ``kriging`` (typical points + Kriging), ``per_point`` (every point
      explored in order) or ``keyframes`` (every keyframe explored in one batch);
      ``typical_indices``: the keyframes explored by the keyframe search (all of them
      unless ``kriging``); ``typical_points``: how many;
      ``kriging_sigma_deg``: the Kriging standard deviation per keyframe (deg), empty
      when nothing was interpolated;
    - fingertip distance to the designed path (mm; the larger of the two hands for a
      two-handed gesture): ``tip_error_before_mm`` mean with the locks applied,
      ``tip_error_mm`` mean and ``tip_error_max_mm`` largest as published;
    - largest joint step between successive keyframes (deg): ``max_jump_designed_deg``
      as designed, ``max_jump_before_deg`` with the locks applied, ``max_jump_deg`` as
      published;
    - ``speed_ratio``: playability, the bound on the player's peak joint speed over the
      joint's velocity limit (:func:`.pacing.speed_ratio`; at most 1: played as timed,
      not stretched; 0 for a single keyframe);
    - ``right_joints``: how many of a row's columns are the right arm's (the rest are
      the left arm's; the arms may differ in joint count); 0 when not known, read as
      half of them (arms of one joint count);
    - ``shared``: the angles (rad) of the joints shared by both arms (a torso) held
      through the gesture, by name, when the staged expansion leaned it
      (:mod:`.lean`); empty: those joints stay at 0, as designed.
    """

    name: str
    times: tuple
    positions: tuple
    score_before: float = 0.0
    score_after: float = 0.0
    wall_time: float = 0.0
    status: str = 'unchanged'
    message: str = ''
    collides: bool = False
    breakdown: dict = field(default_factory=dict)
    stage: int = 1
    colliding_pairs: tuple = ()
    method: str = 'keyframes'
    typical_points: int = 0
    tip_error_mm: float = 0.0
    max_jump_deg: float = 0.0
    score_before_mean: float = 0.0
    score_mean: float = 0.0
    stage1_score: Optional[float] = None
    expansion_stage: int = 0
    free_joints: tuple = ()
    nfev: int = 0
    typical_indices: tuple = ()
    kriging_sigma_deg: tuple = ()
    tip_error_before_mm: float = 0.0
    tip_error_max_mm: float = 0.0
    max_jump_designed_deg: float = 0.0
    max_jump_before_deg: float = 0.0
    speed_ratio: float = 0.0
    right_joints: int = 0
    shared: dict = field(default_factory=dict)

    def right_columns(self, width: int) -> Optional[int]:
        """
        Return how many of a row's ``width`` columns are the right arm's, or None.

        ``right_joints``, or, when it is not known (0), half of an even row (arms of one
        joint count); None for an odd row whose split is not known.
        """
        if self.right_joints:
            return self.right_joints
        return width // 2 if width % 2 == 0 else None

    @property
    def keyframes(self) -> tuple:
        """Return the published keyframes as :class:`~..model.gestures.Keyframe` objects."""
        from ..model.gestures import Keyframe
        out = []
        for t, p in zip(self.times, self.positions):
            split = self.right_columns(len(p))
            if split is None:
                raise ValueError(f'{self.name}: {len(p)} angles per row and right_joints not '
                                 'known; expected right_joints for arms of two joint counts')
            out.append(Keyframe(t, np.array(p[:split]), np.array(p[split:])))
        return tuple(out)

    def to_dict(self) -> dict:
        """Return a JSON-ready dict."""
        return {
            'name': self.name, 'times': list(self.times),
            'positions': [list(p) for p in self.positions],
            'score_before': self.score_before, 'score_after': self.score_after,
            'wall_time': self.wall_time, 'status': self.status, 'message': self.message,
            'collides': self.collides, 'breakdown': dict(self.breakdown),
            'stage': self.stage, 'colliding_pairs': list(self.colliding_pairs),
            'method': self.method, 'typical_points': self.typical_points,
            'tip_error_mm': self.tip_error_mm, 'max_jump_deg': self.max_jump_deg,
            'score_before_mean': self.score_before_mean, 'score_mean': self.score_mean,
            'stage1_score': self.stage1_score, 'expansion_stage': self.expansion_stage,
            'free_joints': list(self.free_joints), 'nfev': self.nfev,
            'typical_indices': list(self.typical_indices),
            'kriging_sigma_deg': list(self.kriging_sigma_deg),
            'tip_error_before_mm': self.tip_error_before_mm,
            'tip_error_max_mm': self.tip_error_max_mm,
            'max_jump_designed_deg': self.max_jump_designed_deg,
            'max_jump_before_deg': self.max_jump_before_deg,
            'speed_ratio': self.speed_ratio, 'right_joints': self.right_joints,
            'shared': dict(self.shared),
        }

    @classmethod
    def from_dict(cls, doc: dict) -> 'GestureResult':
        """Rebuild from :meth:`to_dict` output; raise MalformedResult if malformed."""
        try:
            times = tuple(finite_number(t, 'time') for t in doc['times'])
            positions = tuple(tuple(finite_number(a, 'angle') for a in p)
                              for p in doc['positions'])
            if len(times) != len(positions) or not times:
                raise MalformedResult(f"gesture {doc.get('name')!r}: {len(times)} times for "
                                      f'{len(positions)} keyframes')
            return cls(
                name=str(doc['name']), times=times, positions=positions,
                score_before=number(doc.get('score_before', 0.0)),
                score_after=number(doc.get('score_after', 0.0)),
                wall_time=number(doc.get('wall_time', 0.0)),
                status=str(doc.get('status', '')), message=str(doc.get('message', '')),
                collides=bool(doc.get('collides', False)),
                breakdown={str(k): number(v) for k, v in dict(doc.get('breakdown', {})).items()},
                stage=int(doc.get('stage', 1)),
                colliding_pairs=tuple(str(p) for p in doc.get('colliding_pairs', ())),
                method=str(doc.get('method', 'keyframes')),
                typical_points=int(doc.get('typical_points', 0)),
                tip_error_mm=number(doc.get('tip_error_mm', 0.0)),
                max_jump_deg=number(doc.get('max_jump_deg', 0.0)),
                score_before_mean=number(doc.get('score_before_mean', 0.0)),
                score_mean=number(doc.get('score_mean', 0.0)),
                stage1_score=optional_number(doc.get('stage1_score')),
                expansion_stage=int(doc.get('expansion_stage', 0)),
                free_joints=tuple(str(j) for j in doc.get('free_joints', ())),
                nfev=int(doc.get('nfev', 0)),
                typical_indices=tuple(int(i) for i in doc.get('typical_indices', ())),
                kriging_sigma_deg=tuple(number(v) for v in doc.get('kriging_sigma_deg', ())),
                tip_error_before_mm=number(doc.get('tip_error_before_mm', 0.0)),
                tip_error_max_mm=number(doc.get('tip_error_max_mm', 0.0)),
                max_jump_designed_deg=number(doc.get('max_jump_designed_deg', 0.0)),
                max_jump_before_deg=number(doc.get('max_jump_before_deg', 0.0)),
                speed_ratio=number(doc.get('speed_ratio', 0.0)),
                right_joints=arm_split(doc.get('right_joints', 0), positions),
                shared={str(k): finite_number(v, 'angle')
                        for k, v in dict(doc.get('shared') or {}).items()},
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            if isinstance(exc, MalformedResult):
                raise
            raise MalformedResult(f'malformed gesture entry: {exc!r}') from None


@dataclass(frozen=True)
class LibraryResult:
    """
    One version of the gesture library, as published on ``/gesture_library``.

    - ``gestures``: a :class:`GestureResult` per gesture, in library order (also
      ``result[name]``);
    - ``faults``: the fault set it was computed for (joint -> requested lock angle in
      rad, or None when the lock strategy chose it); ``locks``: the lock angles actually
      used (rad); ``frozen_arms``: arms all of whose joints are locked;
    - ``wall_time``: seconds of the run (of a refined version: of the one search that
      found it); ``deadline``: the run's budget in seconds (None: no deadline);
      ``deadline_met``: no gesture was cut short by it or by a cancel; a refined version
      keeps both of the deadline result it refines (its searches' own budgets are the
      refinement's, not a deadline); ``cancelled``: a cancel request cut the run short;
      ``success``: the deadline was met and every gesture has a finite score;
    - ``refined_after``: of a refined version, seconds from the start of the
      refinement (the deadline result just published) to the end of the search that
      found it (None otherwise, and in files written before it was a field);
      ``refines_version``: the library version number of that deadline result, in
      the node that refined it (0: unknown);
    - ``settings``: the :class:`~.engine.RecoverySettings` of the run, as a dict named
      like the node's parameters; ``seed``: the seed the run used (None: not recorded);
      ``notes``: what a person should know about the run (lock choice, skipped stages);
    - ``tool_mm`` / ``tool_arm``: a tool lengthening that hand (mm, 0: none);
    - ``nfev``: objective evaluations of the whole run;
    - ``origin``: how this version was obtained: ``reference`` (no structure change),
      ``deadline`` (a search within the deadline), ``unbounded`` (a search with no
      deadline), ``table`` (the node's precomputed contingency table) or ``refined`` (the
      node's background refinement after a deadline result) or ``explored`` (a motion
      explored on the robot by the gesture player, scored by what its tracker measured);
    - ``corrections``: the structural corrections learned on the robot that the search
      ran on, per arm (``ArmCorrection.to_dict()``: ``groups``, ``params``, what they
      were measured against); {} for the nominal model.
    """

    gestures: tuple
    faults: dict = field(default_factory=dict)
    locks: dict = field(default_factory=dict)
    frozen_arms: tuple = ()
    wall_time: float = 0.0
    deadline: Optional[float] = 0.0
    deadline_met: bool = True
    success: bool = True
    cancelled: bool = False
    settings: dict = field(default_factory=dict)
    tool_mm: float = 0.0
    tool_arm: str = 'right'
    seed: Optional[int] = None
    notes: tuple = ()
    nfev: int = 0
    origin: str = 'deadline'
    refined_after: Optional[float] = None
    refines_version: int = 0
    corrections: dict = field(default_factory=dict)

    @property
    def names(self) -> tuple:
        """Gesture names in library order."""
        return tuple(g.name for g in self.gestures)

    @property
    def speed_ratio(self) -> float:
        """Return the library's playability: the largest gesture ``speed_ratio``."""
        return float(max((g.speed_ratio for g in self.gestures), default=0.0))

    @property
    def total_score(self) -> float:
        """Return the sum over the gestures of ``score_after`` (the library total)."""
        return float(sum(g.score_after for g in self.gestures))

    def __getitem__(self, name: str) -> GestureResult:
        """Return the :class:`GestureResult` named ``name`` (KeyError naming the choices)."""
        for g in self.gestures:
            if g.name == name:
                return g
        raise KeyError(f'unknown gesture {name!r}; expected one of {", ".join(self.names)}')

    def to_dict(self) -> dict:
        """Return a JSON-ready dict."""
        return {
            'gestures': [g.to_dict() for g in self.gestures],
            'faults': dict(self.faults), 'locks': dict(self.locks),
            'frozen_arms': list(self.frozen_arms), 'wall_time': self.wall_time,
            'deadline': self.deadline, 'deadline_met': self.deadline_met,
            'success': self.success, 'cancelled': self.cancelled,
            'settings': dict(self.settings),
            'tool_mm': self.tool_mm, 'tool_arm': self.tool_arm,
            'seed': self.seed, 'notes': list(self.notes), 'nfev': self.nfev,
            'origin': self.origin, 'refined_after': self.refined_after,
            'refines_version': self.refines_version,
            'corrections': {side: dict(c) for side, c in self.corrections.items()},
        }

    @classmethod
    def from_dict(cls, doc: dict) -> 'LibraryResult':
        """
        Rebuild from :meth:`to_dict` output; raise MalformedResult if malformed.

        Files written before ``seed`` and ``notes`` were fields kept them in
        ``settings``; they are read from there.
        """
        try:
            gestures = tuple(GestureResult.from_dict(g) for g in doc['gestures'])
            if not gestures:
                raise MalformedResult('library: no gestures')
            faults = {str(k): (None if v is None else finite_number(v, 'fault angle'))
                      for k, v in dict(doc.get('faults', {})).items()}
            locks = {str(k): finite_number(v, 'lock angle') for k, v in dict(doc['locks']).items()}
            settings = dict(doc.get('settings', {}))
            # Older files kept the seed and the notes in ``settings``.
            seed = doc['seed'] if 'seed' in doc else settings.pop('seed', None)
            notes = doc['notes'] if 'notes' in doc else settings.pop('notes', ())
            return cls(
                gestures=gestures, faults=faults, locks=locks,
                frozen_arms=tuple(str(a) for a in doc.get('frozen_arms', ())),
                wall_time=number(doc.get('wall_time', 0.0)),
                deadline=optional_number(doc.get('deadline', 0.0)),
                deadline_met=bool(doc.get('deadline_met', True)),
                success=bool(doc.get('success', True)),
                cancelled=bool(doc.get('cancelled', False)),
                settings=settings,
                tool_mm=number(doc.get('tool_mm', 0.0)),
                tool_arm=str(doc.get('tool_arm', 'right')),
                seed=None if seed is None else int(seed),
                notes=tuple(str(n) for n in notes),
                nfev=int(doc.get('nfev', 0)),
                origin=str(doc.get('origin', 'deadline')),
                refined_after=optional_number(doc.get('refined_after')),
                refines_version=int(doc.get('refines_version', 0)),
                corrections={str(side): dict(c) for side, c in
                             dict(doc.get('corrections', {})).items()},
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            if isinstance(exc, MalformedResult):
                raise
            raise MalformedResult(f'malformed library: {exc!r}') from None


def reference_result(library, deadline: Optional[float] = 0.0, settings: Optional[dict] = None,
                     seed: Optional[int] = None, velocity_limits=None) -> LibraryResult:
    """
    Return the reference library as a LibraryResult (no faults, every score 0).

    With the robot's ``velocity_limits`` each gesture's ``speed_ratio`` is the
    design's own (0 without them).
    """
    def ratio(g):
        if velocity_limits is None:
            return 0.0
        times = [kf.time_from_start for kf in g.keyframes]
        return pacing.speed_ratio(velocity_limits, times, g.joint_matrix())

    gestures = tuple(
        GestureResult(name=g.name,
                      times=tuple(float(kf.time_from_start) for kf in g.keyframes),
                      positions=tuple(tuple(float(a) for a in kf.positions())
                                      for kf in g.keyframes),
                      status='unchanged', message='reference gesture',
                      speed_ratio=ratio(g), right_joints=len(g.keyframes[0].right))
        for g in library)
    return LibraryResult(gestures=gestures, deadline=deadline, settings=dict(settings or {}),
                         seed=seed, origin='reference')


ORIGIN_TEXT = {'deadline': ' by a live search',
               'unbounded': ' by a search without deadline',
               'table': ' from the contingency table',
               'explored': ' explored on the robot'}    # refined: in timing_text


def deadline_text(result: LibraryResult) -> str:
    """Return how the deadline went, e.g. ``deadline 1.000 s met`` or ``no deadline``."""
    if result.deadline is None:
        return 'no deadline'
    if result.origin == 'refined':        # the deadline result's, named by its version
        by = (f'version {result.refines_version}' if result.refines_version else
              'the deadline result')
        met = 'met' if result.deadline_met else 'missed'
        return f'deadline {result.deadline:.3f} s {met} by {by}'
    return (f'deadline {result.deadline:.3f} s '
            f"{'met' if result.deadline_met else 'MISSED, best found so far used'}")


def timing_text(result: LibraryResult) -> str:
    """
    Return when a library version was made, for :func:`summary`.

    A version found by the refinement reports the refinement's time and the deadline
    (met by the first version) apart: ``refined 7.761 s after the deadline result
    (deadline 1.000 s met by version 4)``; a contingency-table hit the search made in
    advance and the deadline it is served within; any other version its run and its
    deadline: ``in 0.080 s (deadline 1.000 s met)``.
    """
    if result.origin == 'table':          # served now; its search ran in advance
        return (f'from a search of {result.wall_time:.3f} s made in advance '
                f'({deadline_text(result)})')
    if result.origin != 'refined':
        return f'in {result.wall_time:.3f} s ({deadline_text(result)})'
    if result.refined_after is None:      # written before refined_after was a field
        return 'refined in the background after the deadline result'
    return (f'refined {result.refined_after:.3f} s after the deadline result '
            f'({deadline_text(result)})')


def summary(result: LibraryResult) -> str:
    """Return the one-line summary of a library version that a person reads."""
    tool = result.tool_mm > 0
    if not result.faults and not result.locks and not tool and not result.corrections:
        return (f'no faults: the reference library is published '
                f'({len(result.gestures)} gestures, unchanged)')
    changes = [f'{j} at {math.degrees(a):.2f} deg' for j, a in result.locks.items()]
    if tool:
        changes.append(f'a {result.tool_mm:g} mm tool in the {result.tool_arm} hand')
    changes += [f'the {side} arm as measured ({", ".join(c.get("groups", ())) or "nominal"})'
                for side, c in sorted(result.corrections.items())]
    locks = ', '.join(changes)
    finite = sum(1 for g in result.gestures if math.isfinite(g.score_after))
    parts = [f'{g.name} {g.score_before:.2f} -> {g.score_after:.2f} in {g.wall_time:.3f} s'
             + ('' if g.status in ('converged', 'unchanged') else f' ({g.status})')
             + (' (both arms)' if g.stage == 2 else '')
             + (f" COLLIDES ({', '.join(g.colliding_pairs)})" if g.collides else '')
             for g in result.gestures]
    text = (f"{'reconfigured' if result.success else 'FAILED to fully reconfigure'} "
            f'{finite}/{len(result.gestures)} gestures {timing_text(result)} for {locks}')
    text += ORIGIN_TEXT.get(result.origin, '')
    if result.frozen_arms:
        text += f"; frozen arm(s): {', '.join(result.frozen_arms)}"
    if result.cancelled:
        text += '; run was cancelled'
    return text + ': ' + '; '.join(parts)
