"""
The recovery profile: what a robot's URDF cannot say about its recovery (ROS-free).

A URDF gives the links, joints, limits and (usually) velocity limits.  The profile, a
short YAML file, adds per arm its base and tip links, the landmark links (elbow, wrist,
fingertip with an optional offset, palm frame), the joints the recovery may move and the
staged-expansion joints (a torso or waist), plus the joints shared by both arms and the
velocity limits the URDF lacks.  :func:`load_profile` checks it against the URDF and
compiles each arm's chain (:mod:`.chain`); every error is one line naming the file, the
key, the link or joint, and what was expected.  The format::

    name: talos
    urdf: {file: talos_data/robots/talos_reduced.urdf, distribution: example-robot-data}
    shared: [torso_1_joint, torso_2_joint]
    velocity_limits: {}            # rad/s, joint -> limit, where the URDF has none
    capsules: {upper_arm: 100}     # mm: radii that override the ones fitted to the URDF
    arms:
      right:
        base: base_link
        tip: gripper_right_base_link
        landmarks:
          elbow: arm_right_4_link
          wrist: arm_right_6_link
          fingertip: {link: gripper_right_base_link, offset: [0.0, 0.0, -0.1]}   # m
          palm: arm_right_7_link
        joints: [arm_right_1_joint, ..., arm_right_7_joint]
        expansion: [torso_1_joint, torso_2_joint]

``urdf`` is a path relative to the profile, or ``{file, distribution}`` for a URDF
shipped inside an installed Python distribution.  A URDF document given to
:func:`load_profile` (the ``robot_description`` text) replaces it; its mesh names are
then looked up from the folder of the URDF the profile names (else the profile's).
Chain joints that are neither ``joints`` nor ``expansion`` are held at 0.  Positions
come out in millimetres.
"""

from dataclasses import dataclass, field
import math
import os
from pathlib import Path

from . import yaml_checks as chk
from .chain import compile_chain, KinematicChain
from .robot import ARMS
from .urdf_tree import load_urdf_tree, UrdfTree
from ..errors import ConfigError
from ..resources import distribution_file

MM_PER_M = 1000.0
ARM_JOINTS = (5, 8)          # the model takes 5 to 8 recovery joints per arm
LANDMARKS = ('elbow', 'wrist', 'fingertip', 'palm')
_TOP_KEYS = ('name', 'urdf', 'arms', 'shared', 'velocity_limits', 'capsules')
CAPSULE_KEYS = ('upper_arm', 'forearm', 'hand', 'torso_radius')
_ARM_KEYS = ('base', 'tip', 'landmarks', 'joints', 'expansion')


@dataclass(frozen=True)
class ProfileArm:
    """One arm of a profile: its compiled chain and the roles of the chain's joints."""

    side: str
    chain: KinematicChain
    joints: tuple           # the joints recovery may move
    expansion: tuple        # the staged-expansion joints (torso, waist)
    held: tuple             # the other chain joints, held at 0
    landmark_links: dict    # role -> link
    marks: dict | None = None   # chain role -> link or (link, offset m), as compiled


@dataclass(frozen=True)
class RobotProfile:
    """A robot for the recovery: its URDF tree, its arms and its joints' limits."""

    name: str
    source: str
    tree: UrdfTree
    arms: dict              # side -> ProfileArm
    shared: tuple
    velocity_limits: dict   # joint -> rad/s (the URDF's, or the profile's where it has none)
    capsules: dict | None = None    # capsule radii (mm) that override the fitted ones
    # A URDF given as a document (robot_description), kept for the capsule fit, and the
    # folder its relative and package:// mesh names are looked up from.
    urdf_text: str | None = field(default=None, compare=False, repr=False)
    mesh_dir: str | None = None


def _check_keys(mapping, known, path, where):
    for key in mapping:
        if key not in known:
            raise ConfigError(path, f'{where}{key}',
                              f'unknown key; expected some of {", ".join(known)}')


