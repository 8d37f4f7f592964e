"""The torso's signed distance field (model.torso_field) on a shape of known distances."""

from namo_fault_recovery.model.torso_field import fit_field, surface_points
import numpy as np
import pytest

HALF = np.array([100.0, 50.0, 150.0])       # mm: a 200 x 100 x 300 mm box torso


@pytest.fixture(scope='module')
def box_surface():
    trimesh = pytest.importorskip('trimesh')
    return surface_points(trimesh.creation.box(extents=2 * HALF / 1000.0)) * 1000.0


def _box_distance(points):
    excess = np.abs(points) - HALF
    outside = np.linalg.norm(np.maximum(excess, 0.0), axis=-1)
    return np.where(outside > 0, outside, np.max(excess, axis=-1))


def test_the_field_is_the_signed_distance_to_the_box(box_surface):
    field = fit_field(box_surface, [], 5.0, ((0, 0, 150), (0, 0, -150)))
    assert field.eroded == 0.0
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (2000, 3)) * (HALF + 100.0)     # within the grid
    dist, grad = field.lookup(points)
    truth = _box_distance(points)
    assert np.abs(dist - truth).max() < 15.0                   # the 10 mm grid
    assert np.median(np.abs(dist - truth)) < 6.0
    assert field.lookup(np.zeros((1, 3)))[0][0] < -40.0        # inside: negative
    front = field.lookup(np.array([[180.0, 0.0, 0.0]]))
    assert front[0][0] == pytest.approx(80.0, abs=6.0)
    assert front[1][0] @ np.array([1.0, 0.0, 0.0]) > 0.9       # grows outwards
    step = np.eye(3) * 0.5
    p = np.array([130.0, 20.0, -40.0])
    numeric = [(field.lookup(p + e)[0] - field.lookup(p - e)[0]) for e in step]
    assert np.allclose(field.lookup(p)[1], numeric, atol=1e-6)


def test_the_field_is_eroded_until_the_resting_segments_clear_it(box_surface):
    # A forearm hanging 30 mm beside the box with a 40 mm radius: 15 mm too close.
    forearm = ((0.0, HALF[1] + 30.0, 100.0), (0.0, HALF[1] + 30.0, -100.0), 40.0)
    field = fit_field(box_surface, [forearm], 5.0, ((0, 0, 150), (0, 0, -150)))
    assert field.eroded == pytest.approx(15.0, abs=6.0)
    line = np.linspace(forearm[0], forearm[1], 20)
    assert field.lookup(line)[0].min() >= 45.0 - 1e-6
    assert field.reach >= np.linalg.norm(HALF[:2]) - field.eroded
