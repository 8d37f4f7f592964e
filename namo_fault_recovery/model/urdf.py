"""
Namo's URDF, generated from the robot file's DH table (ROS-free).

Why generate it: robot_state_publisher, RViz and the MuJoCo simulator need a URDF, and
a hand-written one would drift from ``namo_robot.yaml``, the model the optimiser uses.

Frames.  The root link ``base_link`` is the DH base frame: the torso centre at shoulder
height, x forward (the face), y to the robot's left, z up.  It is the frame of the
node's ``/gesture_markers`` (``library_markers`` draws the kinematics' millimetres in
it, scaled to metres), so no static transform is needed between them.  Each arm has
links ``<side>_arm_link1..7``; link i is DH frame i, so the elbow landmark is the origin
of ``<side>_arm_link<elbow frame>`` (link3), the wrist the origin of
``<side>_arm_link<wrist frame>`` (link5), and a fixed ``<side>_arm_fingertip`` link is the
fingertip (end-effector frame).  Joints carry the robot file's names, limits and
velocity limits (so that a URDF-built model, ``config/namo_profile.yaml``, reads them).

Modified DH as URDF.  ``T(i-1, i) = RotX(alpha) TransX(a) RotZ(offset + q) TransZ(d)``
equals ``[RotX(alpha) TransX(a) RotZ(offset) TransZ(d)] RotZ(q)``, because the
translation along z commutes with a rotation about z: the bracket is the joint's fixed
``origin`` and the joint turns about its z axis.  The left arm is the mirror image of
the right one in the x-z plane (``M T M`` with ``M = diag(1, -1, 1)``), which is again
a rigid chain: alpha and the offset change sign and the joint turns about -z.  Its link
frames are then ``M F M``: positions with y negated and rotations ``M R M``, exactly
the kinematics' mirrored landmarks.

Collision geometry: the capsules of the self-collision model (upper arm, forearm,
hand per arm; the torso), each written as a cylinder plus two end spheres because URDF
has no capsule.  ``capsule_segments`` gives the same capsules as segments, for a
simulator that has real capsules (MuJoCo).  Masses and inertias are plausible
placeholders (the paper gives none), so that physics engines can load the model.
"""

import math
from pathlib import Path
from typing import NamedTuple
import xml.etree.ElementTree as ET

import numpy as np

from .kinematics import shoulder_position
from .robot import ARMS, N_JOINTS
from .rotations import rot_x, rot_z

MM = 1e-3
SEGMENTS = ('upper_arm', 'forearm', 'hand')
_FLIP = np.diag([1.0, -1.0, 1.0])
# Placeholder masses (kg) of the links that carry a segment, and of the short links.
_SEGMENT_MASS = {'upper_arm': 1.5, 'forearm': 1.0, 'hand': 0.4}
_SMALL_MASS = 0.2
_EFFORT = 40.0      # N m, placeholder actuator limit
_COLORS = {'right': '1.0 0.55 0.1 1.0', 'left': '0.1 0.6 1.0 1.0',
           'torso': '0.75 0.75 0.75 1.0'}


class Capsule(NamedTuple):
    """One collision capsule, fixed in a link: segment ends (m, link frame) and radius (m)."""

    name: str
    link: str
    start: np.ndarray
    end: np.ndarray
    radius: float


def link_name(side, index):
    """Return the name of link ``index`` (1..7) of an arm: DH frame ``index``."""
    return f'{side}_arm_link{index}'


def fingertip_link(side):
    """Return the name of an arm's fingertip link (the DH end-effector frame)."""
    return f'{side}_arm_fingertip'


def _fixed_part(theta_offset, d, a_prev, alpha_prev, mirrored):
    """Return (R, p in mm) of ``RotX(alpha) TransX(a) RotZ(offset) TransZ(d)``, mirrored."""
    sign = -1.0 if mirrored else 1.0
    rot = rot_x(sign * alpha_prev) @ rot_z(sign * theta_offset)
    pos = np.array([a_prev, 0.0, 0.0]) + rot @ np.array([0.0, 0.0, d])
    return rot, pos