def _urdf_of(data, path):
    """Return the path of the profile's URDF (relative to the profile, or in a package)."""
    spec = chk.require(data, 'urdf', path)
    if isinstance(spec, str):
        found = (Path(path).parent / spec).resolve()
        if not found.is_file():
            raise ConfigError(path, 'urdf', f'no URDF file {found}; expected a readable file '
                              '(a path relative to the profile)')
        return found
    if isinstance(spec, dict):
        _check_keys(spec, ('file', 'distribution'), path, 'urdf.')
        name = chk.require(spec, 'file', path, 'urdf')
        dist = chk.require(spec, 'distribution', path, 'urdf')
        try:
            return distribution_file(str(dist), str(name))
        except FileNotFoundError as exc:
            raise ConfigError(path, 'urdf', str(exc)) from None
    raise ConfigError(path, 'urdf', f'expected a file name or {{file, distribution}}, '
                      f'got {spec!r}')


def _names(value, path, key):
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise ConfigError(path, key, f'expected a list of joint names, got {value!r}')
    if len(set(value)) != len(value):
        raise ConfigError(path, key, f'a joint is listed twice in {value!r}')
    return tuple(value)


def _landmarks(cfg, path, where):
    """Return {chain role: link or (link, offset m)} of an arm's ``landmarks`` key."""
    marks = chk.require(cfg, 'landmarks', path, where)
    _check_keys(marks if isinstance(marks, dict) else {}, LANDMARKS, path,
                f'{where}.landmarks.')
    out = {}
    for role in LANDMARKS:
        spec = chk.require(marks, role, path, f'{where}.landmarks')
        key = f'{where}.landmarks.{role}'
        if isinstance(spec, dict):
            _check_keys(spec, ('link', 'offset'), path, key + '.')
            link = chk.require(spec, 'link', path, key)
            offset = tuple(chk.as_row(spec.get('offset', [0, 0, 0]), 3, path, key + '.offset'))
            spec = (link, offset)
        if not isinstance(spec, (str, tuple)):
            raise ConfigError(path, key, f'expected a link name or {{link, offset}}, '
                              f'got {spec!r}')
        out['tip' if role == 'fingertip' else role] = spec
    return out


def _compile_arm(tree, cfg, path, side):
    """Return the ProfileArm of ``arms.<side>``; errors name the profile and the key."""
    where = f'arms.{side}'
    _check_keys(cfg if isinstance(cfg, dict) else {}, _ARM_KEYS, path, where + '.')
    base = chk.require(cfg, 'base', path, where)
    tip = chk.require(cfg, 'tip', path, where)
    marks = _landmarks(cfg, path, where)
    chain = compile_chain(tree, str(base), str(tip), marks, MM_PER_M,
                          where=f'profile {path}, {where}')
    joints = _names(chk.require(cfg, 'joints', path, where), path, f'{where}.joints')
    expansion = _names(cfg.get('expansion', []), path, f'{where}.expansion')
    lo, hi = ARM_JOINTS
    if not lo <= len(joints) <= hi:
        raise ConfigError(path, f'{where}.joints', f'{len(joints)} joints; the model takes '
                          f'{lo} to {hi} joints per arm')
    for key, names in (('joints', joints), ('expansion', expansion)):
        for name in names:
            if name not in chain.joint_names:
                raise ConfigError(path, f'{where}.{key}',
                                  f'joint {name!r} is not a revolute or continuous joint of '
                                  f'the chain {base} -> {tip}; expected one of '
                                  f'{", ".join(chain.joint_names)}')
    both = set(joints) & set(expansion)
    if both:
        raise ConfigError(path, f'{where}.expansion', f'joint {sorted(both)[0]!r} is also in '
                          f'{where}.joints; expected each joint in one role')
    held = tuple(j for j in chain.joint_names if j not in joints and j not in expansion)
    links = {role: (s if isinstance(s, str) else s[0]) for role, s in marks.items()}
    return ProfileArm(side, chain, joints, expansion, held, links, marks)


