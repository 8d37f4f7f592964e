"""
The reference gesture library: keyframes per gesture, loaded from a validated YAML file.

Angles are in degrees in the file (with an explicit units key) and in radians in memory.
A gesture is a motion: a few keyframes written in the file, or a dense recorded
trajectory read from a CSV file (:mod:`.trajectory_csv`).
"""

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
import logging
import math
import os
from pathlib import Path
import re

import numpy as np

from . import yaml_checks as chk
from .kinematics import split_arms
from .robot import ARMS, RobotModel
from .self_contact import reference_contact
from .trajectory_csv import load_trajectory_csv
from .weights import ScoreWeights
from ..errors import ConfigError
from ..resources import config_path, DEFAULT_GESTURE_FILE

_NAME_RE = re.compile(r'^[a-z][a-z0-9_]*$')


@dataclass(frozen=True)
class Keyframe:
    """Joint angles (rad) of both arms at ``time_from_start`` seconds."""

    time_from_start: float
    right: np.ndarray
    left: np.ndarray

    def arm(self, side: str) -> np.ndarray:
        """Return the angles of one arm."""
        return self.right if side == 'right' else self.left

    def positions(self) -> np.ndarray:
        """All J angles (14 on Namo), right arm first (the order of RobotModel.joint_names)."""
        return np.concatenate((self.right, self.left))


@dataclass(frozen=True)
class Gesture:
    """
    One gesture: its keyframes and the arms that take part in it.

    ``weights`` (ScoreWeights or None) replaces the global score weights for this
    gesture, e.g. a drawing motion that is mostly about its fingertip path.  ``joints``
    are the joints the motion was designed with: after a structure change only those
    (minus locked ones) are searched first; empty means all joints of its arms.
    ``expand`` lists further joints in priority order, one tuple per stage of the staged
    DOF expansion (the second source paper), used when the designed joints cannot
    reach the motion well enough.
    """

    name: str
    arms: tuple
    two_handed: bool
    keyframes: tuple
    description: str = ''
    weights: ScoreWeights | None = None
    joints: tuple = ()
    expand: tuple = ()

    @property
    def times(self) -> np.ndarray:
        """Return the keyframes' times from start (s) as an array."""
        return np.array([kf.time_from_start for kf in self.keyframes])

    def joint_matrix(self) -> np.ndarray:
        """Return every keyframe's J joint angles (rad) stacked, right arm first: (T, J)."""
        return np.array([kf.positions() for kf in self.keyframes])

    def with_keyframes(self, keyframes: Iterable[Keyframe]) -> 'Gesture':
        """Return a copy of this gesture with other keyframes."""
        return Gesture(self.name, self.arms, self.two_handed, tuple(keyframes),
                       self.description, self.weights, self.joints, self.expand)


@dataclass(frozen=True)
class GestureLibrary:
    """
    An ordered collection of gestures, addressable by name.

    ``warnings`` are the one-line warnings of loading it (reference grazes, see
    :func:`load_library`).
    """

    gestures: tuple
    source: str = '<memory>'
    warnings: tuple = ()

    @property
    def names(self) -> tuple:
        """Gesture names in library order."""
        return tuple(g.name for g in self.gestures)

    def __len__(self) -> int:
        return len(self.gestures)

    def __iter__(self) -> Iterator[Gesture]:
        return iter(self.gestures)

    def __getitem__(self, name: str) -> Gesture:
        for gesture in self.gestures:
            if gesture.name == name:
                return gesture
        raise KeyError(f'unknown gesture {name!r}; expected one of {", ".join(self.names)}')

    def lock_averages(self, side: str) -> np.ndarray:
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
    """Parse one arm of a keyframe: a list of its n angles, a joint->angle map or 'mirror'."""
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
        angles = chk.as_row(value, len(names), file, key)
    q = np.array(angles) * scale
    arm = robot.arms[side]
    for i, angle in enumerate(q):
        if not arm.lower[i] - 1e-9 <= angle <= arm.upper[i] + 1e-9:
            raise ConfigError(file, f'{key}[{i}]',
                              f'angle {angles[i]} of {names[i]} is outside its limits '
                              f'[{math.degrees(arm.lower[i]):g}, '
                              f'{math.degrees(arm.upper[i]):g}] deg')
    return q


def load_library(robot: RobotModel,
                 path: str | os.PathLike | None = None,
                 on_warning: Callable[[str], None] | None = None) -> GestureLibrary:
    """
    Load and validate a gesture file against ``robot``; the packaged library if None.

    A reference keyframe that the robot's own body blocks (an undesigned capsule
    contact, :mod:`.self_contact`) is a library error: deeper than
    ``self_contact.REFUSE_MM`` it raises ConfigError naming the file, gesture, keyframe,
    pair and depth; a graze above the 1 mm tolerance is a one-line warning, passed to
    ``on_warning`` (default: this module's ``logging`` logger, which prints it on
    stderr) and kept in the library's ``warnings``.
    """
    path = Path(path) if path is not None else config_path(DEFAULT_GESTURE_FILE)
    data = chk.load_yaml(path)
    _check_robot(data, robot, path)
    scale = chk.as_angle_scale(chk.require(data, 'units', path), path, 'units')
    entries = chk.require(data, 'gestures', path)
    if not isinstance(entries, list) or not entries:
        raise ConfigError(path, 'gestures', f'the library is empty; expected a list of '
                          f'gestures, got {entries!r}')
    gestures = []
    found = []
    seen = set()
    for gi, entry in enumerate(entries):
        gesture = _parse_gesture(entry, robot, scale, path, f'gestures[{gi}]', seen)
        gestures.append(gesture)
        contact = reference_contact(robot, gesture)
        if contact is None:
            continue
        key = (f'gestures[{gi}].keyframes[{contact.keyframe}]' if 'keyframes' in entry
               else f'gestures[{gi}].trajectory')
        if contact.refused:
            raise ConfigError(path, key, contact.problem())
        found.append(f'warning: {ConfigError(path, key, contact.problem())}')
    report = on_warning or logging.getLogger(__name__).warning
    for line in found:
        report(line)
    return GestureLibrary(tuple(gestures), str(path), tuple(found))


