"""The URDF mesh check of self-collision (objective.mesh_clearance) and bench meshes."""

from dataclasses import replace
import io

from namo_fault_recovery.benchmarks.meshes import gesture_checks, run_meshes
from namo_fault_recovery.benchmarks.robots import shipped_robot
from namo_fault_recovery.model.robot_capsules import segment_links
from namo_fault_recovery.model.self_contact import PAIR_NAMES
from namo_fault_recovery.objective.mesh_clearance import MeshClearance
import numpy as np
import pytest
from robot_urdfs import installed_urdf

# Published by the engine for Talos's salute with the left elbow stuck at its library
# average (arm_left_4_joint, seed 1000, 2026-12-06, before the torso's shape was
# checked): the idle left arm, folded by the lock, moved clear of the torso capsule, but
# its hand inside the chest's mesh.
SALUTE_LEFT_ELBOW = np.radians([30.29, -94.52, -57.75, -115.89, -67.29, 25.59, -3.73,
                                5.59, 8.41, -73.13, -118.99, 89.9, 4.08, 1.14])
PAIR = PAIR_NAMES.index('left_hand-torso')


@pytest.fixture(scope='module')
def talos():
    installed_urdf('talos')
    pytest.importorskip('pinocchio', reason='the mesh check needs the robots extra (pin)')
    robot, library = shipped_robot('talos').models()
    return robot, library, MeshClearance(robot)


def test_the_arms_at_rest_clear_the_body_and_the_folded_hand_is_in_the_chest(talos):
    robot, _, meshes = talos
    rest = meshes.distances(np.zeros(7), np.zeros(7))
    assert np.all(rest > 0.0) and np.all(np.isfinite(rest)), dict(zip(PAIR_NAMES, rest))
    folded = meshes.distances(SALUTE_LEFT_ELBOW[:7], SALUTE_LEFT_ELBOW[7:])
    assert folded[PAIR] <= 0.0
    assert rest[PAIR] > 10.0


def _shape(geometry, resolve):
    """Return a URDF collision geometry as a trimesh (None for none)."""
    import trimesh
    if geometry.mesh is not None:
        mesh = trimesh.load(resolve(geometry.mesh.filename), force='mesh')
        if geometry.mesh.scale is not None:
            mesh.apply_scale(geometry.mesh.scale)
        return mesh
    if geometry.cylinder is not None:
        return trimesh.creation.cylinder(geometry.cylinder.radius, geometry.cylinder.length)
    if geometry.box is not None:
        return trimesh.creation.box(geometry.box.size)
    if geometry.sphere is not None:
        return trimesh.creation.icosphere(radius=geometry.sphere.radius)
    return None


def _sampled_distance(robot, pose, first_links, second_links):
    """Smallest distance (mm) between points sampled on two link groups' collision meshes."""
    import trimesh
    import yourdfpy
    urdf_path = robot.profile.tree.source
    roots = installed_urdf('talos').parents

    def resolve(name):
        if not name.startswith('package://'):
            return name
        found = [root / name[len('package://'):] for root in roots]
        return str(next((path for path in found if path.exists()), found[0]))

    urdf = yourdfpy.URDF.load(str(urdf_path), build_scene_graph=True, load_meshes=False,
                              build_collision_scene_graph=True, load_collision_meshes=False,
                              filename_handler=resolve)
    names = robot.arms['right'].joint_names + robot.arms['left'].joint_names
    urdf.update_cfg(dict(zip(names, pose)))
    rng = np.random.default_rng(0)

    def points(links):
        out = []
        for link in links:
            for col in urdf.link_map[link].collisions:
                mesh = _shape(col.geometry, resolve)
                if mesh is None:
                    continue
                local = np.vstack((mesh.vertices, trimesh.sample.sample_surface(
                    mesh, 4000, seed=int(rng.integers(1 << 30)))[0]))
                origin = col.origin if col.origin is not None else np.eye(4)
                frame = urdf.get_transform(link, urdf.base_link, collision_geometry=True)
                pose_link = frame @ origin
                out.append(local @ pose_link[:3, :3].T + pose_link[:3, 3])
        return np.vstack(out)

    from scipy.spatial import cKDTree
    a, b = points(first_links), points(second_links)
    return 1000.0 * cKDTree(b).query(a)[0].min()


def test_exact_distance_agrees_with_points_sampled_on_the_meshes(talos):
    # Cross-check against an independent reading of the same URDF (yourdfpy + trimesh):
    # the exact distance is at most the sampled points' and within a few millimetres.
    robot, _, meshes = talos
    right, left = segment_links(robot, 'right'), segment_links(robot, 'left')
    pose = np.zeros(14)
    exact = meshes.distances(pose[:7], pose[7:])
    sampled = _sampled_distance(robot, pose, left['hand'], left['torso'])
    assert exact[PAIR] <= sampled + 0.5
    assert sampled - exact[PAIR] < 10.0, (exact[PAIR], sampled)
    pair = PAIR_NAMES.index('right_forearm-torso')
    sampled = _sampled_distance(robot, pose, right['forearm'], right['torso'])
    assert exact[pair] <= sampled + 0.5 and sampled - exact[pair] < 10.0


def test_gesture_checks_compare_both_models_and_the_torso_shape_catches_the_chest(talos):
    robot, library, meshes = talos
    salute = next(g for g in library if g.name == 'salute')
    folded = gesture_checks(robot, meshes, salute, SALUTE_LEFT_ELBOW[None], 7)
    assert folded[0]['missed'] == [] and folded[0]['invented'] == []
    # Without the torso's shape the capsules pass that pose: the check says so.
    thin = replace(robot, capsules=replace(robot.capsules, torso_field=None))
    folded = gesture_checks(thin, meshes, salute, SALUTE_LEFT_ELBOW[None], 7)
    assert 'left_hand-torso' in folded[0]['missed'] and folded[0]['invented'] == []
    reference = [np.concatenate((k.right, k.left)) for k in salute.keyframes]
    assert all(r['missed'] == [] and r['invented'] == []
               for r in gesture_checks(robot, meshes, salute, reference, 7))


def test_bench_meshes_counts_every_published_keyframe(talos):
    out = io.StringIO()
    summary = run_meshes(out, shipped_robot('talos'), seeds=1, joints=['arm_left_4_joint'])
    robot, library, _ = talos
    per_library = sum(len(g.keyframes) for g in library)
    assert summary['keyframes'] == 2 * per_library       # the reference, then the fault
    assert all(r['fault'].startswith('arm_left_4_joint=') for r in summary['missed'])
    assert f"{len(summary['missed'])} keyframes" in out.getvalue()
