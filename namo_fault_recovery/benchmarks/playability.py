"""
Every published library can be played: the player's verdict on the engine's output.

``namo-recovery bench playability``.  A gesture is *unplayable* when the player would
stretch it (:func:`~namo_fault_recovery.playback.timing.plan_motion`, the very plan the
gesture player sends: its ``stretch`` above 1 means a segment needed more than a
joint's ``velocity_limits`` and was slowed down).  Every library is planned from the
rest pose, as the player's first play after a fault; the approach is the player's own
(at ``approach_velocity``).  Two parts, both through the engine's entry point
``recover()`` with the node's settings, every single fault:

- ``budget``: ``seeds`` seeds at a fixed small evaluation budget
  (:data:`BUDGET_OVERRIDES`: one colony cycle, a short polish, no deadline), where
  unfinished searches leave keyframes in different branches most often.  It counts
  evaluations, not seconds, so it reads the same on a loaded machine;
- ``deadline``: ``deadline_seeds`` seeds at the node's 1 s deadline (run it alone on the
  machine: how far a search gets depends on the load).

A fault is locked where the lock strategy puts it (``average``: one angle per joint), or,
with ``lock_angles`` N, at N angles across the range the library moves that joint
through (:func:`stuck_angles`): where a joint that sticks mid-gesture is held, and where
the search's far kinematic twins came up (Namo's wai with the right elbow stuck at 44.8
deg: the shoulder half a turn over, the path from rest through the torso, which the
average lock never showed; :mod:`..recovery.twins`).  Each seed then runs at each angle.

Per part: gestures planned, unplayable ones, the largest stretch, the largest peak
speed over the limit of the player's unstretched plan, and the largest ``speed_ratio``
the engine reported (its bound on that peak), with the runs the engine had to repair.
Also the self-contact of the played path by the capsule model
(:func:`~..model.self_contact.undesigned_depth`, every :data:`PATH_STEP` of the plan
from rest): the engine checks its keyframes, the player plays the path between them,
so a gesture whose path goes deeper than its design (:data:`~..model.self_contact.
TOLERANCE_MM`) is counted (``path_contacts``) with the engine's own verdict beside.
The player bends a path that presses deeper than its keyframes
(:mod:`..playback.clearance`); ``straight_path_contacts`` counts the same of the
straight path it played before, from the same plans.
"""

import multiprocessing
import time

import numpy as np

from . import common
from .product import load_models, node_settings
from .robots import robot_models
from ..model.self_contact import TOLERANCE_MM, undesigned_depth
from ..optimize.base import Clock
from ..playback.clearance import PathClearance
from ..playback.timing import plan_motion, PlayTiming
from ..recovery.engine import recover
from ..recovery.keyframes import joint_bounds, PACED_NOTE
from ..recovery.motion import typical_points

# One employed/onlooker cycle and a 5-step polish: a search cut after a handful of
# evaluations, far below what 1 s allows.
BUDGET_OVERRIDES = {'max_cycles': 1, 'polish_maxiter': 5}
_GRID = 400            # samples of a plan when looking for its peak speed
_NO_LIMIT = 1e6        # speed limits that never stretch: the plan as timed
STRETCHED = 1.0 + 1e-9
PATH_STEP = 0.02       # s between the checked poses of a played path

_WORKER = {}


def playability_models(which='product', robot='namo'):
    """Return ``(robot, library)``: Namo's ``which`` library, or a shipped profile robot's."""
    if robot == 'namo':
        return load_models(which)
    if which != 'product':
        raise ValueError(f'--library {which}: only Namo has a demo library; expected product '
                         f'with --robot {robot}')
    return robot_models(robot)


def play_figures(robot, gesture, locks, timing=PlayTiming(), reference=None):
    """
    Return (stretch, peak speed over the limit, path depth mm, straight depth mm).

    The plan of the GestureResult starts at the rest pose (all zeros), holds ``locks``
    (joint -> rad) and clips into the joint limits, and its path is bent clear of the
    body (:mod:`..playback.clearance`), as the player does.  The peak is read off the
    plan timed as designed (limits so high that nothing is stretched), on a fine grid;
    the depths are the played path's deepest contact beyond ``reference``'s design, and
    the same of the straight path that the player played before it bent paths (0
    without a reference).
    """
    names = robot.joint_names
    limits = np.asarray(robot.joint_velocity_limits, dtype=float)
    lower, upper = joint_bounds(robot)
    args = (names, np.zeros(len(names)), gesture.times, np.asarray(gesture.positions))
    options = {'locks': locks, 'lower': lower, 'upper': upper, 'timing': timing}
    clearance = PathClearance(robot, names)
    played = plan_motion(*args, limits, clearance=clearance, **options)
    timed = plan_motion(*args, limits * _NO_LIMIT, clearance=clearance, **options)
    t = np.linspace(0.0, timed.duration, _GRID)
    peak = float(np.max(np.abs(timed.velocity_at(t)) / limits))
    depths = [0.0, 0.0]
    if reference is not None:
        for k, plan in enumerate((played, plan_motion(*args, limits, **options))):
            path = np.arange(0.0, plan.duration + PATH_STEP, PATH_STEP)
            depths[k] = undesigned_depth(robot, reference, plan.command_at(path))
    return float(played.stretch), peak, *depths


