"""
Batched forward kinematics of Namo's arms (modified DH), free of ROS.

Every function takes joint angles of shape ``(..., n)`` in radians (n joints per arm: 7
on Namo) and evaluates all leading configurations in one vectorised pass: there is no
Python loop over them, only over the links of the chain.  Positions are in millimetres
in the robot's base frame.
"""

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from .robot import ARMS, N_JOINTS, RobotModel
from .rotations import cos_sin


# DH table bytes -> link constants.  Keyed by the table, not the robot object: the engine
# makes a new robot per run (a tool, learned corrections), and an entry per object grew
# without end in a long-running node.
_PLANS = {}


class ArmLandmarks(NamedTuple):
    """Landmarks of one arm for a batch of configurations."""

    elbow: np.ndarray   # (..., 3) mm, origin of the elbow frame
    wrist: np.ndarray   # (..., 3) mm, origin of the wrist frame
    tip: np.ndarray     # (..., 3) mm, fingertip (end-effector frame origin)
    palm: np.ndarray    # (..., 3, 3) rotation of frame 7 (palm orientation)


def arm_joint_count(robot, side: str = 'right') -> int:
    """Return the number of joints of one arm: 7 on Namo, the profile's on a URDF robot."""
    chains = getattr(robot, 'chains', None)
    return N_JOINTS if chains is None else len(robot.arms[side].joint_names)


def arm_columns(robot) -> dict:
    """
    Return ``{side: slice}``: each arm's columns in whole-robot angles, right arm first.

    The arms may differ in joint count (a 7-joint right arm and a 6-joint left one): the
    right arm's ``n_r`` columns come first, then the left arm's, as in
    :attr:`~.robot.RobotJoints.joint_names`.
    """
    n_right = arm_joint_count(robot, 'right')
    return {'right': slice(0, n_right),
            'left': slice(n_right, n_right + arm_joint_count(robot, 'left'))}


def split_arms(robot, q) -> tuple:
    """
    Return the (right, left) columns of whole-robot angles ``q`` (..., J), right arm first.

    ``J`` is the robot's joint count (14 on Namo; :func:`arm_columns`); both are views of
    ``q`` as an array.
    """
    q = np.asarray(q, dtype=float)
    cols = arm_columns(robot)
    total = cols['left'].stop
    if q.ndim == 0 or q.shape[-1] != total:
        raise ValueError(f"expected both arms' angles, shape (..., {total}), got {q.shape}")
    return q[..., cols['right']], q[..., cols['left']]


def as_joint_array(q, name='q', n_joints=N_JOINTS):
    """Return ``q`` as a float array of shape (..., n_joints), or raise ValueError naming it."""
    arr = np.asarray(q, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] != n_joints:
        raise ValueError(f'{name}: expected joint angles of shape (..., {n_joints}), '
                         f'got shape {arr.shape}')
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f'{name}: joint angles must be finite, got {arr[tuple(bad)]!r} '
                         f'at index {tuple(int(i) for i in bad)}')
    return arr


def angle_bytes(arrays) -> bytes:
    """Return the bytes of some float arrays, one key for a dict (exact values, in order)."""
    return b''.join(np.asarray(a, dtype=float).tobytes() for a in arrays)


def _link_plan(robot):
    """Per-link constants, with exact 0/+-1 for the common right-angle twists."""
    key = angle_bytes((robot.a_prev, robot.d, robot.alpha_prev))
    cached = _PLANS.get(key)
    if cached is not None:
        return cached
    plan = []
    for i in range(N_JOINTS):
        ca, sa = np.cos(robot.alpha_prev[i]), np.sin(robot.alpha_prev[i])
        ca = 0.0 if abs(ca) < 1e-12 else ca
        sa = 0.0 if abs(sa) < 1e-12 else sa
        plan.append((float(robot.a_prev[i]), float(robot.d[i]), ca, sa))
    _PLANS[key] = plan
    return plan


