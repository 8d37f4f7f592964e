"""
Batched forward kinematics of Namo's arms (modified DH), free of ROS.

Every function takes joint angles of shape ``(..., 7)`` in radians and evaluates all
leading configurations in one vectorised pass: there is no Python loop over them, only
over the 7 links of the chain.  Positions are in millimetres in the robot's base frame.
"""

from typing import NamedTuple

import numpy as np

from .robot_model import ARMS, N_JOINTS


class ArmLandmarks(NamedTuple):
    """Landmarks of one arm for a batch of configurations."""

    elbow: np.ndarray   # (..., 3) mm, origin of the elbow frame
    wrist: np.ndarray   # (..., 3) mm, origin of the wrist frame
    tip: np.ndarray     # (..., 3) mm, fingertip (end-effector frame origin)
    palm: np.ndarray    # (..., 3, 3) rotation of frame 7 (palm orientation)


def as_joint_array(q, name='q'):
    """Return ``q`` as a float array of shape (..., 7), or raise ValueError naming it."""
    arr = np.asarray(q, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] != N_JOINTS:
        raise ValueError(f'{name}: expected joint angles of shape (..., {N_JOINTS}), '
                         f'got shape {arr.shape}')
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f'{name}: joint angles must be finite, got {arr[tuple(bad)]!r} '
                         f'at index {tuple(int(i) for i in bad)}')
    return arr


def _chain(robot, q):
    """Run the right-arm chain on q of shape (N, 7); return landmarks of shape (N, ...)."""
    n = q.shape[0]
    ca = np.cos(robot.alpha_prev)
    sa = np.sin(robot.alpha_prev)
    # Columns of the accumulated rotation, each (N, 3); position (N, 3).
    x_col = np.zeros((n, 3))
    x_col[:, 0] = 1.0
    y_col = np.zeros((n, 3))
    y_col[:, 1] = 1.0
    z_col = np.zeros((n, 3))
    z_col[:, 2] = 1.0
    pos = np.zeros((n, 3))
    theta = q + robot.theta_offset
    cos_t = np.cos(theta)[:, :, None]
    sin_t = np.sin(theta)[:, :, None]
    elbow = wrist = None
    for i in range(N_JOINTS):
        # R_new = R . RotX(alpha) . RotZ(theta); p_new = p + R . (a, -sa d, ca d).
        pos = pos + robot.a_prev[i] * x_col
        y_rot = ca[i] * y_col + sa[i] * z_col
        z_col = ca[i] * z_col - sa[i] * y_col
        c, s = cos_t[:, i], sin_t[:, i]
        x_col, y_col = c * x_col + s * y_rot, c * y_rot - s * x_col
        pos = pos + robot.d[i] * z_col
        if i + 1 == robot.elbow_frame:
            elbow = pos
        if i + 1 == robot.wrist_frame:
            wrist = pos
    palm = np.stack((x_col, y_col, z_col), axis=-1)
    th_e, d_e, a_e, al_e = robot.end_effector
    # The end-effector frame only moves the origin: tip = p7 + R7 . (a, -sa d, ca d).
    z_e = np.cos(al_e) * z_col - np.sin(al_e) * y_col
    tip = pos + a_e * x_col + d_e * z_e
    del th_e  # a constant rotation about z does not move the tip
    return elbow, wrist, tip, palm


def mirror_landmarks(lm):
    """Mirror landmarks in the x-z plane (negate y; R -> M R M with M = diag(1, -1, 1))."""
    flip = np.array([1.0, -1.0, 1.0])
    return ArmLandmarks(lm.elbow * flip, lm.wrist * flip, lm.tip * flip,
                        lm.palm * flip[:, None] * flip[None, :])


def forward_kinematics(robot, q, arm='right'):
    """
    Return the elbow, wrist, fingertip and palm rotation of ``arm`` for angles ``q``.

    ``q`` has shape (..., 7) in radians; each output has the same leading shape.  The
    left arm is the mirror image of the right one, so the same angles give the mirrored
    pose.
    """
    if arm not in ARMS:
        raise ValueError(f'arm: expected one of {ARMS}, got {arm!r}')
    q = as_joint_array(q)
    lead = q.shape[:-1]
    elbow, wrist, tip, palm = _chain(robot, q.reshape(-1, N_JOINTS))
    lm = ArmLandmarks(elbow.reshape(lead + (3,)), wrist.reshape(lead + (3,)),
                      tip.reshape(lead + (3,)), palm.reshape(lead + (3, 3)))
    if robot.arms[arm].mirrored:
        lm = mirror_landmarks(lm)
    return lm


def shoulder_position(robot, arm='right'):
    """Return the shoulder position (mm): the origin of frame 1, which does not move."""
    y = -np.sin(robot.alpha_prev[0]) * robot.d[0]
    pos = np.array([robot.a_prev[0], y, np.cos(robot.alpha_prev[0]) * robot.d[0]])
    if robot.arms[arm].mirrored:
        pos[1] = -pos[1]
    return pos
