"""
The one result type of a recovery: what the engine returns and the node publishes.

:class:`LibraryResult` is one version of the gesture library, :class:`GestureResult` one
gesture of it.  The engine (:func:`.engine.recover`), the node, the persisted state, the
ROS messages, ``/diagnostics`` and ``namo-recovery solve`` all read these two types, and
each field means one thing everywhere:

- ``score_before``: the worst (largest) keyframe score of the gesture as designed, with
  the failed joints moved to their lock angles and nothing re-optimised;
- ``score_after``: the worst keyframe score of the published gesture;
- ``wall_time``: seconds from the start of the run to the end of the engine's work (the
  same value for every gesture of one library);
- ``status``: ``converged``, ``deadline``, ``cancelled`` or ``unchanged``.

Free of ROS; JSON round trip with :meth:`LibraryResult.to_dict` / ``from_dict``.
"""

from dataclasses import dataclass, field
import math


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


@dataclass(frozen=True)
class GestureResult:
    """One gesture of a published library version, with its reconfiguration figures."""

    name: str
    times: tuple            # time_from_start (s) per keyframe
    positions: tuple        # per keyframe: 14 angles (rad), right arm first
    score_before: float = 0.0
    score_after: float = 0.0
    wall_time: float = 0.0
    status: str = 'unchanged'
    message: str = ''
    collides: bool = False
    breakdown: dict = field(default_factory=dict)
    stage: int = 1
    colliding_pairs: tuple = ()
    method: str = 'keyframes'    # kriging, per_point or keyframes (every one explored)
    typical_points: int = 0
    tip_error_mm: float = 0.0    # mean fingertip distance to the designed path
    max_jump_deg: float = 0.0    # largest joint step between successive keyframes

    def to_dict(self):
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
        }

    @classmethod
    def from_dict(cls, doc):
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
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            if isinstance(exc, MalformedResult):
                raise
            raise MalformedResult(f'malformed gesture entry: {exc!r}') from None


@dataclass(frozen=True)
class LibraryResult:
    """
    One version of the gesture library, as published on ``/gesture_library``.

    ``faults`` is the fault set it was computed for (joint -> requested lock angle or
    None), ``locks`` the lock angles actually used (rad).
    """

    gestures: tuple
    faults: dict = field(default_factory=dict)
    locks: dict = field(default_factory=dict)
    frozen_arms: tuple = ()
    wall_time: float = 0.0
    deadline: float = 0.0
    deadline_met: bool = True
    success: bool = True
    cancelled: bool = False
    settings: dict = field(default_factory=dict)
    tool_mm: float = 0.0
    tool_arm: str = 'right'

    @property
    def names(self):
        """Gesture names in library order."""
        return tuple(g.name for g in self.gestures)

    def to_dict(self):
        """Return a JSON-ready dict."""
        return {
            'gestures': [g.to_dict() for g in self.gestures],
            'faults': dict(self.faults), 'locks': dict(self.locks),
            'frozen_arms': list(self.frozen_arms), 'wall_time': self.wall_time,
            'deadline': self.deadline, 'deadline_met': self.deadline_met,
            'success': self.success, 'cancelled': self.cancelled,
            'settings': dict(self.settings),
            'tool_mm': self.tool_mm, 'tool_arm': self.tool_arm,
        }

    @classmethod
    def from_dict(cls, doc):
        """Rebuild from :meth:`to_dict` output; raise MalformedResult if malformed."""
        try:
            gestures = tuple(GestureResult.from_dict(g) for g in doc['gestures'])
            if not gestures:
                raise MalformedResult('library: no gestures')
            faults = {str(k): (None if v is None else finite_number(v, 'fault angle'))
                      for k, v in dict(doc.get('faults', {})).items()}
            locks = {str(k): finite_number(v, 'lock angle') for k, v in dict(doc['locks']).items()}
            return cls(
                gestures=gestures, faults=faults, locks=locks,
                frozen_arms=tuple(str(a) for a in doc.get('frozen_arms', ())),
                wall_time=number(doc.get('wall_time', 0.0)),
                deadline=number(doc.get('deadline', 0.0)),
                deadline_met=bool(doc.get('deadline_met', True)),
                success=bool(doc.get('success', True)),
                cancelled=bool(doc.get('cancelled', False)),
                settings=dict(doc.get('settings', {})),
                tool_mm=number(doc.get('tool_mm', 0.0)),
                tool_arm=str(doc.get('tool_arm', 'right')),
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            if isinstance(exc, MalformedResult):
                raise
            raise MalformedResult(f'malformed library: {exc!r}') from None


def reference_result(library, deadline=0.0, settings=None):
    """Return the reference library as a LibraryResult (no faults, every score 0)."""
    gestures = tuple(
        GestureResult(name=g.name,
                      times=tuple(float(kf.time_from_start) for kf in g.keyframes),
                      positions=tuple(tuple(float(a) for a in kf.positions())
                                      for kf in g.keyframes),
                      status='unchanged', message='reference gesture')
        for g in library)
    return LibraryResult(gestures=gestures, deadline=deadline, settings=dict(settings or {}))


def summary(result):
    """Return the one-line summary of a library version that a person reads."""
    tool = result.tool_mm > 0
    if not result.faults and not result.locks and not tool:
        return (f'no faults: the reference library is published '
                f'({len(result.gestures)} gestures, unchanged)')
    changes = [f'{j} at {math.degrees(a):.2f} deg' for j, a in result.locks.items()]
    if tool:
        changes.append(f'a {result.tool_mm:g} mm tool in the {result.tool_arm} hand')
    locks = ', '.join(changes)
    finite = sum(1 for g in result.gestures if math.isfinite(g.score_after))
    timing = (f'deadline {result.deadline:.3f} s '
              f"{'met' if result.deadline_met else 'MISSED, best found so far used'}")
    parts = [f'{g.name} {g.score_before:.2f} -> {g.score_after:.2f} in {g.wall_time:.3f} s'
             + ('' if g.status in ('converged', 'unchanged') else f' ({g.status})')
             + (' (both arms)' if g.stage == 2 else '')
             + (f" COLLIDES ({', '.join(g.colliding_pairs)})" if g.collides else '')
             for g in result.gestures]
    text = (f"{'reconfigured' if result.success else 'FAILED to fully reconfigure'} "
            f'{finite}/{len(result.gestures)} gestures in {result.wall_time:.3f} s '
            f'({timing}) for {locks}')
    if result.frozen_arms:
        text += f"; frozen arm(s): {', '.join(result.frozen_arms)}"
    if result.cancelled:
        text += '; run was cancelled'
    return text + ': ' + '; '.join(parts)