def _chain(robot, q, axes=None, origins=None, tool=0.0):
    """
    Run the right-arm chain on q of shape (N, 7); return landmarks of shape (N, ...).

    If ``axes``/``origins`` (N, 7, 3) are given, each joint's rotation axis (the z axis
    of its frame) and a point on it (the frame origin) are written there.  ``tool`` (mm)
    lengthens the hand: the fingertip becomes the tip of the tool.
    """
    n = q.shape[0]
    # Columns of the accumulated rotation, each (N, 3); position (N, 3).
    eye = np.zeros((3, n, 3))
    eye[0, :, 0] = eye[1, :, 1] = eye[2, :, 2] = 1.0
    x_col, y_col, z_col = eye
    pos = np.zeros((n, 3))
    theta = (q + robot.theta_offset).T
    cos_t, sin_t = (a[:, :, None] for a in cos_sin(theta))
    elbow = wrist = None
    for i, (a, d, ca, sa) in enumerate(_link_plan(robot)):
        # R_new = R . RotX(alpha) . RotZ(theta); p_new = p + R . (a, -sa d, ca d).
        if a:
            pos = pos + a * x_col
        if ca == 0.0:
            y_rot, z_col = sa * z_col, -sa * y_col
        elif sa == 0.0:
            y_rot, z_col = ca * y_col, ca * z_col
        else:
            y_rot, z_col = ca * y_col + sa * z_col, ca * z_col - sa * y_col
        c, s = cos_t[i], sin_t[i]
        x_col, y_col = c * x_col + s * y_rot, c * y_rot - s * x_col
        if d:
            pos = pos + d * z_col
        if axes is not None:
            axes[:, i] = z_col
            origins[:, i] = pos
        if i + 1 == robot.elbow_frame:
            elbow = pos
        if i + 1 == robot.wrist_frame:
            wrist = pos
    palm = np.stack((x_col, y_col, z_col), axis=-1)
    _, d_e, a_e, al_e = robot.end_effector
    # The end-effector frame only moves the origin: tip = p7 + R7 . (a, -sa d, ca d);
    # its constant rotation about z does not move the tip.  A tool lengthens that offset
    # along its own direction.
    if tool:
        scale = 1.0 + tool / float(np.hypot(a_e, d_e))
        a_e, d_e = a_e * scale, d_e * scale
    tip = pos + a_e * x_col + d_e * (np.cos(al_e) * z_col - np.sin(al_e) * y_col)
    return elbow, wrist, tip, palm


def take_landmarks(lm, index):
    """Return the landmarks of the configurations selected by ``index``."""
    return ArmLandmarks(*(a[index] for a in lm))


def mirror_landmarks(lm):
    """Mirror landmarks in the x-z plane (negate y; R -> M R M with M = diag(1, -1, 1))."""
    flip = np.array([1.0, -1.0, 1.0])
    return ArmLandmarks(lm.elbow * flip, lm.wrist * flip, lm.tip * flip,
                        lm.palm * flip[:, None] * flip[None, :])


def forward_kinematics(robot: RobotModel, q: ArrayLike, arm: str = 'right') -> ArmLandmarks:
    """
    Return the elbow, wrist, fingertip and palm rotation of ``arm`` for angles ``q``.

    ``q`` has shape (..., n) in radians, n the arm's joints (7 on Namo); each output has
    the same leading shape.  On Namo the left arm is the mirror image of the right one,
    so the same angles give the mirrored pose.
    """
    if arm not in ARMS:
        raise ValueError(f'arm: expected one of {ARMS}, got {arm!r}')
    q = as_joint_array(q, n_joints=arm_joint_count(robot, arm))
    return batch_forward(robot, q, arm)


