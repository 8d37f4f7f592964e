"""
A robot built from a recovery profile, for the engine as it is (ROS-free).

:func:`robot_from_profile` turns a :class:`~.robot_profile.RobotProfile` (a URDF plus
its recovery profile) into a :class:`ProfileRobot`: the same joints, limits, tools and
capsules interface as Namo's DH :class:`~.robot.RobotModel` (both are
:class:`~.robot.RobotJoints`), so the score, the collision term, the keyframe search
and ``recover`` take it unchanged.  Only the kinematics differ: each arm is its
profile chain compiled once more as a *reduced* chain, every chain joint that the
recovery does not move (held joints, staged-expansion joints) locked at 0 and folded
into the fixed transforms, in millimetres.  :mod:`.kinematics` runs that chain
whenever a robot has ``chains``.

- Landmarks are by role: elbow, wrist, fingertip (``tip``) and palm, from the profile.
- The shoulder (the fixed end of the upper-arm capsule, and the origin of each arm's
  shoulder frame) is the origin of the arm's first recovery joint, which that joint's
  own turn does not move.
- A tool lengthens the hand as on Namo: the fingertip's offset from the last joint
  frame before it is scaled so that it grows by the tool's length.
- Joint limits and velocity limits come from the URDF (or the profile where the URDF
  has none); the arm's joints are in chain order, base first.
- The arms are not mirror images of each other: each is its own chain (``mirrored``
  is False), so a library for such a robot gives each arm its own angles.
"""

import copy
from dataclasses import dataclass, field, replace
import os

import numpy as np

from .capsules import CapsuleModel
from .chain import compile_chain, KinematicChain
from .kinematics import ArmJacobian, ArmLandmarks
from .robot import ArmModel, ARMS, RobotJoints
from .robot_profile import load_profile, MM_PER_M, RobotProfile
from .shared_joints import shared_joints, SharedJoints
from ..errors import ConfigError

# The joint counts per arm that the engine takes from a profile robot today.
ENGINE_ARM_JOINTS = (5, 8)


@dataclass(frozen=True)
class ArmChain:
    """One arm's reduced chain (mm): the recovery joints move, the others are at 0."""

    side: str
    chain: KinematicChain
    shoulder: np.ndarray                    # (3,) mm, the first recovery joint's origin
    tooled: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def n_joints(self) -> int:
        """Return the number of joints this arm moves."""
        return self.chain.n_joints

    def with_tool(self, tool: float) -> KinematicChain:
        """Return the chain whose fingertip is lengthened by ``tool`` mm (cached)."""
        if not tool:
            return self.chain
        found = self.tooled.get(tool)
        if found is None:
            tip = self.chain.landmarks['tip']
            offset = np.asarray(tip.pos, dtype=float)
            reach = float(np.linalg.norm(offset))
            if reach < 1e-9:
                raise ValueError(f"{self.side} arm: the fingertip is at its joint's origin; "
                                 'expected a fingertip offset to lengthen with a tool')
            found = copy.copy(self.chain)
            found.landmarks = dict(self.chain.landmarks)
            found.landmarks['tip'] = replace(tip, pos=tuple(offset * (1.0 + tool / reach)))
            self.tooled[tool] = found
        return found

    def forward(self, q: np.ndarray, tool: float = 0.0) -> ArmLandmarks:
        """Return the landmarks for q (..., n) (rad, unchecked) with a tool of ``tool`` mm."""
        lead = q.shape[:-1]
        lm = self.with_tool(tool).batch_forward(q.reshape(-1, self.chain.n_joints))
        if len(lead) == 1:
            return lm
        return ArmLandmarks(*(a.reshape(lead + a.shape[1:]) for a in lm))

    def jacobian(self, q: np.ndarray, tool: float = 0.0) -> tuple:
        """Return ``(landmarks, ArmJacobian)`` for q (N, n) with a tool of ``tool`` mm."""
        lm, jac = self.with_tool(tool).jacobian(q)
        return lm, ArmJacobian(jac.positions, jac.axes)


