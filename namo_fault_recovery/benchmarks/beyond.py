"""
Benchmarks of what goes beyond the paper: lock strategies, double faults, stage 2, collision.

Each prints its figures and writes a JSON document of them.

All of them run the real engine, ``recover()``, on the paper's problem
(:data:`~.common.PAPER_SETTINGS`: the packaged Namo model, the Table 2 poses, no collision
term, the faulted arm alone) with a 1 s deadline, fixed seeds and the default ABC,
changing only the setting each benchmark is about.
"""

from itertools import combinations
import time

import numpy as np

from . import common

GESTURES = ('wai', 'bye', 'salute', 'side_invite')
DEADLINE = 1.0


def _recover(robot, library, faults, seed, gestures=None, deadline=DEADLINE, **changes):
    return common.run_recover(robot, library, faults,
                              common.PAPER_SETTINGS.with_changes(**changes), seed=seed,
                              deadline=deadline, gestures=gestures)


def _right_joints(robot):
    return list(robot.arms['right'].joint_names)


def bench_lock(out, out_dir, seeds=3, robot=None, library=None, joints=None):
    """Library total and per-gesture scores, ``average`` vs ``optimal`` lock, per joint."""
    robot, library = robot or common.models()[0], library or common.models()[1]
    rows, doc = [], []
    for joint in joints or _right_joints(robot):
        entry = {'joint': joint}
        for strategy in ('average', 'optimal'):
            runs = [_recover(robot, library, {joint: None}, s, lock_strategy=strategy)
                    for s in range(seeds)]
            best = min(runs, key=lambda r: r.total_score)
            entry[strategy] = {
                'lock_deg': float(np.degrees(best.locks[joint])),
                'total_best': best.total_score,
                'total_median': float(np.median([r.total_score for r in runs])),
                'per_gesture': {g.name: g.score_after for g in best.gestures},
                'time_s_max': max(r.wall_time for r in runs),
                'deadline_met': all(r.deadline_met for r in runs),
            }
        a, o = entry['average'], entry['optimal']
        entry['recovered_pct'] = 100.0 * (a['total_best'] - o['total_best']) / a['total_best']
        doc.append(entry)
        rows.append([joint, common.fmt(a['lock_deg'], 2), common.fmt(a['total_best'], 3),
                     common.fmt(o['lock_deg'], 2), common.fmt(o['total_best'], 3),
                     f'{entry["recovered_pct"]:.1f}%',
                     common.fmt(a['per_gesture']['wai'], 3),
                     common.fmt(o['per_gesture']['wai'], 3),
                     common.fmt(o['time_s_max'], 3)])
    header = ['joint', 'avg lock', 'avg total', 'opt lock', 'opt total', 'recovered',
              'wai avg', 'wai opt', 'opt time s']
    out.write(f'bench lock: library total score, average vs optimal lock (best of {seeds} '
              f'seeds, default ABC, 1 s deadline)\n')
    out.write(common.text_table(header, rows))
    common.write_json(out_dir / 'lock.json', doc)
    common.write_text(out_dir / 'lock.md', common.markdown_table(header, rows))
    return doc


def bench_pairs(out, out_dir, seed=0, robot=None, library=None, deadline=1.0):
    """Every pair of right-arm joints failing at once: scores, times, deadline status."""
    robot, library = robot or common.models()[0], library or common.models()[1]
    rows, doc = [], []
    for a, b in combinations(_right_joints(robot), 2):
        rep = _recover(robot, library, {a: None, b: None}, seed, deadline=deadline)
        scores = {g.name: g.score_after for g in rep.gestures}
        doc.append({'faults': [a, b], 'scores': scores,
                    'before': {g.name: g.score_before for g in rep.gestures},
                    'time_s': rep.wall_time, 'deadline_met': rep.deadline_met,
                    'status': {g.name: g.status for g in rep.gestures}})
        rows.append([f'{common.joint_number(robot, a)}+{common.joint_number(robot, b)}']
                    + [common.fmt(scores[g], 3) for g in GESTURES]
                    + [common.fmt(rep.wall_time * 1000, 1),
                       'yes' if rep.deadline_met else 'NO'])
    times = np.array([d['time_s'] for d in doc])
    header = ['joints'] + list(GESTURES) + ['time ms', 'in deadline']
    out.write(f'bench pairs: 21 right-arm double faults x 4 gestures (default ABC, '
              f'deadline {deadline} s, seed {seed})\n')
    out.write(common.text_table(header, rows))
    out.write(f'library time: median {np.median(times) * 1000:.1f} ms, max '
              f'{times.max() * 1000:.1f} ms; deadline met in '
              f'{sum(d["deadline_met"] for d in doc)}/{len(doc)}\n')
    common.write_json(out_dir / 'pairs.json', doc)
    common.write_text(out_dir / 'pairs.md', common.markdown_table(header, rows))
    return doc


