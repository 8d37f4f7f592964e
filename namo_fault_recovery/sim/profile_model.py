"""
A profile robot (its own URDF plus a recovery profile) in MuJoCo, for :mod:`.physics`.

:class:`~.physics.NamoSim` builds Namo from its generated URDF, whose capsules are
rigid in their links.  A robot from a profile (:mod:`..model.profile_robot`) is
loaded from its own URDF instead:

- The URDF is read with yourdfpy and written again without its visual and collision
  geometry (real URDFs name ``package://`` meshes, often .dae, which MuJoCo can
  neither resolve nor read); the simulator needs only the kinematics, the inertias and
  the optimiser's capsules.
- Every joint the arms do not move (legs, head, torso, grippers, mimic joints, a
  floating base) is made fixed before the import: the body cannot collapse, fall or
  drift, and the model has exactly the arms' degrees of freedom.  Links joined by
  fixed joints stay separate bodies (``fusestatic`` off) so that each landmark link
  has a body to carry its site.  Static links lose their inertia (it moves nothing,
  and real URDFs have invalid ones there).
- The capsules are the optimiser's (:func:`..model.self_contact.arm_segments`):
  shoulder-elbow, elbow-wrist, wrist-fingertip between the profile's landmarks, and
  the torso in the arms' base frame.  On a URDF robot a segment's ends need not be
  fixed in one link (Talos's shoulder is the origin of its first joint, a mount
  beside the torso, while its upper arm turns about joints 2 and 3 elsewhere), so a
  rigid capsule would not be the optimiser's.  Each arm capsule is therefore carried
  by its end landmark's body and re-placed between the landmark sites before every
  step (:class:`MovingCapsules`), one step behind the joints (2 ms: well under a
  millimetre at the arms' speeds).
"""

from pathlib import Path

import mujoco
import numpy as np

from ..model.self_contact import SEGMENTS
from ..model.urdf_tree import load_urdf_document

LANDMARK_SITES = ('shoulder', 'elbow', 'wrist', 'tip')
MIN_INERTIA = 1e-6      # kg m^2: the least principal inertia of a moving link
MIN_RADIUS = 1e-6       # m: a capsule of radius 0 (a segment) as MuJoCo takes it
_RGBA = {'right': (1.0, 0.55, 0.1, 1.0), 'left': (0.1, 0.6, 1.0, 1.0),
         'torso': (0.75, 0.75, 0.75, 1.0)}


def is_profile_robot(robot):
    """Return True for a robot from a URDF profile (it has compiled ``chains``)."""
    return (getattr(robot, 'chains', None) is not None
            and getattr(robot, 'profile', None) is not None)


def sim_urdf(robot, urdf=None, joints=None):
    """
    Return the robot's URDF as MuJoCo takes it: no geometry, only ``joints`` move.

    ``urdf`` is the simulator's own copy (a document or a path); by default the
    profile's URDF file.  The ``joints`` that move (default ``robot.joint_names``; the
    simulator node adds the shared ones, a torso: ``robot.played_joints``) keep their
    type and limits; every other joint becomes fixed (and loses any mimic).
    """
    source = robot.profile.tree.source
    if urdf is None:
        urdf = Path(source)
    elif not (isinstance(urdf, str) and urdf.lstrip().startswith('<')):
        source, urdf = str(urdf), Path(urdf)
    doc = load_urdf_document(urdf, source)
    moving = set(robot.joint_names if joints is None else joints)
    for link in doc.robot.links:
        link.visuals = []
        link.collisions = []
    for joint in doc.robot.joints:
        if joint.name not in moving:
            joint.type = 'fixed'
            joint.mimic = None
    _check_inertias(doc, moving)
    text = doc.write_xml_string()
    return text.decode() if isinstance(text, bytes) else text


def _check_inertias(doc, moving):
    """
    Drop the inertia of links no arm joint moves; make a moving link's inertia valid.

    A static link's mass and inertia change nothing in a model whose base is fixed, and
    real URDFs carry invalid ones there (TIAGo++'s antennas: an inertia that is not
    positive definite), which MuJoCo refuses.  A moving link's inertia keeps its axes;
    eigenvalues below :data:`MIN_INERTIA` are raised to it.
    """
    below = {}
    for joint in doc.robot.joints:
        below.setdefault(joint.parent, []).append(joint)
    carried, todo = set(), [j for j in doc.robot.joints if j.name in moving]
    while todo:
        joint = todo.pop()
        carried.add(joint.child)
        todo += below.get(joint.child, [])
    for link in doc.robot.links:
        if link.inertial is None:
            continue
        if link.name not in carried:
            link.inertial = None
            continue
        values, axes = np.linalg.eigh(np.asarray(link.inertial.inertia, dtype=float))
        if values.min() < MIN_INERTIA:
            link.inertial.inertia = (axes * np.maximum(values, MIN_INERTIA)) @ axes.T


def profile_spec(robot, urdf=None, joints=None):
    """Return the MjSpec of a profile robot: its URDF without geometry, links kept apart."""
    joints = tuple(robot.joint_names if joints is None else joints)
    spec = mujoco.MjSpec.from_string(sim_urdf(robot, urdf, joints))
    spec.compiler.fusestatic = False
    missing = [name for name in joints if spec.joint(name) is None]
    if missing:
        raise ValueError(f'joint {missing[0]!r} of the profile robot {robot.name} is not '
                         'in the simulated URDF; expected its arm and shared joints')
    for name in joints:
        spec.joint(name).frictionloss = 0.0     # the same PD design as Namo's arms
    return spec