def rpy(rot):
    """Return URDF roll, pitch, yaw of a rotation matrix (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    pitch = math.atan2(-rot[2, 0], math.hypot(rot[0, 0], rot[1, 0]))
    if math.cos(pitch) > 1e-9:
        roll = math.atan2(rot[2, 1], rot[2, 2])
        yaw = math.atan2(rot[1, 0], rot[0, 0])
    else:   # gimbal lock: put everything in yaw
        roll = 0.0
        yaw = math.atan2(-rot[0, 1], rot[1, 1])
    return tuple(0.0 if abs(v) < 1e-15 else v for v in (roll, pitch, yaw))


def joint_origins(robot, side):
    """
    Return the fixed origin of each joint of one arm and of its fingertip.

    A list of 8 ``(R, p_mm)``: the transforms from the parent link to the joint frame at
    zero angle (joints 1..7), then the fixed fingertip transform.
    """
    mirrored = robot.arms[side].mirrored
    out = [_fixed_part(robot.theta_offset[i], robot.d[i], robot.a_prev[i],
                       robot.alpha_prev[i], mirrored) for i in range(N_JOINTS)]
    out.append(_fixed_part(*robot.end_effector, mirrored))
    return out


def joint_axis(robot, side):
    """Return the joint axis in its own frame: +z, or -z for the mirrored arm."""
    return (0.0, 0.0, -1.0) if robot.arms[side].mirrored else (0.0, 0.0, 1.0)


def _frames(robot, side, q):
    """Return the 4x4 transforms (mm) of frames 1..7 and the fingertip for angles q."""
    frames = []
    pose = np.eye(4)
    sign = -1.0 if robot.arms[side].mirrored else 1.0
    for i, (rot, pos) in enumerate(joint_origins(robot, side)):
        step = np.eye(4)
        step[:3, :3] = rot @ (rot_z(sign * q[i]) if i < N_JOINTS else np.eye(3))
        step[:3, 3] = pos
        pose = pose @ step
        frames.append(pose)
    return frames


def _capsule_links(robot):
    """Return, per segment, (start frame, end frame, the link that carries it)."""
    # A segment is fixed in the link just before its end frame: that link holds the
    # end frame's origin through the next joint's fixed origin, and (checked by
    # capsule_segments) the start point too.
    return {'upper_arm': (0, robot.elbow_frame, robot.elbow_frame - 1),
            'forearm': (robot.elbow_frame, robot.wrist_frame, robot.wrist_frame - 1),
            'hand': (robot.wrist_frame, N_JOINTS + 1, N_JOINTS)}


def capsule_segments(robot):
    """
    Return the collision capsules (:class:`Capsule`), in metres, fixed in their links.

    Upper arm shoulder-elbow, forearm elbow-wrist and hand wrist-fingertip per arm, as
    in the self-collision objective (the shoulder is the fixed origin of frame 1), and
    the torso capsule in ``base_link``.  Raises ValueError if a robot file's DH table
    makes a segment's ends move relative to every link (no rigid capsule exists).
    """
    rng = np.random.default_rng(0)
    samples = [np.zeros(N_JOINTS)] + [rng.uniform(-math.pi, math.pi, N_JOINTS)
                                      for _ in range(3)]
    caps = []
    for side in ARMS:
        all_frames = [_frames(robot, side, q) for q in samples]
        for seg, (start, end, carrier) in _capsule_links(robot).items():
            points = []
            for frames in all_frames:
                inv = np.linalg.inv(frames[carrier - 1])
                p0 = (shoulder_position(robot, side) if start == 0
                      else frames[start - 1][:3, 3])
                p1 = frames[end - 1][:3, 3]
                points.append([(inv @ np.append(p, 1.0))[:3] for p in (p0, p1)])
            points = np.array(points)
            if np.max(np.abs(points - points[0])) > 1e-6:
                raise ValueError(f'{side} {seg}: its ends are not fixed in '
                                 f'{link_name(side, carrier)}; cannot make a rigid capsule')
            radius = float(getattr(robot.capsules, seg))
            caps.append(Capsule(f'{side}_arm_{seg}', link_name(side, carrier),
                                points[0, 0] * MM, points[0, 1] * MM, radius * MM))
    caps.append(Capsule('torso', 'base_link', np.array(robot.capsules.torso_top) * MM,
                        np.array(robot.capsules.torso_bottom) * MM,
                        robot.capsules.torso_radius * MM))
    return caps


def _fmt(values):
    return ' '.join(f'{v:.9g}' for v in values)


def _origin(parent, xyz, rot=None):
    attrs = {'xyz': _fmt(xyz)}
    attrs['rpy'] = _fmt(rpy(rot) if rot is not None else (0.0, 0.0, 0.0))
    ET.SubElement(parent, 'origin', attrs)


def _capsule_shapes(parent, tag, cap, material=None):
    """Append a cylinder and two spheres (URDF has no capsule) as ``tag`` elements."""
    axis = cap.end - cap.start
    length = float(np.linalg.norm(axis))
    shapes = [('sphere', cap.start, None, {'radius': f'{cap.radius:.9g}'}),
              ('sphere', cap.end, None, {'radius': f'{cap.radius:.9g}'})]
    if length > 1e-9:
        z = axis / length
        # A rotation taking z to the segment's direction.
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        rot = np.column_stack((x, np.cross(z, x), z))
        shapes.insert(0, ('cylinder', (cap.start + cap.end) / 2, rot,
                          {'radius': f'{cap.radius:.9g}', 'length': f'{length:.9g}'}))
    for i, (kind, centre, rot, attrs) in enumerate(shapes):
        element = ET.SubElement(parent, tag, {'name': f'{cap.name}_{kind}_{i}'})
        _origin(element, centre, rot)
        geometry = ET.SubElement(element, 'geometry')
        ET.SubElement(geometry, kind, attrs)
        if material is not None:
            ET.SubElement(element, 'material', {'name': material})


def _inertial(parent, mass, centre=(0.0, 0.0, 0.0), length=0.0, radius=0.03):
    """Append a solid-cylinder-like inertial (placeholder values, always positive)."""
    inertial = ET.SubElement(parent, 'inertial')
    _origin(inertial, centre)
    ET.SubElement(inertial, 'mass', {'value': f'{mass:.6g}'})
    side = mass * (3 * radius ** 2 + length ** 2) / 12.0
    ET.SubElement(inertial, 'inertia', {
        'ixx': f'{side:.6g}', 'iyy': f'{side:.6g}', 'izz': f'{mass * radius ** 2 / 2:.6g}',
        'ixy': '0', 'ixz': '0', 'iyz': '0'})


def urdf_tree(robot):
    """Return the URDF of ``robot`` as an ElementTree root element."""
    root = ET.Element('robot', {'name': robot.name})
    for side, rgba in _COLORS.items():
        material = ET.SubElement(root, 'material', {'name': side})
        ET.SubElement(material, 'color', {'rgba': rgba})
    caps = {c.link: c for c in capsule_segments(robot)}

    base = ET.SubElement(root, 'link', {'name': 'base_link'})
    torso = caps['base_link']
    _inertial(base, 10.0, (torso.start + torso.end) / 2,
              float(np.linalg.norm(torso.end - torso.start)), torso.radius)
    _capsule_shapes(base, 'visual', torso, 'torso')
    _capsule_shapes(base, 'collision', torso)
    # A visual shoulder bar, so that RViz shows what joins the arms.
    shoulder_y = abs(float(shoulder_position(robot, 'right')[1])) * MM
    bar = Capsule('shoulders', 'base_link', np.array([0.0, -shoulder_y, 0.0]),
                  np.array([0.0, shoulder_y, 0.0]), 0.03)
    _capsule_shapes(base, 'visual', bar, 'torso')

    for side in ARMS:
        arm = robot.arms[side]
        parent = 'base_link'
        origins = joint_origins(robot, side)
        for i in range(N_JOINTS):
            name = link_name(side, i + 1)
            joint = ET.SubElement(root, 'joint', {'name': arm.joint_names[i],
                                                  'type': 'revolute'})
            rot, pos = origins[i]
            _origin(joint, pos * MM, rot)
            ET.SubElement(joint, 'parent', {'link': parent})
            ET.SubElement(joint, 'child', {'link': name})
            ET.SubElement(joint, 'axis', {'xyz': _fmt(joint_axis(robot, side))})
            ET.SubElement(joint, 'limit', {
                'lower': f'{arm.lower[i]:.9g}', 'upper': f'{arm.upper[i]:.9g}',
                'effort': f'{_EFFORT:g}',
                'velocity': f'{robot.velocity_limits[i]:.9g}'})
            link = ET.SubElement(root, 'link', {'name': name})
            cap = caps.get(name)
            if cap is None:
                _inertial(link, _SMALL_MASS)
            else:
                seg = cap.name[len(side) + len('_arm_'):]
                _inertial(link, _SEGMENT_MASS[seg], (cap.start + cap.end) / 2,
                          float(np.linalg.norm(cap.end - cap.start)), cap.radius)
                _capsule_shapes(link, 'visual', cap, side)
                _capsule_shapes(link, 'collision', cap)
            parent = name
        tip = ET.SubElement(root, 'joint', {'name': f'{side}_arm_fingertip_joint',
                                            'type': 'fixed'})
        rot, pos = origins[N_JOINTS]
        _origin(tip, pos * MM, rot)
        ET.SubElement(tip, 'parent', {'link': parent})
        ET.SubElement(tip, 'child', {'link': fingertip_link(side)})
        ET.SubElement(root, 'link', {'name': fingertip_link(side)})
    return root


def urdf_string(robot):
    """Return the URDF of ``robot`` as an XML document (a string ending in a newline)."""
    root = urdf_tree(robot)
    ET.indent(root, space='  ')
    source = Path(robot.source).name.replace('--', '- -')
    header = ('<?xml version="1.0"?>\n'
              f'<!-- Generated by namo-recovery urdf from {source}; do not edit: '
              'regenerate it. -->\n')
    return header + ET.tostring(root, encoding='unicode') + '\n'
