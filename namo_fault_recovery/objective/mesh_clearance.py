"""
Self-collision measured on a robot's own URDF collision geometry (Pinocchio and coal).

The search checks self-collision with capsules (:mod:`.collision`): three per arm
between its landmarks and one for the torso, fitted to the URDF's collision geometry
(:mod:`..model.robot_capsules`), because they are batched and differentiable.  A
capsule is round and one radius long, and a robot's links are neither: this module
measures the same pairs (:data:`~..model.self_contact.PAIRS`) on the URDF's meshes and
primitives themselves, the geometry a robot team declares (MoveIt and its planners
check the same), so that what the capsules pass can be cross-checked
(``namo-recovery bench meshes``).  Each capsule stands for the links
:func:`~..model.robot_capsules.segment_links` assigns to it; the torso for the links
above both arms' first joints.  Distances are exact (coal's, between meshes'
bounding-volume hierarchies and primitives), one pose at a time: a check, not a
search term.

Pinocchio (``pin``, with coal) comes with the ``robots`` extra; without it,
:class:`MeshClearance` raises ImportError with the command that installs it.
"""

from pathlib import Path

import numpy as np

from ..model.robot import ARMS
from ..model.robot_capsules import segment_links
from ..model.self_contact import PAIRS, SEGMENTS

TOUCH_MM = 0.0      # meshes this close (or overlapping: coal reports 0) touch


def _pinocchio():
    try:
        import pinocchio
    except ImportError as exc:
        raise ImportError('the URDF mesh check needs Pinocchio: pip install -e '
                          "'.[robots]' (or pip install pin)") from exc
    return pinocchio


def _package_dirs(urdf_path):
    """Return the folders a ``package://NAME/...`` mesh may be resolved from: the ancestors."""
    return [str(p) for p in list(Path(urdf_path).resolve().parents)[:5]]


class MeshClearance:
    """
    Distances (mm) between the URDF collision geometry of every checked pair of a robot.

    ``robot`` is a profile robot (:func:`..model.profile_robot.robot_from_profile`);
    the joints it does not move (a torso, a head) stay at 0, as its model holds them.
    """

    def __init__(self, robot):
        pin = _pinocchio()
        profile = robot.profile
        if profile.urdf_text is not None:
            dirs = [profile.mesh_dir] if profile.mesh_dir else []
            self.model = pin.buildModelFromXML(profile.urdf_text)
            self.geometry = pin.buildGeomFromUrdfString(
                self.model, profile.urdf_text, pin.GeometryType.COLLISION, package_dirs=dirs)
        else:
            path = str(profile.tree.source)
            self.model = pin.buildModelFromUrdf(path)
            self.geometry = pin.buildGeomFromUrdf(self.model, path, pin.GeometryType.COLLISION,
                                                  package_dirs=_package_dirs(path))
        self._pin = pin
        self._columns = {side: [self.model.joints[self.model.getJointId(name)].idx_q
                                for name in robot.arms[side].joint_names] for side in ARMS}
        objects = self._objects(robot)
        self.pairs = []              # per pair of PAIRS: its geometry-pair indices
        for a, i, b, k in PAIRS:
            first = objects[(a, i if a != 'torso' else None)]
            second = objects[(b, k if b != 'torso' else None)]
            indices = []
            for x in first:
                for y in second:
                    indices.append(len(self.geometry.collisionPairs))
                    self.geometry.addCollisionPair(pin.CollisionPair(x, y))
            self.pairs.append(indices)
        self._data = self.model.createData()
        self._geometry_data = pin.GeometryData(self.geometry)

    def _objects(self, robot):
        """Return {(side, segment index) or ('torso', None): [geometry object index]}."""
        owner = {}
        for side in ARMS:
            for seg, links in segment_links(robot, side).items():
                key = ('torso', None) if seg == 'torso' else (side, SEGMENTS.index(seg))
                for link in links:
                    owner[link] = key
        objects = {key: [] for key in set(owner.values())}
        for index, obj in enumerate(self.geometry.geometryObjects):
            key = owner.get(self.model.frames[obj.parentFrame].name)
            if key is not None:
                objects[key].append(index)
        return objects

    def distances(self, q_right, q_left) -> np.ndarray:
        """
        Return the smallest distance (mm) of every pair of PAIRS at one pose, (pairs,).

        ``q_right`` and ``q_left`` are the arms' joint angles (rad), in the robot's
        order; a pair without collision geometry on one side reads ``inf``.
        """
        q = self._pin.neutral(self.model)
        for side, angles in zip(ARMS, (q_right, q_left)):
            q[self._columns[side]] = np.asarray(angles, dtype=float)
        self._pin.computeDistances(self.model, self._data, self.geometry,
                                   self._geometry_data, q)
        results = self._geometry_data.distanceResults
        return np.array([min((results[n].min_distance for n in indices), default=np.inf)
                         for indices in self.pairs]) * 1000.0
