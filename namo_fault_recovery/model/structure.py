"""
A structural correction learned on the robot, applied to the planner's model (ROS-free).

The gesture player's exploration (``explore/corrections.py``) fits a few correction
parameters per arm to what the fingertip tracker measured, on the nominal chain of a
recovery profile (the URDF plus its profile).  :class:`ArmCorrection` is that result as
plain data (what travels between the nodes and is kept on disk); each group is one kind
of change:

- ``tip_offset`` (mm, in the chain tip link's frame): a tool, a longer or shorter hand;
- ``offset:JOINT`` (deg): the joint's true angle is its reading plus this;
- ``bend:LINK`` (a rotation vector, deg, in LINK's frame): everything beyond LINK's
  frame turned about its origin.

:func:`corrected_arm` compiles the corrected arm chain once: each joint offset and bend
is folded into the URDF tree's joint origins (a bend turns the origin of the chain joint
after LINK, a joint offset turns the joint's own origin about its axis), and the tip
offset moves the fingertip landmark, so the compiled chain's forward kinematics and
analytic Jacobians are those of the corrected arm, for every landmark (elbow, wrist,
fingertip, palm).  ``RobotJoints.with_corrections`` then gives the engine a robot whose
kinematics run that chain for the corrected arm (:mod:`.kinematics`), on Namo's DH
model as on a profile robot.  The engine is handed the nominal robot carrying the
corrections (``with_learned``: a :class:`LearnedArm` per arm), so that the design is
still scored against the nominal robot; its ``changed_model`` applies them where it
applies a tool.  The profile's nominal chain must be the robot's own arm: checked at a
few poses (:func:`check_matches`), else a one-line ValueError.
"""

from dataclasses import dataclass, replace
import math

import numpy as np

from .chain import compile_chain
from .profile_robot import ArmChain
from .robot import ARMS
from .robot_profile import MM_PER_M
from .rotations import rot_axis, rotation_vectors
from .urdf_tree import UrdfJoint

SIZES = {'tip_offset': 3, 'offset': 1, 'bend': 3}
UNITS = {'tip_offset': 'mm', 'offset': 'deg', 'bend': 'deg'}
MATCH_MM = 0.01          # the profile's nominal arm must agree with the robot's within this


@dataclass(frozen=True)
class ArmCorrection:
    """
    One arm's fitted structural correction and what it was measured against.

    ``groups`` and ``params`` are ``explore.corrections.Correction``'s (one tuple of mm
    or deg per group); ``gesture``, ``library_stamp`` (ns), ``measured_error_mm`` (at the
    typical points, as the tracker measured the explored poses), ``trials`` and
    ``method`` say where it comes from; ``profile`` names the robot of the chain it was
    fitted on; ``unadapted_error_mm`` is what the first trial of each typical point
    measured (the poses of the version explored from).
    """

    side: str
    groups: tuple = ()
    params: tuple = ()
    gesture: str = ''
    library_stamp: int = 0
    measured_error_mm: tuple = ()
    trials: int = 0
    method: str = ''
    profile: str = ''
    unadapted_error_mm: tuple = ()     # per typical point, its first trial (the old poses)

    def __post_init__(self):
        """Refuse a malformed correction with one line naming the value."""
        if self.side not in ARMS:
            raise ValueError(f'correction arm {self.side!r}; expected one of {", ".join(ARMS)}')
        if len(self.groups) != len(self.params):
            raise ValueError(f'correction of the {self.side} arm: {len(self.groups)} groups '
                             f'for {len(self.params)} parameter sets')
        for group, values in zip(self.groups, self.params):
            kind, _, where = str(group).partition(':')
            if kind not in SIZES or (kind != 'tip_offset') != bool(where):
                raise ValueError(f'correction group {group!r}; expected tip_offset, '
                                 f'offset:JOINT or bend:LINK')
            if len(values) != SIZES[kind] or not all(math.isfinite(v) for v in values):
                raise ValueError(f'correction group {group}: expected {SIZES[kind]} finite '
                                 f'values, got {values!r}')

    @property
    def measured_mean_mm(self) -> float:
        """Return the mean measured error at the typical points (nan if none)."""
        return float(np.mean(self.measured_error_mm)) if self.measured_error_mm else math.nan

    def describe(self) -> str:
        """Return the groups and values, e.g. ``tip_offset (-50.00, 0.10, -0.20) mm``."""
        if not self.groups:
            return 'none'
        return '; '.join(f'{g} ({", ".join(f"{v:.2f}" for v in p)}) {UNITS[g.split(":")[0]]}'
                         for g, p in zip(self.groups, self.params))

    def to_dict(self) -> dict:
        """Return the JSON-ready dict of this correction."""
        return {'side': self.side, 'groups': list(self.groups),
                'params': [list(p) for p in self.params], 'gesture': self.gesture,
                'library_stamp': int(self.library_stamp),
                'measured_error_mm': list(self.measured_error_mm), 'trials': self.trials,
                'method': self.method, 'profile': self.profile,
                'unadapted_error_mm': list(self.unadapted_error_mm)}

    @classmethod
    def from_dict(cls, doc: dict) -> 'ArmCorrection':
        """Rebuild from :meth:`to_dict` output; raise ValueError naming what is wrong."""
        try:
            return cls(str(doc['side']), tuple(str(g) for g in doc.get('groups', ())),
                       tuple(tuple(float(v) for v in p) for p in doc.get('params', ())),
                       str(doc.get('gesture', '')), int(doc.get('library_stamp', 0)),
                       tuple(float(e) for e in doc.get('measured_error_mm', ())),
                       int(doc.get('trials', 0)), str(doc.get('method', '')),
                       str(doc.get('profile', '')),
                       tuple(float(e) for e in doc.get('unadapted_error_mm', ())))
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f'malformed correction: {exc!r}') from None


