"""
One self-contact geometry: the optimiser's capsules against the simulator's.

The optimiser's capsule model (:mod:`namo_fault_recovery.objective.collision`) and the
MuJoCo model the simulator builds from the URDF (:mod:`namo_fault_recovery.sim.physics`)
must agree on every sampled pose, pair by pair: a library the optimiser passes as clear
must count no contact in the simulator for the same poses.  Also the load-time check of
a library's reference poses.
"""

import math

import mujoco
from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.model.kinematics import forward_kinematics
from namo_fault_recovery.model.self_contact import (PAIR_NAMES, PAIRS, penetrations,
                                                    REFUSE_MM, SEGMENTS, TOLERANCE_MM)
from namo_fault_recovery.objective.collision import CollisionModel
from namo_fault_recovery.objective.score import gesture_targets
from namo_fault_recovery.sim.physics import designed_allowances, NamoSim
import numpy as np
import pytest
import yaml


def _geom(side, seg):
    return 'torso' if side == 'torso' else f'{side}_arm_{SEGMENTS[seg]}'


GEOM_PAIRS = [(_geom(a, i), _geom(b, k)) for a, i, b, k in PAIRS]


@pytest.fixture(scope='module')
def sim(robot):
    return NamoSim(robot, gravity=False)


def _sampled_poses(n=300, seed=7):
    """Random poses over the whole joint range, half of them near the body (more contacts)."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-math.pi, math.pi, (n, 14))
    q[n // 2:] *= 0.5
    return q


def _place(sim, q):
    sim.data.qpos[:] = 0.0
    sim.data.qpos[[sim.model.jnt_qposadr[sim.model.joint(j).id]
                   for j in sim.joint_names]] = q
    mujoco.mj_forward(sim.model, sim.data)


def test_capsule_distances_are_the_simulators_on_sampled_poses(robot, sim):
    """Signed surface distance of every checked pair: objective == MuJoCo, to 1 um."""
    model = CollisionModel(robot, [], robot.capsules)
    ids = [(sim.model.geom(a).id, sim.model.geom(b).id) for a, b in GEOM_PAIRS]
    fromto = np.zeros(6)
    worst = 0.0
    touching = 0
    for q in _sampled_poses():
        _place(sim, q)
        d = model.distances(forward_kinematics(robot, q[None, :7], 'right'),
                            forward_kinematics(robot, q[None, 7:], 'left'))[0][0]
        ours = d - model.radius_sum
        theirs = np.array([mujoco.mj_geomDistance(sim.model, sim.data, g1, g2, 2.0, fromto)
                           for g1, g2 in ids]) * 1e3
        worst = max(worst, float(np.max(np.abs(ours - theirs))))
        touching += bool(np.any(ours < -TOLERANCE_MM))
    assert worst < 1e-3, f'capsule models differ by {worst:.4f} mm'
    assert touching > 30      # the sample exercises contacts, not only clear poses


def test_the_simulators_contacts_are_the_objectives_penetrations(robot, sim):
    """The simulator's contact pipeline reports exactly the pairs deeper than 1 mm, as deep."""
    names = [sim.model.geom(i).name for i in range(sim.model.ngeom)]
    index = {frozenset(p): k for k, p in enumerate(GEOM_PAIRS)}
    for q in _sampled_poses(200, seed=11):
        _place(sim, q)
        pen = penetrations(robot, q)[0]
        depth = np.zeros(len(PAIRS))
        con = sim.data.contact
        for c in range(sim.data.ncon):
            k = index[frozenset((names[con.geom1[c]], names[con.geom2[c]]))]
            depth[k] = max(depth[k], -1e3 * con.dist[c])
        np.testing.assert_allclose(depth, pen, atol=1e-3, err_msg=str(
            [PAIR_NAMES[k] for k in np.nonzero(np.abs(depth - pen) > 1e-3)[0]]))


def test_designed_contact_is_the_same_in_both_models(robot, product_library):
    """The Wai's designed depths: the optimiser's allowance == the simulator's, pair by pair."""
    wai = product_library['wai']
    model = CollisionModel(robot, gesture_targets(wai), robot.capsules)
    ours = {GEOM_PAIRS[k]: (model.radius_sum[k] - model.allowed[-1, k]) * 1e-3
            for k in range(len(PAIRS)) if model.allowed[-1, k] < model.radius_sum[k]}
    theirs = designed_allowances(robot, product_library)
    assert ours.keys() == theirs.keys() and ours
    for pair, depth in ours.items():
        assert theirs[pair] == pytest.approx(depth, abs=1e-9)
    # A one-handed gesture, or the torso, never has designed contact.
    for g in product_library:
        model = CollisionModel(robot, gesture_targets(g), robot.capsules)
        torso = [k for k, (_, _, b, _) in enumerate(PAIRS) if b == 'torso']
        assert np.all(model.allowed[:, torso] == model.radius_sum[torso])
        if not g.two_handed:
            assert np.all(model.allowed == model.radius_sum)