def stuck_angles(robot, library, joint, n):
    """
    Return ``n`` lock angles (rad) of ``joint`` evenly inside the range the library uses.

    The range spans the rest pose (0, where every play starts) and every keyframe's
    angle of the joint, clipped to its limits; the angles exclude its ends (a joint that
    sticks mid-gesture).  A joint the library never moves gets its rest angle.
    """
    lower, upper, _ = robot.joint_bounds(joint)
    column = list(robot.joint_names).index(joint)
    angles = [0.0] + [kf.positions()[column] for g in library for kf in g.keyframes]
    low, high = max(min(angles), lower), min(max(angles), upper)
    if high - low <= 1e-9:
        return [float(np.clip(0.0, lower, upper))] * n
    return [float(a) for a in np.linspace(low, high, n + 2)[1:-1]]


def _init_worker(which, robot_name='namo'):
    robot, lib = playability_models(which, robot_name)
    settings = node_settings()
    _WORKER.update(robot=robot, lib=lib, settings=settings,
                   quant=typical_points(robot, lib, settings.vq_distortion_mm))


def _run_one(task):
    joint, seed, deadline, angle = task
    robot, lib, settings = _WORKER['robot'], _WORKER['lib'], _WORKER['settings']
    clock = Clock(deadline)
    overrides = None if deadline is not None else BUDGET_OVERRIDES
    res = recover(robot, lib, {joint: angle}, settings, seed=seed, clock=clock,
                  quantisations=_WORKER['quant'], optimizer_overrides=overrides)
    gestures = []
    for g in res.gestures:
        stretch, peak, depth, straight = play_figures(robot, g, res.locks,
                                                      reference=lib[g.name])
        gestures.append({'gesture': g.name, 'stretch': stretch, 'peak_ratio': peak,
                         'speed_ratio': g.speed_ratio, 'path_depth_mm': depth,
                         'straight_depth_mm': straight,
                         'keyframes_collide': bool(g.collides)})
    return {'fault': joint if angle is None else f'{joint} at {np.degrees(angle):.1f} deg',
            'seed': seed, 'gestures': gestures,
            'repaired': sum(PACED_NOTE in n for n in res.notes),
            'deadline_met': res.deadline_met}


def _summary(runs):
    rows = [g for r in runs for g in r['gestures']]
    bad = [dict(g, fault=r['fault'], seed=r['seed']) for r in runs for g in r['gestures']
           if g['stretch'] > STRETCHED]
    touching = [dict(g, fault=r['fault'], seed=r['seed']) for r in runs
                for g in r['gestures'] if g['path_depth_mm'] > TOLERANCE_MM]
    return {'runs': len(runs), 'gestures': len(rows), 'unplayable': len(bad),
            'unplayable_runs': sum(any(g['stretch'] > STRETCHED for g in r['gestures'])
                                   for r in runs),
            'max_stretch': max(g['stretch'] for g in rows),
            'max_peak_ratio': max(g['peak_ratio'] for g in rows),
            'max_speed_ratio': max(g['speed_ratio'] for g in rows),
            'repaired_runs': sum(r['repaired'] > 0 for r in runs),
            'deadline_met_share': float(np.mean([r['deadline_met'] for r in runs])),
            'worst': sorted(bad, key=lambda g: -g['stretch'])[:5],
            'path_contacts': len(touching),
            'path_contacts_clear_keyframes': sum(not g['keyframes_collide'] for g in touching),
            'max_path_depth_mm': max(g['path_depth_mm'] for g in rows),
            'worst_paths': sorted(touching, key=lambda g: -g['path_depth_mm'])[:5],
            'path_contacts_by': _count_by(touching),
            'straight_path_contacts': sum(g['straight_depth_mm'] > TOLERANCE_MM for g in rows),
            'max_straight_depth_mm': max(g['straight_depth_mm'] for g in rows)}


def _count_by(rows):
    """Return ``{'gesture fault': [paths touching, of them with clear keyframes]}``."""
    counts = {}
    for g in rows:
        entry = counts.setdefault(f"{g['gesture']} {g['fault']}", [0, 0])
        entry[0] += 1
        entry[1] += not g['keyframes_collide']
    return dict(sorted(counts.items()))