@dataclass(frozen=True)
class LearnedArm:
    """A correction and its compiled arm chain, as ``RobotJoints.with_learned`` takes it."""

    correction: ArmCorrection
    chain: ArmChain


def learned_arms(profile, corrections) -> tuple:
    """Return the LearnedArm of each ArmCorrection, compiled on ``profile``."""
    return tuple(LearnedArm(c, corrected_arm(profile, c)) for c in corrections)


def _turned(joint: UrdfJoint, rot: np.ndarray, before: bool) -> UrdfJoint:
    """Return ``joint`` with its origin turned by ``rot`` (before: in the parent's frame)."""
    turn = np.eye(4)
    turn[:3, :3] = rot
    origin = turn @ joint.origin if before else joint.origin @ turn
    return replace(joint, origin=origin)


def corrected_tree(tree, path_joints, correction: ArmCorrection):
    """Return ``tree`` with the joint offsets and bends of ``correction`` in its origins."""
    joints = dict(tree.joints)
    on_path = {j.parent: j.name for j in path_joints}
    for group, values in zip(correction.groups, correction.params):
        kind, _, where = group.partition(':')
        if kind == 'offset':
            if where not in joints:
                raise ValueError(f'correction group {group}: no joint {where!r} in '
                                 f'{tree.source}')
            joint = joints[where]
            joints[where] = _turned(joint, rot_axis(joint.axis, math.radians(values[0])),
                                    before=False)
        elif kind == 'bend':
            if where not in on_path:
                raise ValueError(f'correction group {group}: link {where!r} has no chain '
                                 f'joint after it in {tree.source}')
            name = on_path[where]
            w = np.radians(np.asarray(values, dtype=float))
            joints[name] = _turned(joints[name], rotation_vectors(w[None])[0], before=True)
    parents = {j.child: j for j in joints.values()}
    return replace(tree, joints=joints, parent_joint=parents)


def corrected_arm(profile, correction: ArmCorrection) -> ArmChain:
    """
    Return the engine's ArmChain of ``profile``'s arm with ``correction`` applied.

    The chain is the profile arm's reduced chain (held and expansion joints at 0, as
    :func:`~.profile_robot.robot_from_profile` compiles it), in millimetres.
    """
    side = correction.side
    if side not in profile.arms:
        raise ValueError(f'correction of the {side} arm: profile {profile.source} has no '
                         f'such arm')
    arm = profile.arms[side]
    path = profile.tree.path(arm.chain.base, arm.chain.tip)
    tree = corrected_tree(profile.tree, path, correction)
    where = f'profile {profile.source}, arms.{side} (corrected)'
    chain = compile_chain(tree, arm.chain.base, arm.chain.tip, arm.marks, MM_PER_M,
                          where=where, locked=arm.held + arm.expansion)
    for group, values in zip(correction.groups, correction.params):
        if group == 'tip_offset':
            chain = _moved_tip(chain, np.asarray(values, dtype=float))
    first = profile.tree.joints[chain.joint_names[0]].child
    origin = chain.link_frames(np.zeros(chain.n_joints), [first])[first][0][0]
    return ArmChain(side, chain, np.array(origin, dtype=float))


def _moved_tip(chain, offset_mm):
    """Return a copy of ``chain`` whose fingertip moved by ``offset_mm`` in the tip link."""
    import copy
    state, const = chain.frame_states()[chain.tip]
    tip = chain.landmarks['tip']
    if tip.state != state:
        raise ValueError(f'chain {chain.base} -> {chain.tip}: the fingertip does not move '
                         f'with the tip link; a tip offset cannot be applied')
    moved = copy.copy(chain)
    moved.landmarks = dict(chain.landmarks)
    pos = np.asarray(tip.pos, dtype=float) + const[:3, :3] @ offset_mm
    moved.landmarks['tip'] = replace(tip, pos=tuple(float(v) for v in pos))
    return moved


def check_matches(robot, profile, side: str, samples: int = 8) -> None:
    """
    Raise ValueError unless ``profile``'s nominal ``side`` arm is ``robot``'s own.

    Same joints in the same order, and the same elbow, wrist and fingertip within
    ``MATCH_MM`` at the zero pose and at ``samples`` poses spread over the limits.
    """
    from .kinematics import batch_forward
    nominal = corrected_arm(profile, ArmCorrection(side))
    names = tuple(robot.arms[side].joint_names)
    if tuple(nominal.chain.joint_names) != names:
        raise ValueError(f'profile {profile.source}: the {side} arm moves '
                         f'{", ".join(nominal.chain.joint_names)}; the robot '
                         f'{", ".join(names)}')
    arm = robot.arms[side]
    frac = np.linspace(0.1, 0.9, samples)[:, None] * np.ones(len(names))[None]
    frac = (frac + np.arange(len(names))[None] * 0.37) % 1.0
    q = np.vstack([np.zeros(len(names)), arm.lower + frac * (arm.upper - arm.lower)])
    ours = nominal.forward(q)
    theirs = batch_forward(robot.with_corrections(()), q, side)
    worst = max(float(np.abs(a - b).max()) for a, b in
                zip(ours[:3], theirs[:3]))
    if worst > MATCH_MM:
        raise ValueError(f'profile {profile.source}: its {side} arm is not the robot '
                         f"{robot.name}'s ({worst:.3g} mm apart); a correction fitted on "
                         'it does not apply')