def test_packaged_libraries_load_without_warnings(robot, product_library, demo_library,
                                                  library):
    for lib in (product_library, demo_library, library):
        assert lib.warnings == ()
        for g in lib:
            pen = penetrations(robot, g.joint_matrix())
            if g.two_handed:
                pen = pen[:, [b == 'torso' for _, _, b, _ in PAIRS]]
            assert pen.max() <= TOLERANCE_MM, g.name


def _abduction(deg):
    q = np.zeros(14)
    q[1] = math.radians(deg)
    return q


def _abduction_for_depth(robot, depth_mm):
    """Return the right shoulder abduction (deg) that swings the arm ``depth_mm`` into the body."""
    lo, hi = 0.0, 60.0
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if penetrations(robot, _abduction(mid)).max() < depth_mm else (lo, mid)
    return lo


def _deepest_pair(robot, deg):
    return PAIR_NAMES[int(np.argmax(penetrations(robot, _abduction(deg))[0]))]


def _library_file(tmp_path, abduction_deg):
    doc = {'units': 'deg', 'gestures': [
        {'name': 'wave', 'arms': ['right'], 'two_handed': False, 'keyframes': [
            {'time_from_start': 1.0, 'right': [20, 0, 0, 30, 0, 0, 0], 'left': [0] * 7},
            {'time_from_start': 2.0, 'right': [0, abduction_deg, 0, 0, 0, 0, 0],
             'left': [0] * 7}]}]}
    path = tmp_path / 'lib.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


def test_a_reference_deep_in_the_torso_is_refused_at_load(robot, tmp_path):
    angle = _abduction_for_depth(robot, 30.0)
    path = _library_file(tmp_path, angle)
    with pytest.raises(ValueError) as err:
        load_library(robot, path)
    text = str(err.value)
    assert '\n' not in text
    for part in (str(path), 'gestures[0].keyframes[1]', "'wave'", 'keyframe 1',
                 _deepest_pair(robot, angle), '30.0 mm', 'refused'):
        assert part in text, (part, text)


def test_a_graze_loads_with_a_one_line_warning(robot, tmp_path):
    angle = _abduction_for_depth(robot, 2.5)
    path = _library_file(tmp_path, angle)
    said = []
    lib = load_library(robot, path, on_warning=said.append)
    assert lib.warnings == tuple(said) and len(said) == 1
    assert '\n' not in said[0] and said[0].startswith('warning: ')
    for part in (str(path), "'wave'", 'keyframe 1', _deepest_pair(robot, angle), '2.5 mm'):
        assert part in said[0], (part, said[0])
    assert 2.5 < REFUSE_MM


def test_a_played_path_is_checked_beyond_its_design_as_the_simulator_counts(robot,
                                                                            product_library):
    """
    The path between keyframes is checked, not only the keyframes.

    Wai from rest is within its design; palms pressed deeper along the way count, as
    deep as the simulator's contact says.
    """
    from namo_fault_recovery.model.self_contact import undesigned_depth
    wai = product_library['wai']
    key = wai.joint_matrix()[-1]
    path = np.linspace(0.0, 1.0, 60)[:, None] * key[None, :]    # from rest, as played
    assert undesigned_depth(robot, wai, path) <= TOLERANCE_MM
    sim = NamoSim(robot, gravity=False, allowances=designed_allowances(robot, product_library))
    hands = PAIRS.index(('right', 2, 'left', 2))
    for step in np.radians(np.arange(0.5, 10.0, 0.5)):
        pressed = key.copy()
        pressed[[1, 8]] += step              # both shoulders bring the hands further in
        depth = undesigned_depth(robot, wai, np.vstack([np.zeros(14), pressed]))
        _place(sim, pressed)
        counted = {(c.geom1, c.geom2): c.depth * 1e3 for c in sim.contacts()}
        if depth > TOLERANCE_MM + 0.5:
            assert GEOM_PAIRS[hands] in counted, (np.degrees(step), depth, counted)
            assert max(counted.values()) == pytest.approx(depth, abs=0.05)
            break
    else:
        pytest.fail('no pressed pose went beyond the design')
