"""
The simulator's physics on robots from their URDF and profile: Talos, TIAGo++ (example-robot-data).

Stepped by hand in simulated time, as test_sim_core.py does for Namo: the model is the
robot's own URDF without its meshes, only the arm joints move, the capsules are the
optimiser's, and stuck joints, tracking and contacts behave as on Namo.
"""

from dataclasses import replace
import math
from pathlib import Path

from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.model.profile_robot import robot_from_profile
from namo_fault_recovery.model.robot_profile import load_profile
from namo_fault_recovery.sim.physics import (contact_pairs, designed_allowances, NamoSim,
                                             segments_mm)
from namo_fault_recovery.sim.profile_model import sim_urdf
import numpy as np
import pytest
from robot_urdfs import installed_urdf

ROBOTS = Path(__file__).resolve().parent.parent / 'config' / 'robots'
_LOADED = {}


def shipped(name):
    """Return (robot, library, designed allowances) of a shipped profile robot (once)."""
    installed_urdf(name)
    if name not in _LOADED:
        robot = robot_from_profile(ROBOTS / f'{name}.yaml')
        library = load_library(robot, ROBOTS / f'{name}_gestures.yaml')
        _LOADED[name] = robot, library, designed_allowances(robot, library)
    return _LOADED[name]


@pytest.fixture(scope='module')
def talos():
    return shipped('talos')


def run(sim, q, steps):
    sim.set_targets(q)
    sim.step(steps)


def test_the_model_is_the_urdf_without_meshes_and_only_the_arms_move(talos):
    robot, _, allowances = talos
    text = sim_urdf(robot)
    assert 'package://' not in text and '<mesh' not in text
    sim = NamoSim(robot, allowances=allowances)
    m = sim.model
    assert m.nq == m.nv == m.nu == len(robot.joint_names) == 14     # no free joint
    assert tuple(m.actuator(i).name for i in range(m.nu)) == robot.joint_names
    assert m.body('leg_left_1_link').id > 0 and m.nbody > 40       # the whole body is there
    assert {m.geom(i).name for i in range(m.ngeom)} == {
        f'{s}_arm_{g}' for s in ('right', 'left') for g in ('upper_arm', 'forearm', 'hand')
    } | {'torso'}
    assert m.npair == len(contact_pairs()) - len(allowances)
    sim.step(500)                    # gravity on: the compensated arms hold the zero pose
    assert np.abs(sim.positions()).max() < math.radians(0.01)


def test_the_capsules_are_the_optimisers_at_any_pose(talos):
    robot, _, allowances = talos
    sim = NamoSim(robot, allowances=allowances)
    m, d = sim.model, sim.data
    rng = np.random.default_rng(1)
    lower = np.concatenate([robot.arms[s].lower for s in ('right', 'left')])
    upper = np.concatenate([robot.arms[s].upper for s in ('right', 'left')])
    for q in rng.uniform(lower, upper, (5, 14)):
        sim.set_positions(q)
        for name, (a, b) in segments_mm(robot, q).items():
            g = m.geom(name).id
            axis = d.geom_xmat[g].reshape(3, 3)[:, 2] * m.geom_size[g, 1]
            ends = sorted([(d.geom_xpos[g] - axis) * 1e3, (d.geom_xpos[g] + axis) * 1e3],
                          key=lambda p: np.linalg.norm(p - a))
            assert np.linalg.norm(ends[0] - a) < 1e-6 and np.linalg.norm(ends[1] - b) < 1e-6


def _geom_ends(sim, name):
    """Return a capsule geom's two axis ends (mm, world = the arms' base frame)."""
    m, d = sim.model, sim.data
    g = m.geom(name).id
    axis = d.geom_xmat[g].reshape(3, 3)[:, 2] * m.geom_size[g, 1]
    return (d.geom_xpos[g] - axis) * 1e3, (d.geom_xpos[g] + axis) * 1e3


def test_with_its_torso_the_arms_and_the_torso_capsule_lean_together(talos):
    robot, _, allowances = talos
    sim = NamoSim(robot, allowances=allowances, shared=True)
    assert sim.joint_names == robot.joint_names + ('torso_1_joint', 'torso_2_joint')
    assert sim.model.nu == sim.model.nq == 16
    q = np.radians([30, -20, -20, -60, 10, -20, 30, -30, -20, 20, -60, -10, 20, -30])
    t = np.radians([12.0, 9.0])
    sim.set_positions(np.concatenate((q, t)))
    rot, d = robot.shared.motion(t)
    for name, (a, b) in segments_mm(robot, q).items():
        moved = [rot[0] @ p + d[0] for p in (a, b)]
        ends = sorted(_geom_ends(sim, name), key=lambda p: np.linalg.norm(p - moved[0]))
        assert max(np.linalg.norm(e - p) for e, p in zip(ends, moved)) < 1e-6, name
    upright = NamoSim(robot, allowances=allowances)
    top = [rot[0] @ p + d[0] for p in _geom_ends(upright, 'torso')]
    assert max(np.linalg.norm(e - p) for e, p in zip(_geom_ends(sim, 'torso'), top)) < 1e-6
    run(sim, np.concatenate((q, t)), 600)       # the torso settles on its lean, no contact
    assert np.abs(sim.positions()[-2:] - t).max() < math.radians(0.05)
    assert sim.contact_steps == 0


