"""
Structure changes the planner does not know: edits of the simulator's copy of a URDF.

Why edits of joint origins.  Every change the second source paper adapts to, and every
one a fall leaves, is a different fixed transform somewhere in an arm's chain, while the
joints, their readings and the planner's model stay as they were:

- ``tool``: a tool in the hand (the paper's pen).  The tip's joint origin is lengthened
  by ``amount`` mm along its own offset, as ``RobotModel.with_tool`` lengthens the hand
  for a planner that is told; here nobody tells it.
- ``bend``: a link bent by ``amount`` degrees.  The origin of the joint at the link's far
  end turns about an axis through the link's base, normal to the link (by default also
  normal to that joint's axis, so the bend is not a mere joint offset).
- ``encoder_offset``: a joint whose true angle is its reading plus ``amount`` degrees (an
  encoder that slipped).  The joint's origin turns about the joint's own axis.
- ``link_length``: a link ``amount`` mm longer (or shorter, if negative) than designed.
  The origin of the joint at the link's far end moves along the link.

A change names the joint whose origin it edits, so it applies to any robot's URDF.  The
URDF is read and written with yourdfpy (never by hand).  Only the simulator uses this
module: the recovery side must never learn what changed.
"""

from dataclasses import dataclass
import math
import os
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..model.rotations import rot_axis
from ..model.urdf_tree import load_urdf_document

KINDS = ('tool', 'bend', 'encoder_offset', 'link_length')
UNITS = {'tool': 'mm', 'bend': 'deg', 'encoder_offset': 'deg', 'link_length': 'mm'}
_MM = 1e-3
_SHORT_M = 1e-6            # a link this short (m) has no direction to bend or lengthen


@dataclass(frozen=True)
class StructureChange:
    """One hidden change: its kind, the joint whose origin it edits, and how much."""

    kind: str
    joint: str
    amount: float           # mm for tool and link_length, degrees for bend and encoder_offset
    axis: tuple | None = None   # bend axis in the joint's parent frame (None: the default)

    def describe(self) -> str:
        """Return a short human description, e.g. ``tool 50 mm at right_arm_fingertip_joint``."""
        return f'{self.kind} {self.amount:g} {UNITS[self.kind]} at {self.joint}'


def parse_change(spec: str, source: str = '<parameter>', key: str = 'change') -> StructureChange:
    """
    Read a change written ``KIND:JOINT:AMOUNT`` (e.g. ``bend:right_arm_joint5:10``).

    The form a string-array ROS parameter can carry.  Raises ConfigError (one line naming
    ``source`` and ``key``) on a bad kind, a missing joint or an amount that is no number.
    """
    parts = str(spec).split(':')
    shown = str(spec)[:80]
    if len(parts) != 3 or not parts[1]:
        raise ConfigError(source, key, f'{shown!r}: expected KIND:JOINT:AMOUNT, KIND one of '
                          f'{", ".join(KINDS)}')
    kind, joint, amount = parts
    if kind not in KINDS:
        raise ConfigError(source, key, f'{shown!r}: kind {kind!r}; expected one of '
                          f'{", ".join(KINDS)}')
    try:
        value = float(amount)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or (kind == 'tool' and value < 0):
        bound = ' >= 0' if kind == 'tool' else ''
        raise ConfigError(source, key, f'{shown!r}: amount {amount!r}; expected a finite '
                          f'number{bound} of {UNITS[kind]}')
    return StructureChange(kind, joint, value)


def _unit(vec):
    return np.asarray(vec, dtype=float) / float(np.linalg.norm(vec))


def _bend_axis(origin, joint_axis, given):
    """Return the unit bend axis (parent frame): given, or normal to the link and the joint."""
    if given is not None:
        return _unit(given)
    link = origin[:3, 3]
    axis = np.cross(link, origin[:3, :3] @ joint_axis)
    if np.linalg.norm(axis) < 1e-9 * np.linalg.norm(link):     # link along the joint axis
        helper = np.eye(3)[int(np.argmin(np.abs(link)))]
        axis = np.cross(link, helper)
    return _unit(axis)


