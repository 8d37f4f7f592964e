"""
A robot's torso as a signed distance field, from its URDF collision geometry (ROS-free).

The torso capsule of :mod:`.robot_capsules` is capped so that the arms hang clear of it
at rest, and a torso is rarely round: on Talos and TIAGo++ the capped capsule leaves the
chest in front of it uncovered, and with a faulted left elbow the engine published the
idle left hand inside the chest's mesh (``namo-recovery bench meshes``).  Here the
torso links' collision geometry, sampled on its surface at the zero pose, is voxelised
(``SPACING_MM``), its inside filled, and turned into a signed distance (mm, positive
outside) by Euclidean distance transforms (scipy): the shape the URDF declares, at the
grid's resolution.  The field is then eroded by as much as it takes for the forearms and
hands at rest to clear it by ``REST_CLEARANCE_MM`` (their capsules are rounder than the
links; the upper arms hang from shoulders on the torso and meet the capsule only, see
:func:`.self_contact.closest_pairs`).  :meth:`TorsoField.lookup` interpolates it
trilinearly, with its gradient, for many points at once.
"""

from dataclasses import dataclass

import numpy as np

SPACING_MM = 10.0       # grid spacing
MARGIN_MM = 150.0       # grid beyond the torso's points, each way
SURFACE_SAMPLES_MM = 4.0    # about one surface sample per this many mm, each way


@dataclass(frozen=True, eq=False)
class TorsoField:
    """Signed distances (mm, > 0 outside) on a regular grid in the arms' base frame."""

    origin: np.ndarray      # (3,) mm: the centre of cell (0, 0, 0)
    spacing: float          # mm
    values: np.ndarray      # (nx, ny, nz) mm
    eroded: float = 0.0     # mm taken off the torso so that the arms at rest clear it
    reach: float = np.inf   # mm: no point inside is farther than this from ``axis``
    axis: tuple = ()        # the torso capsule's axis (top, bottom) mm, for ``reach``
    box: tuple = ()         # (lowest, highest) corners (3,) mm of the inside's cells

    def lookup(self, points):
        """Return the distance (...,) mm at ``points`` (..., 3) mm and its gradient (..., 3)."""
        values = self.values
        nx, ny, nz = values.shape
        u = (np.asarray(points, dtype=float) - self.origin) * (1.0 / self.spacing)
        u = np.clip(u, 0.0, np.array([nx, ny, nz]) - 1.000001)
        i = u.astype(np.intp)
        f = u - i
        base = (i[..., 0] * ny + i[..., 1]) * nz + i[..., 2]
        flat = values.reshape(-1)
        c = {(a, b, e): np.take(flat, base + (a * ny + b) * nz + e)
             for a in (0, 1) for b in (0, 1) for e in (0, 1)}
        fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]
        x00 = c[0, 0, 0] + fx * (c[1, 0, 0] - c[0, 0, 0])
        x01 = c[0, 0, 1] + fx * (c[1, 0, 1] - c[0, 0, 1])
        x10 = c[0, 1, 0] + fx * (c[1, 1, 0] - c[0, 1, 0])
        x11 = c[0, 1, 1] + fx * (c[1, 1, 1] - c[0, 1, 1])
        y0 = x00 + fy * (x10 - x00)
        y1 = x01 + fy * (x11 - x01)
        dist = y0 + fz * (y1 - y0)
        gy = (1.0 - fz) * (x10 - x00) + fz * (x11 - x01)
        gx0 = (1.0 - fy) * (c[1, 0, 0] - c[0, 0, 0]) + fy * (c[1, 1, 0] - c[0, 1, 0])
        gx1 = (1.0 - fy) * (c[1, 0, 1] - c[0, 0, 1]) + fy * (c[1, 1, 1] - c[0, 1, 1])
        gx = (1.0 - fz) * gx0 + fz * gx1
        grad = np.stack((gx, gy, y1 - y0), axis=-1) * (1.0 / self.spacing)
        return dist, grad


def fit_field(surface, rest_segments, clearance, axis):
    """
    Return the TorsoField of torso surface points, eroded to clear the arms at rest.

    ``surface`` (K, 3) mm: points on the torso's collision surface at the zero pose.
    ``rest_segments``: ``[(start (3,), end (3,), radius mm)]`` of the forearms and hands
    at rest, which must clear the field by ``clearance`` mm.  ``axis`` (top, bottom) is
    the torso capsule's: the field records how far from it its inside reaches, so that
    a segment farther than that from the axis needs no look-up.
    """
    from scipy import ndimage
    lo = surface.min(axis=0) - MARGIN_MM
    hi = surface.max(axis=0) + MARGIN_MM
    shape = np.ceil((hi - lo) / SPACING_MM).astype(int) + 1
    cells = np.round((surface - lo) / SPACING_MM).astype(int)
    occupied = np.zeros(shape, dtype=bool)
    occupied[tuple(cells.T)] = True
    occupied = ndimage.binary_closing(occupied, structure=np.ones((3, 3, 3), dtype=bool),
                                      iterations=2)
    occupied = ndimage.binary_fill_holes(occupied)
    outside = ndimage.distance_transform_edt(~occupied) * SPACING_MM
    inside = ndimage.distance_transform_edt(occupied) * SPACING_MM
    values = (outside - inside).astype(float)
    field = TorsoField(lo, SPACING_MM, values)
    frac = np.linspace(0.0, 1.0, 33)[:, None]
    need = 0.0
    for start, end, radius in rest_segments:
        start, end = np.asarray(start, float), np.asarray(end, float)
        dist, _ = field.lookup(start + frac * (end - start))
        need = max(need, float(np.max(radius + clearance - dist)))
    values = values + need
    inside = np.argwhere(values <= 0.0) * SPACING_MM + lo
    top, bottom = (np.asarray(a, dtype=float) for a in axis)
    reach = 0.0
    if len(inside):
        from .self_contact import segment_distance
        reach = float(segment_distance(inside, inside, np.broadcast_to(top, inside.shape),
                                       np.broadcast_to(bottom, inside.shape))[0].max())
    box = ((inside.min(axis=0) - SPACING_MM, inside.max(axis=0) + SPACING_MM) if len(inside)
           else (np.zeros(3), np.zeros(3)))
    return TorsoField(lo, SPACING_MM, values, max(need, 0.0), reach + SPACING_MM,
                      (tuple(top), tuple(bottom)), box)


def surface_points(mesh_like, spacing_mm=SURFACE_SAMPLES_MM, seed=0):
    """Return points (K, 3), a trimesh's units, over its surface (about one per spacing)."""
    import trimesh
    area = float(mesh_like.area)
    count = int(min(200000, max(200, area / (spacing_mm * 1e-3) ** 2)))
    points, _ = trimesh.sample.sample_surface(mesh_like, count, seed=seed)
    return np.vstack((np.asarray(points, dtype=float), np.asarray(mesh_like.vertices)))
