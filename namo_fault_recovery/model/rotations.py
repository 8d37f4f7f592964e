"""
Elementary rotation matrices, shared by the DH-to-URDF writer and the chain compiler.

Both build the same fixed transforms (``RotX(alpha) RotZ(theta)``) from a URDF or a DH
table; one definition keeps their conventions from drifting apart.
"""

import math

import numpy as np


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
