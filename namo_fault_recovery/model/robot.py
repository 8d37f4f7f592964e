"""The arm model: the DH table, joint names and limits, loaded from a validated YAML file."""

from dataclasses import dataclass, field, replace
import math
import os
from pathlib import Path

import numpy as np

from . import yaml_checks as chk
from .capsules import CapsuleModel
from ..errors import ConfigError
from ..resources import config_path, DEFAULT_ROBOT_FILE

ARMS = ('right', 'left')
N_JOINTS = 7
_LENGTH_SCALES = {'mm': 1.0, 'm': 1000.0}
# Joint speed limits (deg/s, joints 1..7 of either arm) when the robot file has no
# ``velocity_limits``: servo-class shoulders are the slowest, the wrist the fastest.
DEFAULT_VELOCITY_LIMITS_DEG = (90.0, 90.0, 120.0, 120.0, 150.0, 150.0, 150.0)


@dataclass(frozen=True)
class ArmModel:
    """One 7-DOF arm: its joint names, limits (rad) and whether it is mirrored."""

    side: str
    joint_names: tuple
    lower: np.ndarray
    upper: np.ndarray
    mirrored: bool

    def clip(self, q: np.ndarray) -> np.ndarray:
        """Clip joint angles (rad) into this arm's limits."""
        return np.clip(q, self.lower, self.upper)