def batch_forward(robot, q, arm):
    """Forward kinematics without input checks, for callers that already validated q."""
    corrected = robot.corrected_arm(arm)
    if corrected is not None:     # a correction learned on the robot (structure.py)
        return corrected.forward(q, robot.tool_length(arm))
    chains = getattr(robot, 'chains', None)
    if chains is not None:        # a robot from a URDF profile: its compiled chain
        return chains[arm].forward(q, robot.tool_length(arm))
    lead = q.shape[:-1]
    elbow, wrist, tip, palm = _chain(robot, q.reshape(-1, N_JOINTS),
                                     tool=robot.tool_length(arm))
    lm = ArmLandmarks(elbow.reshape(lead + (3,)), wrist.reshape(lead + (3,)),
                      tip.reshape(lead + (3,)), palm.reshape(lead + (3, 3)))
    if robot.arms[arm].mirrored:
        lm = mirror_landmarks(lm)
    return lm


def shoulder_position(robot, arm='right'):
    """Return the shoulder position (mm): the origin of frame 1, which does not move."""
    chains = getattr(robot, 'chains', None)
    if chains is not None:
        return chains[arm].shoulder.copy()
    y = -np.sin(robot.alpha_prev[0]) * robot.d[0]
    pos = np.array([robot.a_prev[0], y, np.cos(robot.alpha_prev[0]) * robot.d[0]])
    if robot.arms[arm].mirrored:
        pos[1] = -pos[1]
    return pos


class ArmJacobian(NamedTuple):
    """Derivatives of one arm's landmarks with respect to its n joint angles."""

    positions: np.ndarray   # (N, 3, n, 3): d(elbow, wrist, tip) / dq_i
    axes: np.ndarray        # (N, n, 3): angular velocity of the palm per unit dq_i


def forward_kinematics_jacobian(robot, q, arm='right'):
    """
    Return ``(landmarks, jacobian)`` for angles q (N, n) in one vectorised pass.

    For a revolute joint i with axis z_i through o_i, a point p downstream moves as
    ``z_i x (p - o_i)`` and the palm rotates about z_i.  For the mirrored left arm the
    axes become ``-M z_i`` (a reflection reverses the sense of rotation).
    """
    q = np.atleast_2d(as_joint_array(q, n_joints=arm_joint_count(robot, arm)))
    return batch_forward_jacobian(robot, q, arm)


def batch_forward_jacobian(robot, q, arm):
    """:func:`forward_kinematics_jacobian` without input checks, on q of shape (N, 7)."""
    corrected = robot.corrected_arm(arm)
    if corrected is not None:
        return corrected.jacobian(q, robot.tool_length(arm))
    chains = getattr(robot, 'chains', None)
    if chains is not None:
        return chains[arm].jacobian(q, robot.tool_length(arm))
    n = q.shape[0]
    axes = np.empty((n, N_JOINTS, 3))
    origins = np.empty((n, N_JOINTS, 3))
    lm = ArmLandmarks(*_chain(robot, q, axes, origins, robot.tool_length(arm)))
    pts = np.stack((lm.elbow, lm.wrist, lm.tip), axis=1)            # (N, 3, 3)
    arm_vec = pts[:, :, None, :] - origins[:, None, :, :]              # (N, 3, 7, 3)
    ax = axes[:, None]
    jac = np.empty_like(arm_vec)    # z_i x (p - o_i), written out: np.cross is slower here
    jac[..., 0] = ax[..., 1] * arm_vec[..., 2] - ax[..., 2] * arm_vec[..., 1]
    jac[..., 1] = ax[..., 2] * arm_vec[..., 0] - ax[..., 0] * arm_vec[..., 2]
    jac[..., 2] = ax[..., 0] * arm_vec[..., 1] - ax[..., 1] * arm_vec[..., 0]
    reach = np.array([robot.elbow_frame, robot.wrist_frame, N_JOINTS])
    jac[:, np.arange(N_JOINTS)[None, :] >= reach[:, None]] = 0.0     # upstream joints only
    if robot.arms[arm].mirrored:
        flip = np.array([1.0, -1.0, 1.0])
        lm = mirror_landmarks(lm)
        jac = jac * flip
        axes = -axes * flip
    return lm, ArmJacobian(jac, axes)