def edited_origin(origin: np.ndarray, joint_axis: np.ndarray, change: StructureChange,
                  where: str) -> np.ndarray:
    """
    Return the 4x4 joint origin (metres) after ``change``; ``where`` names it in errors.

    The origin maps the joint's frame into its parent link's frame, as in the URDF.
    """
    out = np.array(origin, dtype=float)
    link = out[:3, 3]
    length = float(np.linalg.norm(link))
    if change.kind == 'encoder_offset':
        out[:3, :3] = out[:3, :3] @ rot_axis(_unit(joint_axis), math.radians(change.amount))
        return out
    if length < _SHORT_M:
        raise ConfigError(where, change.joint, f'{change.kind} needs a link: the joint origin '
                          'has no offset from its parent; expected the joint at the far end '
                          'of a link of some length')
    if change.kind == 'bend':
        turn = rot_axis(_bend_axis(out, joint_axis, change.axis), math.radians(change.amount))
        out[:3, :3] = turn @ out[:3, :3]
        out[:3, 3] = turn @ link
        return out
    new_length = length + change.amount * _MM          # tool, link_length
    if new_length < _SHORT_M:
        raise ConfigError(where, change.joint, f'{change.kind} {change.amount:g} mm leaves '
                          f'a link of {new_length / _MM:.1f} mm; expected a positive length '
                          f'(the link is {length / _MM:.1f} mm)')
    out[:3, 3] = link * (new_length / length)
    return out


def apply_changes(urdf: str | os.PathLike, changes, source: str | None = None) -> str:
    """
    Return the URDF document (``str``) of ``urdf`` (a document or a file) after ``changes``.

    Changes apply in order; several may edit one joint.  Raises ConfigError (one line) if
    a change names a joint the URDF lacks, or asks an encoder offset of a fixed joint.
    """
    is_text = isinstance(urdf, str) and urdf.lstrip().startswith('<')
    source = source or ('<robot_description>' if is_text else str(urdf))
    model = load_urdf_document(urdf if is_text else Path(urdf), source)
    joints = {joint.name: joint for joint in model.robot.joints}
    for change in changes:
        joint = joints.get(change.joint)
        if joint is None:
            raise ConfigError(source, change.joint, f'{change.describe()}: no such joint; '
                              f"expected one of the URDF's {len(joints)} joints")
        if change.kind == 'encoder_offset' and joint.type not in ('revolute', 'continuous'):
            raise ConfigError(source, change.joint, f'{change.describe()}: the joint is '
                              f'{joint.type}; expected a revolute or continuous joint')
        origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)
        axis = np.array([1.0, 0.0, 0.0] if joint.axis is None else joint.axis, dtype=float)
        joint.origin = edited_origin(origin, axis, change, source)
    text = model.write_xml_string()
    return text.decode('utf-8') if isinstance(text, bytes) else str(text)


def hidden_changes(specs, tools: dict, fingertip_joints: dict,
                   source: str = '<parameter>') -> list:
    """
    Return the changes of the simulator's parameters: ``specs`` then one tool per hand.

    ``specs`` are ``KIND:JOINT:AMOUNT`` strings (empty ones skipped, as a ROS string
    array cannot be empty); ``tools`` maps a side to a tool length in mm (0: none),
    applied at that side's fingertip joint (``fingertip_joints``).
    """
    changes = [parse_change(s, source, 'structure_changes') for s in specs if s]
    for side, length in tools.items():
        key = f'hidden_tool_{side}_mm'
        if not (math.isfinite(length) and length >= 0):
            raise ConfigError(source, key, f'{length!r}; expected a tool length >= 0 mm')
        if length > 0:
            changes.append(StructureChange('tool', fingertip_joints[side], float(length)))
    return changes