@pytest.mark.parametrize('name', ['talos', 'tiago_dual'])
def test_every_key_pose_of_the_library_is_held_without_contact(name):
    robot, library, allowances = shipped(name)
    sim = NamoSim(robot, allowances=allowances)
    assert sim.model.nq == len(robot.joint_names)       # no free joint, nothing else moves
    for gesture in library:
        for frame in gesture.keyframes:
            q = frame.positions()
            sim.set_positions(q)
            sim.reset_contact_count()
            run(sim, q, 100)
            assert np.abs(sim.positions() - q).max() < math.radians(0.01), gesture.name
            assert sim.contact_steps == 0, (gesture.name, sim.pairs_seen)


def test_a_urdf_document_is_simulated_as_its_file(talos):
    robot, _, allowances = talos
    text = Path(robot.profile.tree.source).read_text()
    described = robot_from_profile(load_profile(ROBOTS / 'talos.yaml', urdf=text))
    assert described.profile.tree.source == '<robot_description>'
    a = NamoSim(robot, allowances=allowances)
    b = NamoSim(described, allowances=allowances, urdf=text)
    q = np.radians([30, -20, -20, -60, 10, -20, 30, -30, -20, 20, -60, -10, 20, -30])
    for sim in (a, b):
        run(sim, q, 200)
    assert np.abs(a.positions() - b.positions()).max() < 1e-9
    assert np.abs(a.data.geom_xpos - b.data.geom_xpos).max() < 1e-9


def test_the_arms_track_every_key_pose_of_the_library(talos):
    robot, library, allowances = talos
    sim = NamoSim(robot, allowances=allowances)
    for gesture in library:
        for frame in gesture.keyframes:
            q = frame.positions()
            sim.set_positions(q)
            sim.reset_contact_count()
            run(sim, q, 250)
            assert np.abs(sim.positions() - q).max() < math.radians(0.05), gesture.name
            assert sim.contact_steps == 0 and not sim.pairs_seen, (gesture.name,
                                                                   sim.pairs_seen)
    wai = library['wai'].keyframes[-1].positions()
    sim.set_positions(np.zeros(14))
    for s in np.linspace(0.0, 1.0, 500):          # 2 s from rest, straight in joints
        run(sim, s * wai, 2)
    run(sim, wai, 1000)
    assert np.abs(sim.positions() - wai).max() < math.radians(0.05)
    assert np.abs(sim.velocities()).max() < 1e-3


def test_a_stuck_joint_stays_while_the_others_move(talos):
    robot, library, allowances = talos
    sim = NamoSim(robot, allowances=allowances)
    sim.stick('arm_right_4_joint', math.radians(-40.0))
    run(sim, np.zeros(14), 500)
    target = library['salute'].keyframes[-1].positions()
    worst = 0.0
    for _ in range(100):
        run(sim, target, 10)
        worst = max(worst, abs(sim.positions()[3] - math.radians(-40.0)))
    assert worst < math.radians(0.05), math.degrees(worst)
    moved = np.delete(np.arange(14), 3)
    assert np.abs(sim.positions()[moved] - target[moved]).max() < math.radians(0.1)
    assert sim.release('arm_right_4_joint')
    run(sim, target, 1500)
    assert abs(sim.positions()[3] - target[3]) < math.radians(0.1)
    with pytest.raises(KeyError, match='unknown joint'):
        sim.stick('leg_left_1_joint')               # fixed, not an arm joint


def test_a_colliding_pose_counts_and_the_torso_holds_the_arm_off(talos):
    robot, library, allowances = talos
    bare = NamoSim(robot)                # without the designed allowance, Wai is a contact
    bare.set_positions(library['wai'].keyframes[-1].positions())
    bare.step(1)
    assert {frozenset((c.geom1, c.geom2)) for c in bare.contacts()} & {
        frozenset(('right_arm_forearm', 'left_arm_forearm'))}
    sim = NamoSim(robot, allowances=allowances)
    into = np.zeros(14)
    into[2], into[3] = math.radians(90.0), math.radians(-135.0)   # forearm into the torso
    run(sim, into, 1500)
    assert sim.contact_events >= 1 and sim.max_depth > 1e-3
    # Held off physically: the torso stops the arm more than 10 deg short of the pose.
    assert np.abs(sim.positions() - into).max() > math.radians(10.0)
    assert sim.pairs_seen and all('torso' in pair and any(g.startswith('right_arm_')
                                                          for g in pair)
                                  for pair in sim.pairs_seen), sim.pairs_seen


def test_a_torso_of_radius_zero_is_a_segment_that_still_counts(talos):
    robot, _, allowances = talos
    bare = replace(robot, capsules=replace(robot.capsules, torso_radius=0.0))
    sim = NamoSim(bare, allowances=allowances)        # MuJoCo refuses a capsule of size 0
    assert 0.0 < sim.model.geom('torso').size[0] < 1e-5
    q = np.zeros(14)
    q[2], q[3] = math.radians(90.0), math.radians(-135.0)   # the forearm across the axis
    sim.set_positions(q)
    assert {pair for c in sim.contacts() for pair in [(c.geom1, c.geom2)] if 'torso' in pair}
