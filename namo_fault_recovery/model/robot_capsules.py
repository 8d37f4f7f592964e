"""
Self-collision capsules fitted to a robot's URDF collision geometry (ROS-free).

The collision term (:mod:`..objective.collision`, :mod:`.self_contact`) models each arm
as three capsules between its landmarks: upper arm (shoulder-elbow), forearm
(elbow-wrist) and hand (wrist-fingertip), and the torso as one more.  On Namo their
radii are the robot file's.  For a robot from a URDF profile, :func:`fit_capsules`
fits them to the URDF's ``<collision>`` geometry:

- the points of the arm's chain links go to the nearest of its three segments at the
  zero pose, except the first joint's link: the upper arm starts at that joint's
  origin, which does not move (the shoulder), and on a robot whose first joint is a
  mount beside the torso (Talos, TIAGo++) that link reaches out to the shoulder
  proper, which a capsule from the fixed shoulder cannot cover; the links above the
  first arm joint (on either arm's chain) are the torso;
- a link's geometry becomes surface points in its frame: a box's corners and face
  centres, a cylinder's rims, a sphere's six poles, a mesh's vertices (loaded with
  trimesh, ``package://`` names resolved upwards from the URDF's folder, then in the
  ``share`` folders of ``AMENT_PREFIX_PATH``);
- at the zero pose, a segment's radius is the :data:`COVER` quantile of its points'
  distances from its axis: a capsule that enclosed every point would be as wide as a
  gripper's open fingers.  A segment with no loadable geometry keeps the default
  radius of :class:`~.capsules.CapsuleModel` (stated in :attr:`FittedCapsules.notes`);
- the torso is a vertical capsule through its points' mean, its radius their
  :data:`COVER` quantile distance from that axis, capped so that both arms at the zero
  pose clear it by :data:`REST_CLEARANCE_MM` (a torso mesh often includes the shoulder
  mounts, which the upper arms touch by design: adjacent links are not a collision).

A profile's ``capsules`` key overrides fitted radii (mm); the torso radius given there
is still capped by the arms at rest.

Pairs: the checked pairs are :data:`.self_contact.PAIRS` (every segment against the
torso and every right-left pair; the segments of one arm are adjacent and never
checked); a two-handed gesture's reference defines its designed right-left contact
(Wai's palms), as on Namo.
"""

from dataclasses import dataclass
import io
import logging
import os
from pathlib import Path

import numpy as np

from .capsules import CapsuleModel
from .self_contact import segment_distance, SEGMENTS

COVER = 0.9                 # the share of a segment's surface points inside its capsule
REST_CLEARANCE_MM = 5.0     # the zero pose's arms clear the fitted torso by this much
_MAX_POINTS = 4000          # mesh vertices kept per link (evenly subsampled)


@dataclass(frozen=True)
class FittedCapsules:
    """The fitted capsules and, per segment, how each was made (for reports)."""

    capsules: CapsuleModel
    notes: tuple            # one line per segment: source of its points, or the default


def _resolve(filename, urdf_dir):
    """Return the local path of a mesh file name of a URDF, or None."""
    if filename.startswith('file://'):
        filename = filename[len('file://'):]
    if not filename.startswith('package://'):
        path = Path(filename)
        path = path if path.is_absolute() else Path(urdf_dir) / path
        return path if path.is_file() else None
    package, _, rest = filename[len('package://'):].partition('/')
    for parent in [Path(urdf_dir)] + list(Path(urdf_dir).parents):
        if parent.name == package and (parent / rest).is_file():
            return parent / rest
        if (parent / package / rest).is_file():
            return parent / package / rest
    for prefix in filter(None, os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)):
        found = Path(prefix) / 'share' / package / rest        # an installed ROS package
        if found.is_file():
            return found
    return None


def _load_mesh(mesh, urdf_dir):
    """Return a URDF mesh as a trimesh (m, its own frame, unscaled), or None if not loadable."""
    path = _resolve(mesh.filename, urdf_dir)
    if path is None:
        return None
    try:
        import trimesh
        logging.getLogger('trimesh').setLevel(logging.ERROR)
        return trimesh.load(str(path), force='mesh')
    except (ImportError, OSError, ValueError, AttributeError, IndexError, KeyError):
        return None