def _landmark_links(robot, side):
    """Return {site role: (link, offset m)} of one arm: the shoulder, then the landmarks."""
    profile = robot.profile
    first = robot.chains[side].chain.joint_names[0]
    out = {'shoulder': (profile.tree.joints[first].child, (0.0, 0.0, 0.0))}
    for role in LANDMARK_SITES[1:]:
        spec = profile.arms[side].marks[role]
        out[role] = spec if isinstance(spec, tuple) else (spec, (0.0, 0.0, 0.0))
    return out


def add_profile_capsules(spec, robot, pairs, allowances):
    """
    Add a profile robot's landmark sites, capsules and contact pairs to ``spec``.

    The torso capsule is fixed in the arms' base link (its frame is the optimiser's);
    each arm capsule goes on its end landmark's body, placed by :class:`MovingCapsules`.
    Every checked pair that is not a designed contact becomes a MuJoCo contact pair.
    """
    cap = robot.capsules
    for side in robot.chains:
        for role, (link, offset) in _landmark_links(robot, side).items():
            spec.body(link).add_site(name=f'{side}_{role}', pos=np.asarray(offset, float))
        ends = _landmark_links(robot, side)
        for k, seg in enumerate(SEGMENTS):
            body = spec.body(ends[LANDMARK_SITES[k + 1]][0])
            _capsule(body, np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1e-3]), f'{side}_arm_{seg}',
                     getattr(cap, seg) * 1e-3, _RGBA[side])
    _capsule(*_torso_body(spec, robot), 'torso', cap.torso_radius * 1e-3, _RGBA['torso'])
    for a, b in pairs:
        if (a, b) not in allowances:
            spec.add_pair(name=f'{a}-{b}', geomname1=a, geomname2=b)


def _torso_body(spec, robot):
    """
    Return the torso capsule's body and its ends there (``fromto``, m).

    The capsule is the optimiser's, in the arms' base frame at rest; with joints shared
    by both arms (a torso) it rides on the link they end on, as the arms do.
    """
    ends = np.stack((robot.capsules.torso_top, robot.capsules.torso_bottom)).astype(float)
    link = robot.chains['right'].chain.base
    if robot.shared is not None:
        link = robot.shared.link
        zero = np.zeros((1, len(robot.shared.names)))
        origin, rot = (a[0] for a in robot.shared.chain.link_frames(zero, [link])[link])
        ends = (ends - origin) @ rot          # into the link's frame: R^T (p - o)
    return spec.body(link) or spec.worldbody, ends.reshape(-1) * 1e-3


def _capsule(body, fromto, name, radius, rgba):
    """Add a capsule; radius 0 (no geometry to fit: a bare segment) becomes MIN_RADIUS."""
    geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=fromto,
                         size=[max(radius, MIN_RADIUS), 0.0, 0.0], rgba=rgba)
    geom.contype = 0          # only the explicit pairs collide
    geom.conaffinity = 0


class MovingCapsules:
    """
    The arm capsules of a profile robot, re-placed between their landmark sites.

    :meth:`update` writes each capsule's position, orientation, half-length and
    bounding sizes (``geom_rbound``, ``geom_aabb``, which the collision pass reads)
    into the model from the sites' world positions in ``data`` (the last forward pass).
    """

    def __init__(self, model, robot):
        names = [(f'{side}_arm_{seg}', f'{side}_{LANDMARK_SITES[k]}',
                  f'{side}_{LANDMARK_SITES[k + 1]}')
                 for side in robot.chains for k, seg in enumerate(SEGMENTS)]
        self.geoms = np.array([model.geom(g).id for g, _, _ in names])
        self.start = np.array([model.site(s).id for _, s, _ in names])
        self.end = np.array([model.site(e).id for _, _, e in names])
        self.bodies = model.geom_bodyid[self.geoms].copy()
        self.radius = model.geom_size[self.geoms, 0].copy()
        self._quat = np.zeros(4)

    def update(self, model, data):
        """Place the capsules between their sites as ``data`` has them."""
        pos = data.xpos[self.bodies]
        rot = data.xmat[self.bodies].reshape(-1, 3, 3)
        a = np.einsum('kji,kj->ki', rot, data.site_xpos[self.start] - pos)
        b = np.einsum('kji,kj->ki', rot, data.site_xpos[self.end] - pos)
        axis = b - a
        half = np.linalg.norm(axis, axis=1) / 2.0
        model.geom_pos[self.geoms] = (a + b) / 2.0
        model.geom_size[self.geoms, 1] = half
        model.geom_rbound[self.geoms] = self.radius + half
        model.geom_aabb[self.geoms, :3] = 0.0
        model.geom_aabb[self.geoms, 3:5] = self.radius[:, None]
        model.geom_aabb[self.geoms, 5] = self.radius + half
        for k, g in enumerate(self.geoms):
            if half[k] > 1e-9:
                mujoco.mju_quatZ2Vec(self._quat, axis[k])
                model.geom_quat[g] = self._quat