def _check_shared(arms, shared, path):
    """Check that a joint on two arms' chains is declared shared, and a shared one is."""
    owners = {}
    for side, arm in arms.items():
        for name in arm.chain.joint_names:
            owners.setdefault(name, []).append(side)
    for name, sides in owners.items():
        if len(sides) > 1 and name not in shared:
            raise ConfigError(path, 'shared', f'joint {name!r} is in arms {" and ".join(sides)}'
                              ' without being declared shared; expected it under shared')
    for name in shared:
        if len(owners.get(name, ())) < 2:
            raise ConfigError(path, 'shared', f'joint {name!r} is declared shared but is on '
                              f'the chain of {" and ".join(owners.get(name, [])) or "no arm"}; '
                              'expected a joint of both arms')


def _velocity_limits(data, arms, tree, path, shared=()):
    """Return joint -> rad/s of every moving and shared joint: the URDF's, else the profile's."""
    given = data.get('velocity_limits') or {}
    if not isinstance(given, dict):
        raise ConfigError(path, 'velocity_limits', f'expected joint: rad/s, got {given!r}')
    for name, value in given.items():
        if name not in tree.joints:
            raise ConfigError(path, f'velocity_limits.{name}', f'no joint {name!r} in the '
                              f'URDF {tree.source}; expected one of its joints')
        if chk.as_number(value, path, f'velocity_limits.{name}') <= 0:
            raise ConfigError(path, f'velocity_limits.{name}', f'expected rad/s above 0, '
                              f'got {value!r}')
    limits = {}
    for names in [arm.joints + arm.expansion for arm in arms.values()] + [tuple(shared)]:
        for name in names:
            value = given.get(name, tree.joints[name].velocity)
            if value is None or not math.isfinite(value):
                raise ConfigError(path, f'velocity_limits.{name}', f'missing key: joint '
                                  f'{name!r} has no velocity limit in the URDF; expected one '
                                  'here (rad/s)')
            limits[name] = float(value)
    return limits


def load_profile(path: str | os.PathLike, urdf: str | os.PathLike | None = None) -> RobotProfile:
    """
    Load a recovery profile and compile its arms against its URDF.

    ``urdf`` overrides the profile's ``urdf`` key: a path, or the URDF document itself
    (a ``robot_description`` string).  Raises ConfigError (one line) on any problem.
    """
    path = Path(path)
    data = chk.load_yaml(path)
    _check_keys(data, _TOP_KEYS, path, '')
    text = urdf if isinstance(urdf, str) and urdf.lstrip().startswith('<') else None
    tree = load_urdf_tree(urdf if urdf is not None else _urdf_of(data, path))
    arms_cfg = chk.require(data, 'arms', path)
    if not isinstance(arms_cfg, dict) or not arms_cfg:
        raise ConfigError(path, 'arms', f'expected one or two of {", ".join(ARMS)}, got '
                          f'{arms_cfg!r}')
    _check_keys(arms_cfg, ARMS, path, 'arms.')
    arms = {side: _compile_arm(tree, arms_cfg[side], path, side)
            for side in ARMS if side in arms_cfg}
    shared = _names(data.get('shared', []), path, 'shared')
    _check_shared(arms, shared, path)
    return RobotProfile(str(data.get('name', tree.name)), str(path), tree, arms, shared,
                        _velocity_limits(data, arms, tree, path, shared),
                        _capsules(data, path),
                        text, _mesh_dir(data, path) if text is not None else None)


def _mesh_dir(data, path):
    """Return where a URDF document's meshes are looked up: the named URDF's folder."""
    if 'urdf' in data:
        try:
            return str(Path(_urdf_of(data, path)).parent)
        except ConfigError:
            pass            # the document replaces a URDF that is not here: the profile's
    return str(Path(path).resolve().parent)


def _capsules(data, path):
    """Return the optional ``capsules`` key: radii (mm) overriding the fitted capsules."""
    given = data.get('capsules') or {}
    if not isinstance(given, dict):
        raise ConfigError(path, 'capsules', f'expected radius names: mm, got {given!r}')
    _check_keys(given, CAPSULE_KEYS, path, 'capsules.')
    out = {}
    for key, value in given.items():
        out[key] = chk.as_number(value, path, f'capsules.{key}')
        if out[key] < 0:
            raise ConfigError(path, f'capsules.{key}', f'expected a radius >= 0 mm, got {value!r}')
    return out
