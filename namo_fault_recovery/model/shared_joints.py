"""
The joints shared by both arms (a torso or waist), as a rigid motion of the arms' base.

A profile's ``shared`` joints sit above both arms: turning them carries both arms, and
everything fixed to the link they end on (the chest the arms hang from), as one rigid
body.  The arms' reduced chains (:mod:`.profile_robot`) hold them at 0, so what the
shared joints add is one rigid motion of the arms' base per configuration:
``p(t) = R(t) p(0) + d(t)`` for every point carried, which :class:`SharedJoints`
computes batched (mm).

That is also why the staged expansion into a torso (:mod:`..recovery.lean`) searches
the arms as they are: the similarity score measures distances and rotations, which a
rigid motion keeps, so scoring arms leaned by ``t`` against a reference equals scoring
the upright arms against the reference moved back by ``t`` (:meth:`SharedJoints.back`);
and the arms, the chest and the torso's shape move together, so their self-contact is
unchanged.  What hangs below the shared joints (hips, legs) is not in the collision
model.
"""

from dataclasses import dataclass

import numpy as np

from .chain import compile_chain, KinematicChain
from .kinematics import ArmLandmarks
from .robot_profile import MM_PER_M, RobotProfile
from ..errors import ConfigError


@dataclass(frozen=True)
class SharedJoints:
    """
    The shared joints of a profile robot: names, limits, speeds and their rigid motion.

    ``chain`` runs from the arms' base link to ``link``, the child of the last shared
    joint (mm); only the shared joints move in it.
    """

    names: tuple
    lower: np.ndarray
    upper: np.ndarray
    velocity: tuple          # rad/s per joint, the URDF's (or the profile's)
    chain: KinematicChain
    link: str

    def motion(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """
        Return ``(R (N, 3, 3), d (N, 3))``, the rigid motion of the shared joints at ``t``.

        A point fixed above the shared joints at ``t`` (N, S) is at ``p(t) = R p(0) + d``
        in the arms' base frame (mm).
        """
        t = np.atleast_2d(np.asarray(t, dtype=float))
        zero = np.zeros((1, len(self.names)))
        p0, r0 = (a[0] for a in self.chain.link_frames(zero, [self.link])[self.link])
        pt, rt = self.chain.link_frames(t, [self.link])[self.link]
        rot = rt @ r0.T
        return rot, pt - rot @ p0

    def carry(self, lm: ArmLandmarks, t: np.ndarray) -> ArmLandmarks:
        """Return upright landmarks (N rows) carried by the shared joints at ``t`` (N, S)."""
        rot, d = self.motion(t)
        moved = [np.einsum('nij,nj->ni', rot, p) + d for p in (lm.elbow, lm.wrist, lm.tip)]
        return ArmLandmarks(*moved, rot @ lm.palm)

    def back(self, lm: ArmLandmarks, t: np.ndarray) -> ArmLandmarks:
        """
        Return base-frame landmarks (N rows) as seen from the torso leaned by ``t`` (N, S).

        The inverse of :meth:`carry`: where the upright arms must put their landmarks for
        the leaned arms to put them at ``lm``.
        """
        rot, d = self.motion(t)
        inv = np.swapaxes(rot, -1, -2)
        moved = [np.einsum('nij,nj->ni', inv, p - d) for p in (lm.elbow, lm.wrist, lm.tip)]
        return ArmLandmarks(*moved, inv @ lm.palm)

    def within(self, t: np.ndarray, tol: float = 1e-9) -> bool:
        """Return whether every row of ``t`` is within the joints' limits."""
        t = np.atleast_2d(t)
        return bool(np.all(t >= self.lower - tol) and np.all(t <= self.upper + tol))


def shared_joints(profile: RobotProfile) -> SharedJoints | None:
    """
    Return the profile's shared joints (None without any), compiled from its URDF.

    The shared joints are the first movable joints of each arm's chain; the chain to
    the child of the last of them is compiled with every other joint on it held at 0.
    """
    if not profile.shared:
        return None
    arm = next(iter(profile.arms.values()))
    path = profile.tree.path(arm.chain.base, arm.chain.tip)
    last = max(i for i, joint in enumerate(path) if joint.name in profile.shared)
    link = path[last].child
    others = tuple(j.name for j in path[:last + 1] if j.name not in profile.shared)
    where = f'profile {profile.source}, shared'
    chain = compile_chain(profile.tree, arm.chain.base, link, None, MM_PER_M, where=where,
                          locked=others)
    if tuple(chain.joint_names) != tuple(profile.shared):
        raise ConfigError(profile.source, 'shared', f'{list(profile.shared)}, but the chain '
                          f'{arm.chain.base} -> {link} moves {list(chain.joint_names)}; '
                          'expected them in chain order')
    velocity = tuple(float(profile.velocity_limits[n]) for n in chain.joint_names)
    return SharedJoints(tuple(chain.joint_names), chain.lower.copy(), chain.upper.copy(),
                        velocity, chain, link)