class RobotJoints:
    """
    What the engine asks of any robot's joints and tools, whatever its kinematics.

    Shared by Namo's DH :class:`RobotModel` and a robot built from a recovery profile
    (:class:`~namo_fault_recovery.model.profile_robot.ProfileRobot`); a subclass is a
    frozen dataclass with ``arms`` ({side: ArmModel}), ``tools``, ``corrections`` and
    ``learned`` fields.  A robot
    with a ``chains`` field has its kinematics run by its compiled chains; without one
    (the DH model) :mod:`.kinematics` runs its DH table.  ``shared`` is the joints both
    arms hang from (:class:`~.shared_joints.SharedJoints`, a torso), None on Namo.
    """

    shared = None

    def tool_length(self, side: str) -> float:
        """Return the length (mm) of the tool held by one arm's hand; 0 without one."""
        for arm, length in self.tools:
            if arm == side:
                return length
        return 0.0

    def with_tool(self, length_mm: float, arm: str = 'right') -> 'RobotModel':
        """
        Return this robot with a tool of ``length_mm`` in one hand (0 removes it).

        A tool is a structure change (the second source paper's pen): it lengthens the
        hand, so the fingertip landmark becomes the tool's tip.  The arm's joints, limits
        and every other landmark are unchanged.
        """
        if arm not in ARMS:
            raise ValueError(f'tool arm: expected one of {ARMS}, got {arm!r}')
        if (isinstance(length_mm, bool) or not isinstance(length_mm, (int, float))
                or not math.isfinite(length_mm) or length_mm < 0):
            raise ValueError(f'tool length: expected a finite number of mm >= 0, '
                             f'got {length_mm!r}')
        tools = tuple((a, n) for a, n in self.tools if a != arm)
        if length_mm > 0:
            tools = tuple(sorted(tools + ((arm, float(length_mm)),)))
        return replace(self, tools=tools)

    def corrected_arm(self, side: str):
        """Return the corrected chain of one arm (:mod:`.structure`), or None."""
        for arm, chain in self.corrections:
            if arm == side:
                return chain
        return None

    def with_corrections(self, corrections) -> 'RobotModel':
        """
        Return this robot whose kinematics run ``corrections`` ({side: ArmChain}).

        A correction learned on the robot (:func:`.structure.corrected_arm`) is a
        structure change like a tool: the corrected arm's landmarks come from its
        corrected chain; joints, limits and the other arm are unchanged.  An empty
        mapping gives the nominal robot back.
        """
        items = dict(corrections).items()
        for side, _ in items:
            if side not in ARMS:
                raise ValueError(f'corrected arm: expected one of {ARMS}, got {side!r}')
        return replace(self, corrections=tuple(sorted(items, key=lambda kv: kv[0])))

    def with_learned(self, learned) -> 'RobotModel':
        """
        Return this robot carrying corrections learned on the robot, not yet applied.

        ``learned`` holds :class:`~.structure.LearnedArm` entries (a correction and its
        compiled chain).  This robot's own kinematics stay nominal (it is the reference
        a design is scored against); :meth:`changed_model` applies them, as it applies
        a tool.
        """
        return replace(self, learned=tuple(sorted(learned, key=lambda a: a.correction.side)))

    def changed_model(self, tool_mm: float = 0.0, tool_arm: str = 'right') -> 'RobotModel':
        """Return the model of the changed structure: the tool and the learned corrections."""
        return self.with_tool(tool_mm, tool_arm).with_corrections(
            {a.correction.side: a.chain for a in self.learned})

    def changed(self, side: str) -> bool:
        """Return True if one arm's structure differs from the design: a tool or a correction."""
        return self.tool_length(side) > 0 or self.corrected_arm(side) is not None

    def arm_velocity_limits(self, side: str) -> tuple:
        """Speed limit (rad/s) of each joint of one arm, base first (Namo: the same two)."""
        return tuple(self.velocity_limits)

    @property
    def joint_velocity_limits(self) -> tuple:
        """Speed limit (rad/s) of every joint, in :attr:`joint_names` order (right first)."""
        return sum((self.arm_velocity_limits(side) for side in ARMS if side in self.arms), ())

    @property
    def joint_names(self) -> tuple:
        """All joint names, arm by arm in ARMS order (right first): 14 on Namo."""
        return sum((self.arms[side].joint_names for side in ARMS if side in self.arms), ())

    @property
    def played_joints(self) -> tuple:
        """
        Every joint a played gesture commands: :attr:`joint_names`, then the shared ones.

        The shared joints (a torso, :attr:`shared`) are commanded at 0 unless the
        recovery leans them (``GestureResult.shared``); Namo has none.
        """
        return self.joint_names + (self.shared.names if self.shared is not None else ())

    def locate_played(self, name: str) -> tuple[str, int]:
        """
        Return ``(arm, index)`` of a played joint, or ``('shared', index)`` for a torso's.

        A joint both arms hang from is in :attr:`shared`; every other is an arm's
        (:meth:`locate_joint`).  KeyError for an unknown name.
        """
        if self.shared is not None and name in self.shared.names:
            return 'shared', self.shared.names.index(name)
        return self.locate_joint(name)

    def joint_bounds(self, name: str) -> tuple[float, float, float]:
        """Return ``(lower, upper, velocity limit)`` (rad, rad/s) of a played joint."""
        side, i = self.locate_played(name)
        if side == 'shared':
            return (float(self.shared.lower[i]), float(self.shared.upper[i]),
                    float(self.shared.velocity[i]))
        return (float(self.arms[side].lower[i]), float(self.arms[side].upper[i]),
                float(self.arm_velocity_limits(side)[i]))

    def joint_within_limits(self, name: str, angle: float, tol: float = 1e-9) -> bool:
        """
        Return True if ``angle`` (rad) lies within a played joint's limits, ``tol`` beyond.

        An arm's joint or one both arms hang from (:meth:`locate_played`; without the
        speed :meth:`joint_bounds` adds: it runs per published angle); KeyError for an
        unknown name.  ``tol=0`` asks for the limits exactly (what is published).
        """
        side, i = self.locate_played(name)
        limits = self.shared if side == 'shared' else self.arms[side]
        return float(limits.lower[i]) - tol <= angle <= float(limits.upper[i]) + tol

    def locate_joint(self, name: str) -> tuple[str, int]:
        """Return ``(arm, index)`` for a joint name, or raise KeyError naming the choices."""
        for side in ARMS:
            if side not in self.arms:
                continue
            names = self.arms[side].joint_names
            if name in names:
                return side, names.index(name)
        raise KeyError(f'unknown joint {name!r}; expected one of {", ".join(self.joint_names)}')

    def within_limits(self, side: str, index: int, angle: float, tol: float = 1e-9) -> bool:
        """Return True if ``angle`` (rad) lies within the limits of that joint."""
        arm = self.arms[side]
        return arm.lower[index] - tol <= angle <= arm.upper[index] + tol


@dataclass(frozen=True)
class RobotModel(RobotJoints):
    """
    Namo's two arms, sharing one modified-DH chain (the left one mirrored).

    Lengths are in millimetres and angles in radians in memory, whatever the file used.
    """

    name: str
    theta_offset: np.ndarray
    d: np.ndarray
    a_prev: np.ndarray
    alpha_prev: np.ndarray
    end_effector: np.ndarray
    elbow_frame: int
    wrist_frame: int
    arms: dict
    source: str = '<memory>'
    capsules: CapsuleModel = CapsuleModel()
    tools: tuple = ()   # ((arm, length mm), ...): tools that lengthen the hands
    # ((arm, ArmChain), ...): arms whose kinematics run a learned correction (structure.py)
    corrections: tuple = field(default=(), compare=False, repr=False)
    # (LearnedArm, ...): corrections learned on the robot, applied by changed_model()
    learned: tuple = field(default=(), compare=False, repr=False)
    # Speed limit (rad/s) of joints 1..7, the same for both arms; used to time playback.
    velocity_limits: tuple = tuple(math.radians(v) for v in DEFAULT_VELOCITY_LIMITS_DEG)


