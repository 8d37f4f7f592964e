"""
The reference gesture library: keyframes per gesture, loaded from a validated YAML file.

Angles are in degrees in the file (with an explicit units key) and in radians in memory.
"""

from dataclasses import dataclass
import math
from pathlib import Path
import re

import numpy as np

from . import _yaml_checks as chk
from .errors import ConfigError
from .resources import config_path, DEFAULT_GESTURE_FILE
from .robot_model import ARMS, N_JOINTS

_NAME_RE = re.compile(r'^[a-z][a-z0-9_]*$')


@dataclass(frozen=True)
class Keyframe:
    """Joint angles (rad) of both arms at ``time_from_start`` seconds."""

    time_from_start: float
    right: np.ndarray
    left: np.ndarray

    def arm(self, side):
        """Return the angles of one arm."""
        return self.right if side == 'right' else self.left

    def positions(self):
        """All 14 angles, right arm first (the order of RobotModel.joint_names)."""
        return np.concatenate((self.right, self.left))


@dataclass(frozen=True)
class Gesture:
    """One emblematic gesture: its keyframes and the arms that take part in it."""

    name: str
    arms: tuple
    two_handed: bool
    keyframes: tuple
    description: str = ''


@dataclass(frozen=True)
class GestureLibrary:
    """An ordered collection of gestures, addressable by name."""

    gestures: tuple
    source: str = '<memory>'

    @property
    def names(self):
        """Gesture names in library order."""
        return tuple(g.name for g in self.gestures)

    def __len__(self):
        return len(self.gestures)

    def __iter__(self):
        return iter(self.gestures)

    def __getitem__(self, name):
        for gesture in self.gestures:
            if gesture.name == name:
                return gesture
        raise KeyError(f'unknown gesture {name!r}; expected one of {", ".join(self.names)}')

    def lock_averages(self, side):
        """
        Return the paper's lock angles (rad) for one arm.

        They are the per-joint mean over the gestures in which that arm takes part (each
        gesture's keyframes averaged first).
        """
        if side not in ARMS:
            raise ValueError(f'arm: expected one of {ARMS}, got {side!r}')
        per_gesture = [np.mean([kf.arm(side) for kf in g.keyframes], axis=0)
                       for g in self.gestures if side in g.arms]
        if not per_gesture:
            # No gesture uses this arm: its rest pose is the only reference there is.
            per_gesture = [np.mean([kf.arm(side) for g in self.gestures for kf in g.keyframes],
                                   axis=0)]
        return np.mean(per_gesture, axis=0)


def _arm_angles(value, side, robot, scale, file, key, right_angles):
    """Parse one arm of a keyframe: a list of 7 angles, a joint->angle map or 'mirror'."""
    if value == 'mirror':
        if side != 'left' or right_angles is None:
            raise ConfigError(file, key, "'mirror' is only valid for the left arm")
        return right_angles.copy()
    names = robot.arms[side].joint_names
    if isinstance(value, dict):
        unknown = [j for j in value if j not in names]
        if unknown:
            raise ConfigError(file, f'{key}.{unknown[0]}',
                              f'unknown joint {unknown[0]!r}; the {side} arm has '
                              f'{", ".join(names)}')
        missing = [j for j in names if j not in value]
        if missing:
            raise ConfigError(file, f'{key}.{missing[0]}', 'missing key')
        angles = [chk.as_number(value[j], file, f'{key}.{j}') for j in names]
    else:
        angles = chk.as_row(value, N_JOINTS, file, key)
    q = np.array(angles) * scale
    arm = robot.arms[side]
    for i, angle in enumerate(q):
        if not arm.lower[i] - 1e-9 <= angle <= arm.upper[i] + 1e-9:
            raise ConfigError(file, f'{key}[{i}]',
                              f'angle {angles[i]} of {names[i]} is outside its limits '
                              f'[{math.degrees(arm.lower[i]):g}, '
                              f'{math.degrees(arm.upper[i]):g}] deg')
    return q


def load_library(robot, path=None):
    """Load and validate a gesture file against ``robot``; the packaged library if None."""
    path = Path(path) if path is not None else config_path(DEFAULT_GESTURE_FILE)
    data = chk.load_yaml(path)
    scale = chk.as_angle_scale(chk.require(data, 'units', path), path, 'units')
    entries = chk.require(data, 'gestures', path)
    if not isinstance(entries, list) or not entries:
        raise ConfigError(path, 'gestures', f'the library is empty; expected a list of '
                          f'gestures, got {entries!r}')
    gestures = []
    seen = set()
    for gi, entry in enumerate(entries):
        where = f'gestures[{gi}]'
        name = chk.require(entry, 'name', path, where)
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise ConfigError(path, f'{where}.name',
                              f'expected a lower_snake_case name, got {name!r}')
        if name in seen:
            raise ConfigError(path, f'{where}.name', f'duplicate gesture name {name!r}')
        seen.add(name)
        arms = chk.require(entry, 'arms', path, where)
        if (not isinstance(arms, list) or not arms or any(a not in ARMS for a in arms)
                or len(set(arms)) != len(arms)):
            raise ConfigError(path, f'{where}.arms',
                              f'expected a list of distinct arms from {list(ARMS)}, '
                              f'got {arms!r}')
        two_handed = chk.require(entry, 'two_handed', path, where)
        if not isinstance(two_handed, bool):
            raise ConfigError(path, f'{where}.two_handed', f'expected true or false, '
                              f'got {two_handed!r}')
        if two_handed and len(arms) != 2:
            raise ConfigError(path, f'{where}.two_handed',
                              f'a two-handed gesture must use both arms, got arms {arms!r}')
        frames = chk.require(entry, 'keyframes', path, where)
        if not isinstance(frames, list) or not frames:
            raise ConfigError(path, f'{where}.keyframes',
                              f'expected a non-empty list of keyframes, got {frames!r}')
        keyframes = []
        last_time = -math.inf
        for ki, frame in enumerate(frames):
            fwhere = f'{where}.keyframes[{ki}]'
            t = chk.as_number(chk.require(frame, 'time_from_start', path, fwhere), path,
                              f'{fwhere}.time_from_start')
            if t <= last_time or t < 0:
                raise ConfigError(path, f'{fwhere}.time_from_start',
                                  f'times must be non-negative and strictly increasing; '
                                  f'got {t:g} after {last_time:g}')
            last_time = t
            right = _arm_angles(chk.require(frame, 'right', path, fwhere), 'right', robot,
                                scale, path, f'{fwhere}.right', None)
            left = _arm_angles(chk.require(frame, 'left', path, fwhere), 'left', robot,
                               scale, path, f'{fwhere}.left', right)
            keyframes.append(Keyframe(t, right, left))
        gestures.append(Gesture(name, tuple(arms), two_handed, tuple(keyframes),
                                str(entry.get('description', ''))))
    return GestureLibrary(tuple(gestures), str(path))