def _check_robot(data, robot, path):
    """
    Refuse a library made for another robot: its optional ``robot`` key names the robot.

    Angles are listed per arm, not per joint name, so a library of another robot with
    as many joints per arm would otherwise load (within wide limits) and be wrong.
    """
    if 'robot' not in data:
        return
    made_for = data['robot']
    if made_for != robot.name:
        raise ConfigError(path, 'robot', f'a library for robot {made_for!r}, whose joints are '
                          f'not those of robot {robot.name!r} ({robot.source}); expected a '
                          f'library made for {robot.name!r}')


def _parse_gesture(entry, robot, scale, path, where, seen):
    """Parse one entry of ``gestures``; ``seen`` holds the names of those before it."""
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
    if ('keyframes' in entry) == ('trajectory' in entry):
        raise ConfigError(path, f'{where}.keyframes',
                          "expected exactly one of 'keyframes' (a list) and "
                          "'trajectory' (a CSV file)")
    options = _gesture_options(entry, robot, arms, path, where)
    if 'trajectory' in entry:
        keyframes = _csv_keyframes(entry['trajectory'], robot, scale, path,
                                   f'{where}.trajectory')
    else:
        keyframes = _yaml_keyframes(entry['keyframes'], robot, scale, path, where)
    return Gesture(name, tuple(arms), two_handed, keyframes,
                   str(entry.get('description', '')), *options)


def _yaml_keyframes(frames, robot, scale, path, where):
    """Parse a gesture's ``keyframes`` list: increasing times, both arms' angles."""
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
    return tuple(keyframes)


def _csv_keyframes(value, robot, scale, file, key):
    """Load ``trajectory: {file: NAME.csv, units: deg}`` (relative to the YAML file)."""
    csv_name = chk.require(value, 'file', file, key)
    if not isinstance(csv_name, str) or not csv_name:
        raise ConfigError(file, f'{key}.file', f'expected a CSV file name, got {csv_name!r}')
    if 'units' in value:
        scale = chk.as_angle_scale(value['units'], file, f'{key}.units')
    unknown = set(value) - {'file', 'units'}
    if unknown:
        raise ConfigError(file, f'{key}.{sorted(unknown)[0]}',
                          'unknown key; expected file and units')
    csv_path = Path(file).parent / csv_name
    times, angles = load_trajectory_csv(csv_path, robot, scale)
    return tuple(Keyframe(float(t), *(arm.copy() for arm in split_arms(robot, q)))
                 for t, q in zip(times, angles))


def _gesture_options(entry, robot, arms, file, where):
    """Parse a gesture's optional weights, designed joints and expansion stages."""
    weights = None
    if 'weights' in entry:
        value = entry['weights']
        if not isinstance(value, dict):
            raise ConfigError(file, f'{where}.weights', f'expected a mapping of component '
                              f'weights, got {value!r}')
        try:
            weights = ScoreWeights.from_mapping(value)
        except (TypeError, ValueError) as exc:
            raise ConfigError(file, f'{where}.weights', str(exc)) from None
    known = set(robot.joint_names)
    used = set()

    def joint_list(value, key):
        if not isinstance(value, list) or not value:
            raise ConfigError(file, key, f'expected a non-empty list of joint names, '
                              f'got {value!r}')
        for i, joint in enumerate(value):
            if joint not in known:
                raise ConfigError(file, f'{key}[{i}]', f'unknown joint {joint!r}; expected '
                                  f'one of {", ".join(robot.joint_names)}')
            if joint in used:
                raise ConfigError(file, f'{key}[{i}]', f'joint {joint!r} is listed twice')
            used.add(joint)
        return tuple(value)

    joints = ()
    if 'joints' in entry:
        joints = joint_list(entry['joints'], f'{where}.joints')
        outside = [j for j in joints if robot.locate_joint(j)[0] not in arms]
        if outside:
            raise ConfigError(file, f'{where}.joints', f'joint {outside[0]!r} is not on '
                              f'an arm of this gesture ({", ".join(arms)})')
    expand = ()
    if 'expand' in entry:
        stages = entry['expand']
        if not isinstance(stages, list) or not stages:
            raise ConfigError(file, f'{where}.expand', f'expected a list of stages (lists '
                              f'of joint names), got {stages!r}')
        if not joints:
            raise ConfigError(file, f'{where}.expand', "needs 'joints' (the designed "
                              'joints that the stages expand)')
        expand = tuple(joint_list(stage, f'{where}.expand[{i}]')
                       for i, stage in enumerate(stages))
    return weights, joints, expand