@dataclass(frozen=True)
class ProfileRobot(RobotJoints):
    """
    A robot from its URDF and recovery profile, with the engine's robot interface.

    Lengths in millimetres, angles in radians.  Each arm's own speeds are in
    :attr:`arm_velocity` (:meth:`arm_velocity_limits`), and :attr:`joint_velocity_limits`
    lists them joint by joint,
    as the engine and the player use them.  ``velocity_limits`` (one speed per arm
    joint, the slower of the two arms', as on Namo) is kept for arms of one joint count;
    it is empty when the counts differ.
    """

    name: str
    arms: dict                  # side -> ArmModel
    chains: dict                # side -> ArmChain
    source: str
    capsules: CapsuleModel = CapsuleModel()
    tools: tuple = ()
    velocity_limits: tuple = ()
    corrections: tuple = field(default=(), compare=False, repr=False)
    learned: tuple = field(default=(), compare=False, repr=False)
    arm_velocity: dict = field(default_factory=dict)
    profile: RobotProfile | None = field(default=None, compare=False, repr=False)
    shared: SharedJoints | None = field(default=None, compare=False, repr=False)

    def arm_velocity_limits(self, side: str) -> tuple:
        """Speed limit (rad/s) of each joint of one arm, base first (the URDF's or profile's)."""
        return tuple(self.arm_velocity[side])

    def geometry_key(self) -> bytes:
        """Return bytes that change with any kinematic constant (for fingerprints)."""
        parts = []
        for side in ARMS:
            if side not in self.chains:
                continue
            ch = self.chains[side].chain
            parts.append(repr((side, ch.joint_names, ch.describe())))
        return '\n'.join(parts).encode()


def _reduced_arm(profile, side):
    """Return the ArmChain of one profile arm, its non-recovery joints locked at 0."""
    arm = profile.arms[side]
    where = f'profile {profile.source}, arms.{side}'
    chain = compile_chain(profile.tree, arm.chain.base, arm.chain.tip, arm.marks, MM_PER_M,
                          where=where, locked=arm.held + arm.expansion)
    lo, hi = ENGINE_ARM_JOINTS
    if not lo <= chain.n_joints <= hi:
        raise ConfigError(profile.source, f'arms.{side}.joints',
                          f'{chain.n_joints} joints; the recovery engine takes {lo} to {hi} '
                          'joints per arm from a profile')
    first = profile.tree.joints[chain.joint_names[0]].child
    origin = chain.link_frames(np.zeros(chain.n_joints), [first])[first][0][0]
    return ArmChain(side, chain, np.array(origin, dtype=float))


def robot_from_profile(profile: RobotProfile | str | os.PathLike,
                       capsules: CapsuleModel | None = None) -> ProfileRobot:
    """
    Return the engine's robot for a recovery profile (a RobotProfile or its file).

    ``capsules`` overrides the self-collision capsules, which are otherwise fitted to
    the URDF's collision geometry (:mod:`.robot_capsules`).  Raises ConfigError (one
    line) for a profile the engine cannot take: it needs both arms, each of 5 to 8
    joints (the two counts may differ).
    """
    from .robot_capsules import fit_capsules
    if not isinstance(profile, RobotProfile):
        profile = load_profile(profile)
    missing = [side for side in ARMS if side not in profile.arms]
    if missing:
        raise ConfigError(profile.source, 'arms', f'no {" or ".join(missing)} arm; the '
                          'recovery engine takes two-armed robots for now')
    chains = {side: _reduced_arm(profile, side) for side in ARMS}
    arms = {side: ArmModel(side, chains[side].chain.joint_names,
                           chains[side].chain.lower.copy(), chains[side].chain.upper.copy(),
                           mirrored=False) for side in ARMS}
    speeds = {side: tuple(profile.velocity_limits[j] for j in arms[side].joint_names)
              for side in ARMS}
    counts = {len(speeds[side]) for side in ARMS}
    slowest = (tuple(float(v) for v in np.min([speeds[s] for s in ARMS], axis=0))
               if len(counts) == 1 else ())
    robot = ProfileRobot(profile.name, arms, chains, profile.source, CapsuleModel(),
                         velocity_limits=slowest, arm_velocity=speeds, profile=profile,
                         shared=shared_joints(profile))
    return replace(robot, capsules=capsules if capsules is not None else fit_capsules(robot))