# Twin joint triples: see equivalent_twins.  Keyed by the arm's landmarks at the probe
# configurations (what the answer depends on), so that the robot made anew for each run
# finds it again; at most FLIP_CACHE entries.
_FLIPS = {}
FLIP_CACHE = 64
FLIP_TOLERANCE = 1e-6    # mm and rotation-matrix entries: "the same landmarks"
FLIP_PROBES = 8          # random configurations on which a flip must hold
TWIN_MIRRORS = (0.0, np.pi)   # the middle joint's reading in a twin: mirror - b


def equivalent_twins(robot, side: str) -> tuple:
    """
    Return the joint triples ``(i, i+1, i+2, mirror)`` of one arm that twin every landmark.

    Three joints whose axes meet in one point, the middle one square to the outer two,
    reach every orientation twice: turning the outer joints by half a turn and reading
    the middle one as ``mirror - b`` gives the same hand and the same links beyond.
    ``mirror`` is 0 where the outer axes are parallel (roll-pitch-roll, ``Rz(a) Ry(b)
    Rz(c) = Rz(a + pi) Ry(-b) Rz(c + pi)``: a spherical wrist, Namo's upper arm, elbow
    and forearm) and pi where they are square (roll-pitch-yaw, ``Rz(a) Ry(b) Rx(c) =
    Rz(a + pi) Ry(pi - b) Rx(c + pi)``: Namo's shoulder and wrist, Talos's wrist).  The
    triples are found numerically, on this robot's own forward kinematics (every
    landmark, the palm's orientation included, within ``FLIP_TOLERANCE`` at random
    configurations), so any chain is covered, whatever its convention: Namo (0, 1, 2,
    pi), (2, 3, 4, 0) and (4, 5, 6, pi); TIAGo++ (4, 5, 6, 0); Talos (4, 5, 6, pi).
    Cached by the arm's landmarks at the probes (one forward kinematics call per lookup).
    """
    n = arm_joint_count(robot, side)
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, size=(FLIP_PROBES, n))
    base = batch_forward(robot, q, side)
    key = b''.join(np.round(a, 9).tobytes() for a in base)
    hit = _FLIPS.get(key)
    if hit is not None:
        return hit
    found = []
    for i in range(n - 2):
        for mirror in TWIN_MIRRORS:
            twin = q.copy()
            twin[:, i] += np.pi
            twin[:, i + 1] = mirror - twin[:, i + 1]
            twin[:, i + 2] += np.pi
            moved = batch_forward(robot, twin, side)
            if all(np.max(np.abs(a - b)) <= FLIP_TOLERANCE for a, b in zip(base, moved)):
                found.append((i, i + 1, i + 2, mirror))
    if len(_FLIPS) >= FLIP_CACHE:
        _FLIPS.pop(next(iter(_FLIPS)))
    _FLIPS[key] = tuple(found)
    return tuple(found)


def equivalent_flips(robot, side: str) -> tuple:
    """
    Return the roll-pitch-roll triples ``(i, i+1, i+2)`` of one arm (twins of mirror 0).

    The two readings of such a group differ in their joint limits, and a locked middle
    joint reads as ``-b`` through the flipped outer joints (TIAGo++'s salute with right
    joint 6 locked at +20 deg where the design has -22 deg: 4.4 through the flip, 27.4
    without it): the keyframe search starts from both
    (:func:`~..recovery.seeding.flip_starts`).  Namo (2, 3, 4), TIAGo++ (4, 5, 6), Talos
    none (see :func:`equivalent_twins`).
    """
    return tuple(t[:3] for t in equivalent_twins(robot, side) if t[3] == 0.0)