def bench_bimanual(out, out_dir, seeds=3, robot=None, library=None):
    """Wai under each single right-arm failure: stage 1 (faulted arm) vs stage 2."""
    robot, library = robot or common.models()[0], library or common.models()[1]
    rows, doc = [], []
    for joint in _right_joints(robot):
        s1, s2 = [], []
        for s in range(seeds):
            rep = _recover(robot, library, {joint: None}, s, gestures=['wai'], bimanual='on')
            s1.append(rep['wai'].stage1_score)
            s2.append(rep['wai'].score_after)
        b1, b2 = min(s1), min(s2)
        doc.append({'joint': joint, 'stage1': b1, 'stage2': b2,
                    'gain_pct': 100.0 * (b1 - b2) / b1 if b1 > 0 else 0.0})
        rows.append([joint, common.fmt(b1, 3), common.fmt(b2, 3),
                     f'{doc[-1]["gain_pct"]:.1f}%'])
    out.write(f'bench bimanual: Wai, stage 1 (faulted arm only) vs stage 2 (healthy arm '
              f'joins), best of {seeds} seeds\n')
    out.write(common.text_table(['joint', 'stage 1', 'stage 2', 'gain'], rows))
    common.write_json(out_dir / 'bimanual.json', doc)
    return doc


def bench_collision(out, out_dir, seed=0, robot=None, library=None, png=True):
    """Colliding results with the plain score vs with the collision term, and the cost."""
    robot, library = robot or common.models()[0], library or common.models()[1]
    joints = _right_joints(robot)
    fault_sets = [(j,) for j in joints] + list(combinations(joints, 2))
    counts = {'plain': 0, 'collision': 0}
    cost, doc = [], []
    start = time.monotonic()
    for faults in fault_sets:
        plain = _recover(robot, library, dict.fromkeys(faults), seed)
        aware = _recover(robot, library, dict.fromkeys(faults), seed, collision_check=True)
        checked = _check(robot, library, plain)   # the plain result, same capsule model
        counts['plain'] += sum(checked)
        for g_plain, g_col, hit in zip(plain.gestures, aware.gestures, checked):
            counts['collision'] += bool(g_col.collides)
            cost.append(g_col.score_after - g_plain.score_after)
            doc.append({'faults': list(faults), 'gesture': g_col.name,
                        'plain_score': g_plain.score_after, 'plain_collides': hit,
                        'collision_score': g_col.score_after,
                        'collision_collides': bool(g_col.collides),
                        'pairs': list(g_col.colliding_pairs)})
    cost = np.array(cost)
    n = len(doc)
    hit = cost[[d['plain_collides'] for d in doc]]
    out.write(f'bench collision: {len(fault_sets)} fault sets (7 single + 21 double, right '
              f'arm) x 4 gestures = {n} results, seed {seed} '
              f'({time.monotonic() - start:.1f} s)\n')
    out.write(f'  colliding results, plain score:          {counts["plain"]}/{n}\n')
    out.write(f'  colliding results, with collision term:  {counts["collision"]}/{n}\n')
    if hit.size:
        out.write(f'  score cost where the plain result collided: median {np.median(hit):.3f},'
                  f' max {hit.max():.3f}\n')
    out.write(f'  score cost over all results: mean {cost.mean():.4f}\n')
    fig7g = _recover(robot, library, {'right_arm_joint6': None}, seed, gestures=['wai'],
                     collision_check=True)
    plain7g = _recover(robot, library, {'right_arm_joint6': None}, seed, gestures=['wai'])
    hands = _hand_gap(robot, fig7g['wai'].keyframes[0])
    out.write(f'  paper Fig. 7g case (Wai, joint 6): score {fig7g["wai"].score_after:.3f} '
              f'(plain {plain7g["wai"].score_after:.3f}), collides: '
              f'{fig7g["wai"].collides}, hand-axis gap {hands:.1f} mm (right hand y < left '
              f'hand y: {_not_crossed(robot, fig7g["wai"].keyframes[0])})\n')
    common.write_json(out_dir / 'collision.json', {'counts': counts, 'results': doc})
    if png:
        try:
            from .plotting import plot_reconfiguration
            path = plot_reconfiguration(robot, library, fig7g, 'wai',
                                        out_dir / 'fig7g_wai_joint6.png',
                                        title='Wai, right joint 6 locked: collision-aware')
            out.write(f'  figure: {path}\n')
        except ImportError as exc:
            out.write(f'  figure skipped: {exc}\n')
    return counts, doc


def _check(robot, library, report):
    from ..objective.collision import CollisionModel
    from ..model.kinematics import forward_kinematics
    from ..objective.score import gesture_targets
    model = CollisionModel(robot, [t for g in library for t in gesture_targets(g)
                                   if g.name in [x.name for x in report.gestures]],
                           robot.capsules)
    out = []
    for k, g in enumerate(report.gestures):
        kf = g.keyframes[0]
        out.append(bool(model.collides(forward_kinematics(robot, kf.right[None], 'right'),
                                       forward_kinematics(robot, kf.left[None], 'left'),
                                       np.array([k]))[0]))
    return out


def _hand_gap(robot, keyframe):
    from ..objective.collision import segment_distance
    from ..model.kinematics import forward_kinematics
    r = forward_kinematics(robot, keyframe.right[None], 'right')
    left = forward_kinematics(robot, keyframe.left[None], 'left')
    return float(segment_distance(r.wrist, r.tip, left.wrist, left.tip)[0][0])


def _not_crossed(robot, keyframe):
    from ..model.kinematics import forward_kinematics
    r = forward_kinematics(robot, keyframe.right[None], 'right')
    left = forward_kinematics(robot, keyframe.left[None], 'left')
    return bool(r.tip[0, 1] <= left.tip[0, 1] + 1e-6 and r.wrist[0, 1] <= left.wrist[0, 1])
