"""
The gesture player's explored motions on disk (its ``explore_state_file``).

Free of ROS.  What an exploration on the robot learned outlives the player: per gesture,
the library keyframes it was explored from (so that it is served again only for that
very motion), the explored keyframes, what the tracker measured, and the structural
correction ours fitted (``explore.corrections.Correction``'s ``groups`` and ``params``,
plain lists).  One JSON document, written atomically (:mod:`..files`) after every
exploration; a file that cannot be read is a one-line ValueError naming it and the key.
"""

from dataclasses import dataclass
import json
import math
from pathlib import Path

import numpy as np

from ..files import write_text_atomically

FORMAT = 'namo_fault_recovery explored motions 1'


@dataclass(frozen=True)
class StoredMotion:
    """One explored motion as kept on disk (angles in rad, errors in mm)."""

    name: str
    side: str
    joint_names: tuple
    times: tuple
    base: tuple                  # per keyframe, the library's angles it was explored from
    positions: tuple             # per keyframe, the explored angles (the same joints)
    measured_error_mm: tuple     # at the typical points, as the tracker measured them
    trials: int = 0
    method: str = 'secant'
    groups: tuple = ()           # the fitted Correction's groups ...
    params: tuple = ()           # ... and its values (mm or deg), one tuple per group

    def to_dict(self) -> dict:
        """Return the JSON-ready dict of this motion."""
        return {'name': self.name, 'side': self.side, 'joint_names': list(self.joint_names),
                'times': list(self.times), 'base': [list(q) for q in self.base],
                'positions': [list(q) for q in self.positions],
                'measured_error_mm': list(self.measured_error_mm), 'trials': self.trials,
                'method': self.method, 'groups': list(self.groups),
                'params': [list(p) for p in self.params]}


def _angles(rows, width, what):
    out = tuple(tuple(float(a) for a in row) for row in rows)
    if any(len(row) != width or not all(math.isfinite(a) for a in row) for row in out):
        raise ValueError(f'{what}: expected {width} finite angles per keyframe')
    return out


def _motion(doc) -> StoredMotion:
    names = tuple(str(n) for n in doc['joint_names'])
    times = tuple(float(t) for t in doc['times'])
    base = _angles(doc['base'], len(names), 'base')
    positions = _angles(doc['positions'], len(names), 'positions')
    if not times or len(base) != len(times) or len(positions) != len(times):
        raise ValueError(f'{len(times)} times for {len(base)} base and {len(positions)} '
                         f'explored keyframes')
    return StoredMotion(str(doc['name']), str(doc['side']), names, times, base, positions,
                        tuple(float(e) for e in doc['measured_error_mm']),
                        int(doc.get('trials', 0)), str(doc.get('method', 'secant')),
                        tuple(str(g) for g in doc.get('groups', ())),
                        tuple(tuple(float(v) for v in p) for p in doc.get('params', ())))


def save_motions(path, motions: dict) -> None:
    """Write ``{gesture: StoredMotion}`` to ``path`` atomically (OSError if it cannot)."""
    doc = {'format': FORMAT, 'motions': [m.to_dict() for m in motions.values()]}
    write_text_atomically(path, json.dumps(doc, indent=1))


def load_motions(path) -> dict:
    """Return ``{gesture: StoredMotion}`` from ``path`` ({} if there is no such file)."""
    path = Path(path)
    if not path.exists():
        return {}
    try:
        doc = json.loads(path.read_text(encoding='utf-8'))
        if doc.get('format') != FORMAT:
            raise ValueError(f'format {doc.get("format")!r}; expected {FORMAT!r}')
        out = {}
        for i, entry in enumerate(doc['motions']):
            try:
                motion = _motion(entry)
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(f'key motions[{i}]: {exc}') from None
            out[motion.name] = motion
        return out
    except (OSError, KeyError, TypeError, AttributeError, ValueError) as exc:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f'{path}: {text}') from None


def stored(name: str, side: str, joint_names, times, base, positions, result) -> StoredMotion:
    """Return the StoredMotion of an ExploredMotion ``result`` served as ``positions``."""
    model = result.model
    return StoredMotion(
        name, side, tuple(joint_names), tuple(float(t) for t in times),
        tuple(tuple(float(a) for a in q) for q in np.asarray(base)),
        tuple(tuple(float(a) for a in q) for q in np.asarray(positions)),
        tuple(float(e) for e in result.measured_error_mm), int(result.trials), result.method,
        tuple(model.groups) if model is not None else (),
        tuple(tuple(float(v) for v in p) for p in model.params) if model is not None else ())