def parse_velocity_limits(data, path, angle_scale):
    """
    Return the optional ``velocity_limits`` key (units.angle per second) in rad/s.

    Seven positive numbers, joints 1..7 of either arm; absent means
    DEFAULT_VELOCITY_LIMITS_DEG.  The gesture player stretches a motion's timing so no
    joint exceeds them.
    """
    if 'velocity_limits' not in data:
        return tuple(math.radians(v) for v in DEFAULT_VELOCITY_LIMITS_DEG)
    row = chk.as_row(data['velocity_limits'], N_JOINTS, path, 'velocity_limits')
    for i, v in enumerate(row):
        if v <= 0:
            raise ConfigError(path, f'velocity_limits[{i}]',
                              f'expected a speed above 0, got {v!r}')
    return tuple(v * angle_scale for v in row)


def load_robot(path: str | os.PathLike | None = None) -> RobotModel:
    """Load and validate a robot file; the packaged Namo model when ``path`` is None."""
    path = Path(path) if path is not None else config_path(DEFAULT_ROBOT_FILE)
    data = chk.load_yaml(path)
    if 'units' not in data and ('urdf' in data or 'arms' in data and 'dh' not in data):
        raise ConfigError(path, None, 'a recovery profile (a robot from its URDF), not a DH '
                          'robot file; expected it as robot_profile (--robot-profile on the '
                          'command line)')
    name = str(data.get('name', path.stem))
    length_scale, angle_scale = _parse_units(data, path)
    table, ee = _parse_dh(data, path)
    frames = _parse_landmarks(data, path)
    arms = _parse_arms(data, path, angle_scale)
    capsules = _parse_capsules(data, path, length_scale)
    return RobotModel(
        name=name,
        theta_offset=table[:, 0] * angle_scale,
        d=table[:, 1] * length_scale,
        a_prev=table[:, 2] * length_scale,
        alpha_prev=table[:, 3] * angle_scale,
        end_effector=np.array([ee[0] * angle_scale, ee[1] * length_scale,
                               ee[2] * length_scale, ee[3] * angle_scale]),
        elbow_frame=frames['elbow'],
        wrist_frame=frames['wrist'],
        arms=arms,
        source=str(path),
        capsules=capsules,
        velocity_limits=parse_velocity_limits(data, path, angle_scale),
    )


def _parse_units(data, path):
    """Return the ``units`` key as (mm per length unit, rad per angle unit)."""
    units = chk.require(data, 'units', path)
    length_unit = chk.require(units, 'length', path, 'units')
    if length_unit not in _LENGTH_SCALES:
        raise ConfigError(path, 'units.length',
                          f"unknown length unit {length_unit!r}; expected 'mm' or 'm'")
    angle_scale = chk.as_angle_scale(chk.require(units, 'angle', path, 'units'),
                                     path, 'units.angle')
    return _LENGTH_SCALES[length_unit], angle_scale


def _parse_dh(data, path):
    """Return the ``dh`` key as the (7, 4) joint table and the end-effector row (file units)."""
    dh = chk.require(data, 'dh', path)
    convention = chk.require(dh, 'convention', path, 'dh')
    if convention != 'modified':
        raise ConfigError(path, 'dh.convention',
                          f"unknown DH convention {convention!r}; expected 'modified'")
    columns = chk.require(dh, 'columns', path, 'dh')
    expected_columns = ['theta_offset', 'd', 'a_prev', 'alpha_prev']
    if columns != expected_columns:
        raise ConfigError(path, 'dh.columns', f'expected {expected_columns}, got {columns!r}')
    rows = chk.require(dh, 'joints', path, 'dh')
    if not isinstance(rows, list) or len(rows) != N_JOINTS:
        raise ConfigError(path, 'dh.joints',
                          f'expected a list of {N_JOINTS} rows, got {rows!r}')
    table = np.array([chk.as_row(r, 4, path, f'dh.joints[{i}]') for i, r in enumerate(rows)])
    ee = np.array(chk.as_row(chk.require(dh, 'end_effector', path, 'dh'), 4, path,
                             'dh.end_effector'))
    return table, ee


