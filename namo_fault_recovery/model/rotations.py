"""
Rotation matrices, one definition for every part of the package that builds them.

Users: the URDF writer and the chain compiler build the same fixed transforms
(``RotX(alpha) RotZ(theta)``) from a URDF or a DH table; the compiler turns a URDF joint
axis onto z; the simulator's structure changes turn a bent link about an axis; the
exploration's corrections turn rotation vectors into matrices in batches.  One
definition keeps their conventions from drifting apart.  :func:`cos_sin` gives both
forward kinematics (the DH table's and the URDF chains') the joint turns' cosines and sines.
"""

import math

import numpy as np


HALF_ANGLE_FROM = 128      # elements: from here on, cos_sin takes the half angle


def cos_sin(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return ``(cos(theta), sin(theta))`` elementwise, from one tangent of the half angle.

    ``t = tan(theta / 2)`` gives ``cos = (1 - t^2) / (1 + t^2)`` and ``sin = 2 t / (1 +
    t^2)``: one transcendental function instead of two, and numpy's float64 ``tan`` is
    vectorised where ``cos`` and ``sin`` are not (7,000 angles, Namo's two-arm batch of
    1,000: 23 us against about 230 us for the two calls).  Within 2.3e-16 of ``np.cos``
    / ``np.sin`` (test_rotations), also at the half angle's pole, where ``t`` is large
    but finite.  Below :data:`HALF_ANGLE_FROM` elements (the search's small batches) the
    two calls are the cheaper: 1.3 us for 35 angles, where the half angle takes 5 us
    (for 700: 23 us against 5 us).
    """
    theta = np.asarray(theta)
    if theta.size < HALF_ANGLE_FROM:
        return np.cos(theta), np.sin(theta)
    t = np.tan(0.5 * theta)
    t2 = t * t
    inv = 1.0 / (1.0 + t2)
    return (1.0 - t2) * inv, (t + t) * inv


def rot_x_cs(c: float, s: float) -> np.ndarray:
    """Return the 3x3 rotation about x whose cosine and sine are ``c`` and ``s``."""
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_x(angle: float) -> np.ndarray:
    """Return the 3x3 rotation by ``angle`` (rad) about x."""
    return rot_x_cs(math.cos(angle), math.sin(angle))


def rot_z(angle: float) -> np.ndarray:
    """Return the 3x3 rotation by ``angle`` (rad) about z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_vectors(w: np.ndarray) -> np.ndarray:
    """Return the rotations (N, 3, 3) of rotation vectors ``w`` (N, 3), rad (Rodrigues)."""
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=1)
    safe = np.where(theta > 1e-12, theta, 1.0)
    k = w / safe[:, None]
    kx = np.zeros((len(w), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    kx[:, 1, 0], kx[:, 2, 0], kx[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, None, None], (1.0 - np.cos(theta))[:, None, None]
    return np.eye(3)[None] + s * kx + c * (kx @ kx)


def rot_axis(axis, angle: float) -> np.ndarray:
    """Return the 3x3 rotation by ``angle`` (rad) about the unit vector ``axis``."""
    return rotation_vectors(np.asarray(axis, dtype=float)[None] * float(angle))[0]
