"""
``bench meshes``: what the capsules pass as clear, measured on the robot's URDF meshes.

Every single fault x ``seeds`` through ``recover()`` at the node's deadline (and the
reference library itself), every published keyframe of every gesture: the capsule
verdict the engine reports (:class:`~..objective.collision.CollisionModel`, the
designed right-left contacts of a two-handed gesture allowed) beside the distance of
the same pairs on the URDF's collision geometry
(:class:`~..objective.mesh_clearance.MeshClearance`).  A two-handed gesture's
right-left pairs are left out of both (its hands are designed to meet).  Counted per
keyframe:

- **missed**: the meshes touch where the capsules are clear: the robot would hit
  itself with a library the engine published as collision-free;
- **invented**: the capsules penetrate (beyond the tolerance) where the meshes are
  more than ``FREE_MM`` apart: a pose the search was pushed away from for nothing.
"""

import time

import numpy as np

from .robots import BenchRobot, QUALITY_SEED_BASE
from ..model.kinematics import batch_forward
from ..model.self_contact import designed_pairs, PAIR_NAMES, TOLERANCE_MM
from ..objective.collision import CollisionModel
from ..objective.mesh_clearance import MeshClearance, TOUCH_MM
from ..objective.score import gesture_targets
from ..recovery.contingency import entry_key, fault_sets
from ..recovery.engine import recover, RecoverySettings

FREE_MM = 20.0      # meshes this far apart while the capsules penetrate: an invented contact
SHOWN = 12          # keyframes listed of each kind


def gesture_checks(robot, meshes, gesture, positions, right_joints):
    """
    Return one record per keyframe of a published gesture: the pairs each model flags.

    ``gesture`` is the library's (its keyframes' references set the allowed distances);
    ``positions`` (K, J) its published angles, ``right_joints`` the right arm's columns.
    """
    targets = gesture_targets(gesture)
    checker = CollisionModel(robot, targets, robot.capsules)
    q = np.asarray(positions, dtype=float)
    ids = np.minimum(np.arange(len(q)), len(targets) - 1)
    lm_r = batch_forward(robot, q[:, :right_joints], 'right')
    lm_l = batch_forward(robot, q[:, right_joints:], 'left')
    capsule_hits = checker.penetration(lm_r, lm_l, ids) > TOLERANCE_MM
    skip = designed_pairs(gesture.two_handed)
    records = []
    for k, row in enumerate(q):
        mesh = meshes.distances(row[:right_joints], row[right_joints:])
        caps = capsule_hits[k] & ~skip
        touch = (mesh <= TOUCH_MM) & ~skip
        records.append({'keyframe': k, 'mesh_mm': mesh,
                        'missed': [PAIR_NAMES[p] for p in np.nonzero(touch & ~caps)[0]],
                        'invented': [PAIR_NAMES[p] for p in
                                     np.nonzero(caps & (mesh > FREE_MM))[0]]})
    return records


def _libraries(robot, lib, seeds, joints):
    """Yield ``(fault key, seed, library result)``: the reference, then every single fault."""
    settings = RecoverySettings()
    yield 'none', None, recover(robot, lib, {}, settings, seed=0)
    for faults in fault_sets(robot, lib, settings, joints=joints):
        for seed in range(QUALITY_SEED_BASE, QUALITY_SEED_BASE + seeds):
            yield entry_key(faults), seed, recover(robot, lib, dict.fromkeys(faults),
                                                   settings, seed=seed)


def run_meshes(out, bench: BenchRobot, seeds=1, joints=None) -> dict:
    """Check every published keyframe of ``bench``'s robot on its meshes; print, return."""
    robot, lib = bench.models()
    began = time.monotonic()
    meshes = MeshClearance(robot)
    by_name = {g.name: g for g in lib}
    rows, found = 0, {'missed': [], 'invented': []}
    for key, seed, result in _libraries(robot, lib, seeds, joints):
        for g in result.gestures:
            split = g.right_joints or len(robot.arms['right'].joint_names)
            for rec in gesture_checks(robot, meshes, by_name[g.name], g.positions, split):
                rows += 1
                for kind in found:
                    if rec[kind]:
                        found[kind].append({'fault': key, 'seed': seed, 'gesture': g.name,
                                            'keyframe': rec['keyframe'], 'pairs': rec[kind]})
    summary = {'robot': bench.name, 'keyframes': rows, 'seeds': seeds,
               'missed': found['missed'], 'invented': found['invented'],
               'wall_s': round(time.monotonic() - began, 1)}
    _print(out, summary)
    return summary


def _print(out, s):
    robot, rows, seeds = s['robot'], s['keyframes'], s['seeds']
    out.write(f'\n== {robot}: capsules against the URDF collision meshes, {rows} published '
              f'keyframes (the reference library and every single fault x {seeds} '
              f'seed(s) at the deadline), {s["wall_s"]} s ==\n')
    out.write(f'meshes touch, capsules clear (missed):      {len(s["missed"])} keyframes\n')
    out.write(f'capsules touch, meshes > {FREE_MM:g} mm apart (invented): '
              f'{len(s["invented"])} keyframes\n')
    for kind in ('missed', 'invented'):
        for r in s[kind][:SHOWN]:
            seed = '' if r['seed'] is None else f' seed {r["seed"]}'
            out.write(f'  {kind}: {r["fault"]}{seed} {r["gesture"]}[{r["keyframe"]}]: '
                      f'{", ".join(r["pairs"])}\n')