def _mesh_points(mesh, urdf_dir):
    """Return a mesh's vertices (m, in its own frame, scaled), or None if not loadable."""
    loaded = _load_mesh(mesh, urdf_dir)
    if loaded is None:
        return None
    points = np.asarray(loaded.vertices, dtype=float)
    if points.size == 0:
        return None
    step = max(1, len(points) // _MAX_POINTS)
    scale = np.asarray(mesh.scale if mesh.scale is not None else 1.0, dtype=float)
    return points[::step] * scale


def _primitive_points(geometry):
    """Return surface points (m) of a box, cylinder or sphere, or None for a mesh."""
    if geometry.box is not None:
        h = np.asarray(geometry.box.size, dtype=float) / 2.0
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        faces = np.vstack((np.eye(3), -np.eye(3)))
        return np.vstack((corners, faces)) * h
    if geometry.cylinder is not None:
        r, half = geometry.cylinder.radius, geometry.cylinder.length / 2.0
        ang = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
        rim = np.stack((r * np.cos(ang), r * np.sin(ang), np.zeros_like(ang)), axis=1)
        return np.vstack((rim + [0.0, 0.0, half], rim - [0.0, 0.0, half]))
    if geometry.sphere is not None:
        return np.vstack((np.eye(3), -np.eye(3))) * geometry.sphere.radius
    return None


def link_points(urdf, link_name, urdf_dir):
    """Return (points (K, 3) m in the link's frame, kinds) of a link's collision geometry."""
    link = urdf.link_map.get(link_name)
    out, kinds = [], []
    for col in (link.collisions if link is not None else ()):
        points = _primitive_points(col.geometry)
        kind = next((k for k in ('box', 'cylinder', 'sphere')
                     if getattr(col.geometry, k) is not None), 'mesh')
        if points is None and col.geometry.mesh is not None:
            points = _mesh_points(col.geometry.mesh, urdf_dir)
        if points is None:
            kinds.append(f'{kind} (not loadable)')
            continue
        origin = col.origin if col.origin is not None else np.eye(4)
        out.append(points @ origin[:3, :3].T + origin[:3, 3])
        kinds.append(kind)
    return (np.vstack(out) if out else np.zeros((0, 3))), kinds


def _load_urdf(source):
    import yourdfpy
    logging.getLogger('yourdfpy').setLevel(logging.CRITICAL)
    return yourdfpy.URDF.load(source if isinstance(source, io.BytesIO) else str(source),
                              build_scene_graph=False, load_meshes=False,
                              build_collision_scene_graph=False, load_collision_meshes=False)


def segment_links(robot, side) -> dict:
    """
    Return ``{segment or 'torso': [link, ...]}``: which of an arm's chain links each covers.

    A link goes to the segment of the landmarks it moves with (upper arm up to the elbow,
    forearm up to the wrist, hand beyond); the links above the first arm joint are the
    torso.  The first joint's own link (a mount beside the torso on Talos and TIAGo++,
    which the torso touches by design) is in no segment: see the module.
    """
    chain = robot.chains[side].chain
    marks = chain.landmarks
    bounds = (marks['elbow'].state, marks['wrist'].state)
    mount = robot.profile.tree.joints[chain.joint_names[0]].child
    groups = {name: [] for name in SEGMENTS + ('torso',)}
    for link, (state, _) in chain.frame_states().items():
        if state == 0:
            groups['torso'].append(link)
        elif link != mount:
            groups[SEGMENTS[int(state >= bounds[0]) + int(state >= bounds[1])]].append(link)
    return groups


def _points_at_zero(robot, side, links, urdf, urdf_dir, points_of=None):
    """
    Return the links' collision points at the zero pose (mm, base frame), and kinds.

    ``points_of(urdf, link, urdf_dir)`` gives a link's points (m, its frame) and kinds:
    :func:`link_points` by default.
    """
    chain = robot.chains[side].chain
    frames = chain.link_frames(np.zeros(chain.n_joints), links)
    pts, kinds = [], []
    for link in links:
        local, kind = (points_of or link_points)(urdf, link, urdf_dir)
        kinds += [f'{link}: {k}' for k in kind]
        if len(local):
            origin, rot = frames[link]
            pts.append(local * 1000.0 @ rot[0].T + origin[0])
    return (np.vstack(pts) if pts else np.zeros((0, 3))), kinds


def _assign(points, ends):
    """Return, per point, the index of its nearest arm segment and its distance (mm)."""
    d = np.stack([segment_distance(points, points, np.broadcast_to(ends[i], points.shape),
                                   np.broadcast_to(ends[i + 1], points.shape))[0]
                  for i in range(len(SEGMENTS))], axis=1)
    nearest = np.argmin(d, axis=1)
    return nearest, d[np.arange(len(points)), nearest]


def _fit_arm(robot, side, urdf, urdf_dir, notes):
    """Return ({segment: radius mm}, rest ends, torso points) of one arm."""
    from .kinematics import forward_kinematics, shoulder_position
    lm = forward_kinematics(robot, np.zeros(robot.chains[side].n_joints), side)
    ends = [shoulder_position(robot, side), lm.elbow, lm.wrist, lm.tip]
    groups = segment_links(robot, side)
    torso, _ = _points_at_zero(robot, side, groups['torso'], urdf, urdf_dir)
    links = [link for seg in SEGMENTS for link in groups[seg]]
    points, kinds = _points_at_zero(robot, side, links, urdf, urdf_dir)
    nearest, dist = (_assign(points, ends) if len(points)
                     else (np.zeros(0, dtype=int), np.zeros(0)))
    radii = {}
    for i, seg in enumerate(SEGMENTS):
        mine = dist[nearest == i]
        if not len(mine):
            notes.append(f'{side} {seg}: no loadable collision geometry near it; default '
                         f'radius {getattr(CapsuleModel(), seg):g} mm')
            continue
        radii[seg] = float(np.quantile(mine, COVER))
        notes.append(f'{side} {seg}: {radii[seg]:.1f} mm from {len(mine)} points')
    shapes = sorted({k.split(': ')[1] for k in kinds})
    notes.append(f'{side} arm: points of {", ".join(shapes) or "nothing"} on '
                 f'{len(links)} links ({", ".join(links)})')
    return radii, ends, torso


def fit_report(robot) -> FittedCapsules:
    """Fit the capsules of a profile robot (``robot.chains``) to its URDF's geometry."""
    profile = robot.profile
    if profile.urdf_text is not None:           # a robot_description document
        urdf, folder = _load_urdf(io.BytesIO(profile.urdf_text.encode())), profile.mesh_dir
    else:
        source = Path(profile.tree.source)
        urdf, folder = _load_urdf(source), source.parent
    default = CapsuleModel()
    radii, notes, torso_pts, rest = {}, [], [], {}
    for side in ('right', 'left'):
        arm, rest[side], torso = _fit_arm(robot, side, urdf, folder, notes)
        torso_pts.append(torso)
        for seg, r in arm.items():
            radii.setdefault(seg, []).append(r)
    values = {seg: max(r) for seg, r in radii.items()}
    for key, value in (robot.profile.capsules or {}).items():
        if key in SEGMENTS:
            notes.append(f'{key}: {value:g} mm from the profile (fitted '
                         f'{values.get(key, getattr(default, key)):.1f} mm)')
            values[key] = value
    given = (robot.profile.capsules or {}).get('torso_radius')
    known = {**vars(default), **values, **({} if given is None else {'torso_given': given})}
    torso, capped = _fit_torso(np.vstack(torso_pts), rest, known, notes)
    values.update(torso)
    if capped:      # the capsule leaves the torso uncovered: its own shape is checked too
        values['torso_field'] = _torso_shape(robot, urdf, folder, rest, known | values, notes)
    return FittedCapsules(CapsuleModel(**values), tuple(notes))


def _torso_axis(points, centre, radius):
    top = float(points[:, 2].max()) - radius
    bottom = float(points[:, 2].min()) + radius
    mid = (top + bottom) / 2.0
    top, bottom = max(top, mid), min(bottom, mid)
    return np.array([*centre, top]), np.array([*centre, bottom])


def _fit_torso(points, rest, radii, notes):
    """
    Return the torso keys of CapsuleModel fitted to ``points`` (mm), capped by the arms.

    And whether the cap took more than a millimetre off the fitted radius (then the
    capsule leaves part of the torso uncovered; a radius the profile gives is not).
    """
    if not len(points):
        notes.append('torso: no loadable collision geometry; no torso capsule (radius 0)')
        return {'torso_radius': 0.0}, False
    centre = points[:, :2].mean(axis=0)
    radial = np.linalg.norm(points[:, :2] - centre, axis=1)
    fitted = radius = float(radii.get('torso_given', np.quantile(radial, COVER)))
    for _ in range(4):      # the ends move with the radius: cap, re-place, cap again
        axis = _torso_axis(points, centre, radius)
        clear = [float(segment_distance(np.asarray(ends[i]), np.asarray(ends[i + 1]),
                                        *axis)[0]) - radii[seg] - REST_CLEARANCE_MM
                 for ends in rest.values() for i, seg in enumerate(SEGMENTS)]
        if min(clear) >= radius - 1e-9:
            break
        radius = max(0.0, min(clear))
    notes.append(f'torso: radius {radius:.1f} mm (fitted {fitted:.1f} mm from '
                 f'{len(points)} points, capped so the arms at rest clear it), axis z '
                 f'{axis[1][2]:.0f}..{axis[0][2]:.0f} mm at x, y {centre[0]:.0f}, '
                 f'{centre[1]:.0f} mm')
    return ({'torso_radius': radius, 'torso_top': tuple(float(v) for v in axis[0]),
             'torso_bottom': tuple(float(v) for v in axis[1])},
            'torso_given' not in radii and radius < fitted - 1.0)


def _torso_shape(robot, urdf, urdf_dir, rest, radii, notes):
    """Return the torso's TorsoField (:mod:`.torso_field`), or None without geometry."""
    from .torso_field import fit_field
    surface, seen = [], set()
    for side in ('right', 'left'):      # the torso links both chains share: sampled once
        links = [link for link in segment_links(robot, side)['torso'] if link not in seen]
        seen.update(links)
        points, _ = _points_at_zero(robot, side, links, urdf, urdf_dir, _link_surface)
        if len(points):
            surface.append(points)
    if not surface:
        return None
    segments = [(ends[i], ends[i + 1], radii[seg]) for ends in rest.values()
                for i, seg in enumerate(SEGMENTS) if i > 0]
    shape = fit_field(np.vstack(surface), segments, REST_CLEARANCE_MM,
                      (radii['torso_top'], radii['torso_bottom']))
    notes.append(f'torso shape: a {shape.spacing:g} mm distance field of '
                 f'{sum(len(p) for p in surface)} surface points, '
                 f'{shape.values.shape[0]} x {shape.values.shape[1]} x '
                 f'{shape.values.shape[2]} cells, eroded {shape.eroded:.1f} mm so that the '
                 'forearms and hands at rest clear it')
    return shape


def _link_surface(urdf, link_name, urdf_dir):
    """Return points (K, 3) m spread over a link's collision surfaces (its frame), and ()."""
    import trimesh
    from .torso_field import surface_points
    link = urdf.link_map.get(link_name)
    out = []
    for col in (link.collisions if link is not None else ()):
        g = col.geometry
        try:
            if g.box is not None:
                shape = trimesh.creation.box(extents=g.box.size)
            elif g.cylinder is not None:
                shape = trimesh.creation.cylinder(g.cylinder.radius, g.cylinder.length)
            elif g.sphere is not None:
                shape = trimesh.creation.icosphere(radius=g.sphere.radius)
            else:
                shape = _load_mesh(g.mesh, urdf_dir)
                if shape is None:
                    continue
                if g.mesh.scale is not None:
                    shape.apply_scale(g.mesh.scale)
        except (OSError, ValueError, AttributeError, IndexError, KeyError):
            continue
        origin = col.origin if col.origin is not None else np.eye(4)
        points = surface_points(shape)
        out.append(points @ origin[:3, :3].T + origin[:3, 3])
    return (np.vstack(out) if out else np.zeros((0, 3))), ()


def fit_capsules(robot) -> CapsuleModel:
    """Return the CapsuleModel of a profile robot, fitted to its URDF (see :func:`fit_report`)."""
    return fit_report(robot).capsules
