"""The shared rotation matrices (model/rotations.py) against scipy's Rotation."""

import math

from namo_fault_recovery.model.rotations import rot_axis, rot_x, rot_z, rotation_vectors
import numpy as np
from scipy.spatial.transform import Rotation


def test_rotation_vectors_match_scipy_in_a_batch_and_zero_is_the_identity():
    rng = np.random.default_rng(3)
    w = rng.normal(size=(50, 3)) * rng.uniform(0.0, 3.0, size=(50, 1))
    w[0] = 0.0                                   # no rotation at all
    w[1] = [1e-14, 0.0, 0.0]                     # below the threshold of the unit axis
    got = rotation_vectors(w)
    assert got.shape == (50, 3, 3)
    assert np.abs(got - Rotation.from_rotvec(w).as_matrix()).max() < 1e-12
    assert np.array_equal(got[0], np.eye(3))


def test_rot_axis_is_the_elementary_rotation_about_x_and_z():
    for angle in (-2.5, -0.3, 0.0, 0.7, math.pi):
        assert np.abs(rot_axis([1.0, 0.0, 0.0], angle) - rot_x(angle)).max() < 1e-15
        assert np.abs(rot_axis([0.0, 0.0, 1.0], angle) - rot_z(angle)).max() < 1e-15
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    turned = rot_axis(axis, 1.1)
    assert np.allclose(turned @ axis, axis)      # the axis stays
    assert np.allclose(turned @ turned.T, np.eye(3)) and np.linalg.det(turned) > 0.0
