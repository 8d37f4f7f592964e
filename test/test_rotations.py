"""The shared rotation matrices (model/rotations.py) against scipy's Rotation."""

import math

from namo_fault_recovery.model.rotations import (cos_sin, HALF_ANGLE_FROM, rot_axis, rot_x,
                                                 rot_z, rotation_vectors)
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


def test_cos_sin_from_the_half_angle_matches_numpy_also_at_its_pole():
    rng = np.random.default_rng(5)
    poles = math.pi * np.arange(-6, 7)                # tan(theta / 2) at its largest
    theta = np.concatenate([rng.uniform(-12.0, 12.0, 200_000), poles, poles / 2,
                            np.nextafter(poles, 0.0), [0.0, -0.0, 1e-300]])
    c, s = cos_sin(theta)
    small_c, small_s = cos_sin(theta[:HALF_ANGLE_FROM - 1])      # np.cos and np.sin
    assert np.array_equal(small_c, np.cos(theta[:HALF_ANGLE_FROM - 1]))
    assert np.array_equal(small_s, np.sin(theta[:HALF_ANGLE_FROM - 1]))
    assert np.all(np.isfinite(c)) and np.all(np.isfinite(s))
    assert np.abs(c - np.cos(theta)).max() < 1e-15
    assert np.abs(s - np.sin(theta)).max() < 1e-15
    assert np.isnan(cos_sin(np.array([np.nan]))[0]).all()
