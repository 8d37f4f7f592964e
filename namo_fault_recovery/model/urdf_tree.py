"""
A robot's kinematic tree read from its URDF (ROS-free, robot-agnostic).

Why a tree of our own: the URDF is parsed by yourdfpy (never by hand), but yourdfpy
accepts a joint whose child link does not exist, a link with two parents, or no root at
all.  :func:`load_urdf_tree` checks those once, so that everything built on the tree (the
compiled chains, the recovery profile, the profile template) can rely on one root and one
path from any link up to it.  Every error is one line naming the file, the joint or
link, and what was expected.
"""

from dataclasses import dataclass
import io
import logging
import math
import os
from pathlib import Path
import xml.etree.ElementTree as ET

import numpy as np

from ..errors import ConfigError

MOVABLE = ('revolute', 'continuous')     # the joint types a chain can move
KNOWN_TYPES = MOVABLE + ('fixed', 'prismatic', 'floating', 'planar')


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint: its type, links, origin (4x4, metres), unit axis and limits."""

    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float
    velocity: float | None     # rad/s; None where the URDF gives none (or 0)
    mimic: str | None          # the joint this one mimics, if any

    @property
    def movable(self) -> bool:
        """Return True for a revolute or continuous joint that mimics no other joint."""
        return self.kind in MOVABLE and self.mimic is None


@dataclass(frozen=True)
class UrdfTree:
    """The links and joints of one URDF, with its single root link."""

    name: str
    source: str
    root: str
    links: tuple
    joints: dict               # joint name -> UrdfJoint
    parent_joint: dict         # child link -> UrdfJoint

    def children(self, link: str) -> list:
        """Return the joints whose parent is ``link``, in file order."""
        return [j for j in self.joints.values() if j.parent == link]

    def path_to_root(self, link: str) -> list:
        """Return the joints from the root down to ``link`` (root first)."""
        path = []
        while link in self.parent_joint:
            joint = self.parent_joint[link]
            path.append(joint)
            link = joint.parent
        return path[::-1]

    def path(self, base: str, tip: str, where: str = '') -> list:
        """
        Return the joints from ``base`` down to ``tip``, or raise ConfigError.

        ``where`` names what asked for the path (a profile key), for the message.
        """
        for link in (base, tip):
            self.require_link(link, where)
        joints = self.path_to_root(tip)
        names = [j.parent for j in joints] + [tip]
        if base not in names:
            raise ConfigError(self.source, None,
                              f'{where + ": " if where else ""}no path from base link '
                              f'{base!r} down to tip link {tip!r}; expected {base!r} to be '
                              f'an ancestor of {tip!r} (its ancestors: {", ".join(names)})')
        return joints[names.index(base):]

    def require_link(self, link: str, where: str = '') -> None:
        """Raise ConfigError naming ``link`` if the URDF has no such link."""
        if link not in self.links:
            raise ConfigError(self.source, None,
                              f'{where + ": " if where else ""}no link {link!r} in robot '
                              f'{self.name!r}; expected one of its {len(self.links)} links')


def _check_xml(text_or_path, source):
    """Refuse a document that is not well-formed XML with a <robot> root (yourdfpy recovers)."""
    try:
        root = (ET.fromstring(text_or_path) if isinstance(text_or_path, str)
                else ET.parse(text_or_path).getroot())
    except ET.ParseError as exc:
        raise ConfigError(source, None, f'not a URDF that parses ({exc}); expected a '
                          'well-formed <robot> document') from None
    if root.tag != 'robot':
        raise ConfigError(source, None, f'not a URDF: the root element is <{root.tag}>; '
                          'expected <robot>')


def load_urdf_document(text_or_path: str | Path, source: str):
    """
    Parse a URDF document (``str``) or file (a ``Path``) with yourdfpy, links and joints only.

    Returns yourdfpy's ``URDF`` (for code that edits a description and writes it again);
    raises ConfigError (one line naming ``source``) if it does not parse.
    """
    import yourdfpy
    _check_xml(text_or_path, source)
    # yourdfpy logs its own complaints before raising; our one-line error says it all.
    logging.getLogger('yourdfpy').setLevel(logging.CRITICAL)
    handle = (io.BytesIO(text_or_path.encode('utf-8')) if isinstance(text_or_path, str)
              else str(text_or_path))
    try:
        return yourdfpy.URDF.load(handle, build_scene_graph=False, load_meshes=False,
                                  build_collision_scene_graph=False,
                                  load_collision_meshes=False)
    except (OSError, ValueError, TypeError, KeyError, AttributeError, SyntaxError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(source, None, f'not a URDF that parses ({reason}); expected a '
                          '<robot> document of links and joints') from None


def _joint(raw, source):
    kind = raw.type
    if kind not in KNOWN_TYPES:
        raise ConfigError(source, None, f'joint {raw.name!r} has type {kind!r}; expected '
                          f'one of {", ".join(KNOWN_TYPES)}')
    origin = np.eye(4) if raw.origin is None else np.array(raw.origin, dtype=float)
    axis = np.array([1.0, 0.0, 0.0] if raw.axis is None else raw.axis, dtype=float)
    norm = float(np.linalg.norm(axis))
    if kind != 'fixed' and not (math.isfinite(norm) and norm > 1e-12):
        raise ConfigError(source, None, f'joint {raw.name!r} has axis {axis.tolist()}; '
                          'expected a non-zero direction')
    limit = raw.limit
    lower = getattr(limit, 'lower', None)
    upper = getattr(limit, 'upper', None)
    if kind == 'continuous' or lower is None or upper is None:
        lower, upper = -math.pi, math.pi    # one full turn: every angle has a reading
    velocity = getattr(limit, 'velocity', None)
    velocity = float(velocity) if velocity else None
    if kind == 'revolute' and lower > upper:
        raise ConfigError(source, None, f'joint {raw.name!r}: lower limit {lower} is above '
                          f'upper limit {upper}; expected lower <= upper')
    mimic = raw.mimic.joint if raw.mimic is not None else None
    return UrdfJoint(raw.name, kind, raw.parent, raw.child, origin,
                     axis / norm if norm > 1e-12 else axis, float(lower), float(upper),
                     velocity, mimic)


def _check_tree(joints, links, source):
    """Return (root, child -> joint) after checking that the links form one tree."""
    parent_joint = {}
    for joint in joints.values():
        for end in (joint.parent, joint.child):
            if end not in links:
                raise ConfigError(source, None, f'joint {joint.name!r} names link {end!r}, '
                                  'which the URDF does not define; expected a <link> of '
                                  'that name')
        if joint.child in parent_joint:
            raise ConfigError(source, None, f'link {joint.child!r} is the child of joints '
                              f'{parent_joint[joint.child].name!r} and {joint.name!r}; '
                              'expected one parent joint per link (a tree)')
        parent_joint[joint.child] = joint
    roots = [link for link in links if link not in parent_joint]
    if len(roots) != 1:
        raise ConfigError(source, None, f'links {", ".join(roots) or "(none)"} have no parent '
                          'joint; expected exactly one root link (a tree)')
    return roots[0], parent_joint


def load_urdf_tree(urdf: str | os.PathLike, source: str | None = None) -> UrdfTree:
    """
    Parse a URDF file (a path) or document (a ``str`` starting with ``<``) into a tree.

    ``source`` names the URDF in errors (default: the path, or ``<robot_description>``
    for a document).  Raises ConfigError (one line) if it does not parse or is no tree.
    """
    is_text = isinstance(urdf, str) and urdf.lstrip().startswith('<')
    if source is None:
        source = '<robot_description>' if is_text else str(urdf)
    if not is_text:
        path = Path(urdf)
        if not path.is_file():
            raise ConfigError(source, None, 'no such URDF file; expected a readable file')
        urdf = path
    model = load_urdf_document(urdf, source)
    links = tuple(link.name for link in model.robot.links)
    joints = {}
    for raw in model.robot.joints:
        if raw.name in joints:
            raise ConfigError(source, None, f'joint {raw.name!r} is defined twice; expected '
                              'unique joint names')
        joints[raw.name] = _joint(raw, source)
    if not links:
        raise ConfigError(source, None, 'the URDF has no links; expected a robot')
    root, parent_joint = _check_tree(joints, set(links), source)
    return UrdfTree(str(model.robot.name), source, root, links, joints, parent_joint)