def _part(out, models, tasks, jobs, label, progress):
    prog = common.Progress(len(tasks), label) if progress else None
    runs = []
    began = time.monotonic()
    ctx = multiprocessing.get_context('spawn')
    with ctx.Pool(max(1, int(jobs)), initializer=_init_worker, initargs=models) as pool:
        for run in pool.imap_unordered(_run_one, tasks, chunksize=8):
            runs.append(run)
            if prog:
                prog.step()
    summary = _summary(runs)
    summary['wall_sec'] = time.monotonic() - began
    return summary


def run_playability(out, which='product', seeds=2000, deadline_seeds=0, joints=None,
                    jobs=2, seed_base=0, progress=True, robot_name='namo', lock_angles=0):
    """
    Run the parts (see the module docstring); print the figures, return the summary.

    ``seeds`` runs per single fault at the fixed budget (0: skip), ``deadline_seeds``
    at the node's deadline (0: skip; run it with ``jobs=1`` on a quiet machine).
    ``robot_name``: ``namo``, or one of the shipped profile robots
    (:data:`.robots.ROBOTS`) with its retargeted library.  ``lock_angles`` > 0 locks
    each joint at that many angles of :func:`stuck_angles` (each seed at each) instead
    of the lock strategy's.
    """
    robot, library = playability_models(which, robot_name)
    joints = list(joints or robot.joint_names)
    locks = {j: (stuck_angles(robot, library, j, lock_angles) if lock_angles > 0 else [None])
             for j in joints}
    deadline = node_settings().deadline_sec
    summary = {'library': which if robot_name == 'namo' else f'{robot_name} product',
               'robot': robot_name, 'joints': joints, 'budget_overrides': BUDGET_OVERRIDES,
               'lock_angles_deg': {j: [None if a is None else float(np.degrees(a))
                                       for a in angles] for j, angles in locks.items()},
               'machine': common.machine_info(), 'parts': {}}
    plan = [('budget', seeds, None, jobs), ('deadline', deadline_seeds, deadline, 1)]
    for name, n, limit, n_jobs in plan:
        if n <= 0:
            continue
        tasks = [(j, seed_base + s, limit, a) for j in joints for a in locks[j]
                 for s in range(n)]
        summary['parts'][name] = _part(out, (which, robot_name), tasks, n_jobs,
                                       f'playability {name}', progress)
    print_playability(out, summary, deadline)
    return summary


def print_playability(out, s, deadline):
    """Print the table of :func:`run_playability`'s summary."""
    out.write(f"\n== playability [{s['library']}] (every single fault; the player's plan "
              f'from the rest pose) ==\n')
    labels = {'budget': f"fixed budget {s['budget_overrides']}",
              'deadline': f'deadline {deadline:g} s'}
    rows = [[labels[k], p['runs'], p['gestures'], p['unplayable'], p['unplayable_runs'],
             common.fmt(p['max_stretch'], 3), common.fmt(p['max_peak_ratio'], 3),
             common.fmt(p['max_speed_ratio'], 3), p['repaired_runs'],
             f"{100 * p['deadline_met_share']:.0f}%", f"{p['wall_sec']:.0f}"]
            for k, p in s['parts'].items()]
    out.write(common.text_table(
        ['part', 'runs', 'gestures', 'unplayable', 'runs with one', 'max stretch',
         'max peak/limit', 'max speed_ratio', 'repaired runs', 'deadline met', 'wall s'],
        rows))
    for k, p in s['parts'].items():
        for g in p['worst']:
            out.write(f"  {k}: {g['gesture']} (fault {g['fault']}, seed {g['seed']}): "
                      f"stretch {g['stretch']:.3f}, peak {g['peak_ratio']:.3f} x the "
                      f'limit\n')
        verdict = 'met' if p['unplayable'] == 0 else 'MISSED'
        out.write(f"{k}: {p['unplayable']} unplayable of {p['gestures']} gestures "
                  f'(target 0): {verdict}\n')
        for g in p['worst_paths']:
            out.write(f"  {k}: {g['gesture']} (fault {g['fault']}, seed {g['seed']}): the "
                      f"played path {g['path_depth_mm']:.1f} mm beyond the design"
                      f"{'' if g['keyframes_collide'] else ' (keyframes clear)'}\n")
        out.write(f"{k}: {p['path_contacts']} of {p['gestures']} played paths touch beyond "
                  f"their design ({p['path_contacts_clear_keyframes']} of them with every "
                  f"keyframe clear), deepest {p['max_path_depth_mm']:.1f} mm (target 0); "
                  f"straight, as played before paths were bent: {p['straight_path_contacts']}"
                  f", deepest {p['max_straight_depth_mm']:.1f} mm\n")