def _parse_landmarks(data, path):
    """Return the ``landmarks`` key: the DH frame numbers of the elbow and the wrist."""
    landmarks = chk.require(data, 'landmarks', path)
    frames = {}
    for key in ('elbow', 'wrist'):
        value = chk.require(landmarks, key, path, 'landmarks')
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= N_JOINTS:
            raise ConfigError(path, f'landmarks.{key}',
                              f'expected a frame number 1..{N_JOINTS}, got {value!r}')
        frames[key] = value
    return frames


def _parse_arms(data, path, angle_scale):
    """Return the ``arms`` key as {side: ArmModel}; joint names are unique over both arms."""
    arms_cfg = chk.require(data, 'arms', path)
    arms = {}
    seen = {}
    for side in ARMS:
        arm_cfg = chk.require(arms_cfg, side, path, 'arms')
        arms[side] = _parse_arm(side, arm_cfg, path, angle_scale, seen)
    if not arms['left'].mirrored:
        raise ConfigError(path, 'arms.left.mirror_of',
                          "missing key: the left arm must be declared 'mirror_of: right'")
    return arms


def _parse_joint_names(arm_cfg, path, where, seen):
    """Return one arm's 7 joint names; ``seen`` maps the names met so far to their key."""
    names = chk.require(arm_cfg, 'joints', path, where)
    if not isinstance(names, list) or len(names) != N_JOINTS:
        raise ConfigError(path, f'{where}.joints',
                          f'expected {N_JOINTS} joint names, got {names!r}')
    for i, joint in enumerate(names):
        if not isinstance(joint, str) or not joint:
            raise ConfigError(path, f'{where}.joints[{i}]',
                              f'expected a joint name, got {joint!r}')
        if joint in seen:
            raise ConfigError(path, f'{where}.joints[{i}]',
                              f'duplicate joint name {joint!r} (also {seen[joint]})')
        seen[joint] = f'{where}.joints[{i}]'
    return tuple(names)


def _parse_arm(side, arm_cfg, path, angle_scale, seen):
    """Return one arm of the ``arms`` key: joint names, limits (rad), mirroring."""
    where = f'arms.{side}'
    names = _parse_joint_names(arm_cfg, path, where, seen)
    limits = chk.require(arm_cfg, 'limits', path, where)
    if not isinstance(limits, list) or len(limits) != N_JOINTS:
        raise ConfigError(path, f'{where}.limits',
                          f'expected {N_JOINTS} [lower, upper] pairs, got {limits!r}')
    lims = np.array([chk.as_row(lim, 2, path, f'{where}.limits[{i}]')
                     for i, lim in enumerate(limits)]) * angle_scale
    for i, (lo, hi) in enumerate(lims):
        if lo > hi:
            raise ConfigError(path, f'{where}.limits[{i}]',
                              f'lower limit {limits[i][0]} is above upper limit '
                              f'{limits[i][1]}')
    mirror_of = arm_cfg.get('mirror_of')
    if mirror_of not in (None, 'right') or (side == 'right' and mirror_of is not None):
        raise ConfigError(path, f'{where}.mirror_of',
                          f'only the left arm may mirror the right arm; got {mirror_of!r}')
    return ArmModel(side, names, lims[:, 0].copy(), lims[:, 1].copy(),
                    mirrored=mirror_of == 'right')


def _parse_capsules(data, path, length_scale):
    """Return the optional ``capsules`` key as a CapsuleModel (mm); the defaults if absent."""
    if 'capsules' not in data:
        return CapsuleModel()
    cap = data['capsules']
    if not isinstance(cap, dict):
        raise ConfigError(path, 'capsules', f'expected a mapping, got {cap!r}')
    known = {'upper_arm', 'forearm', 'hand', 'torso_radius', 'torso_top', 'torso_bottom',
             'weight'}
    for key in cap:
        if key not in known:
            raise ConfigError(path, f'capsules.{key}',
                              f'unknown key; expected some of {", ".join(sorted(known))}')
    values = {}
    for key, value in cap.items():
        if key in ('torso_top', 'torso_bottom'):
            values[key] = tuple(v * length_scale for v in
                                chk.as_row(value, 3, path, f'capsules.{key}'))
        elif key == 'weight':
            values[key] = chk.as_number(value, path, f'capsules.{key}')
        else:
            values[key] = chk.as_number(value, path, f'capsules.{key}') * length_scale
    try:
        return CapsuleModel(**values)
    except ValueError as exc:
        raise ConfigError(path, 'capsules', str(exc)) from None
