"""
``bench motion``: typical points + Kriging against per-point exploration, whole motions.

The second source paper's three scenarios (a 50 mm tool, a 100 mm tool, the elbow
locked at 0 deg with and without DOF expansion) are run on the dense "draw a circle"
motion and on the Bye wave, each with both methods in the same run.  They are read from
the demo library of motions (``config/demo_motions.yaml``) unless a gesture file is given:
the packaged library holds Namo's four gestures only.  Per case it prints
the exploration cost (objective evaluations, and the Kriging method's share of the
per-point one), the wall time, the fingertip error against the designed path (mean and
max, mm), the similarity score and the largest joint jump between successive points.

With ``--deadline`` (:func:`bench_motion_deadline`) it runs the node's case instead:
the whole library that holds the circle, the node's settings and method ``auto`` within
the deadline, for all 14 single faults, the 50 and 100 mm tools and the elbow locked at
0 with expansion; per case, whether the deadline was met, the wall time, the circle's
mean fingertip error against the per-point pass without a deadline, and its largest
joint step against the designed one.
"""

from dataclasses import replace
import json
import math
import os
import time

from . import common
from ..model.gestures import GestureLibrary, load_library
from ..model.robot import ARMS, load_robot
from ..optimize.base import Clock
from ..recovery.engine import recover, RecoverySettings
from ..recovery.locks import resolve_locks
from ..recovery.motion import DEFAULT_DISTORTION_MM, typical_points
from ..resources import config_path, DEMO_MOTION_FILE

ELBOW = 'right_arm_joint4'
SCENARIOS = (
    ('tool 50 mm', {'tool_mm': 50.0}),
    ('tool 100 mm', {'tool_mm': 100.0}),
    ('elbow locked at 0, no expansion', {'faults': {ELBOW: 0.0}, 'expand': False}),
    ('elbow locked at 0, with expansion', {'faults': {ELBOW: 0.0}}),
)
MOTIONS = ('circle', 'bye')
WAVE_DISTORTION_MM = 20.0
METHODS = ('kriging', 'per_point')
# The paper's figures (its own 3-DOF humanoid arm and circle; compare shapes only).
PAPER = {
    'tool 50 mm': 'recovered, ~8% exploration cost (8 of 100 points)',
    'tool 100 mm': 'not reachable in 3 DOF; recovered in 4 DOF',
    'elbow locked at 0, no expansion': '216 mm unadapted -> ~30 mm (3 DOF)',
    'elbow locked at 0, with expansion': '216 mm -> 7.4 mm (4 DOF), ~97% similar',
}


def run_case(robot, gesture, method, seed, min_points, distortion_mm=DEFAULT_DISTORTION_MM,
             faults=None, tool_mm=0.0, expand=True):
    """
    Adapt one motion alone with ``recover()``, without a deadline.

    The settings are the paper's problem (:data:`~.common.PAPER_SETTINGS`) with this
    ``method``, tool and distortion threshold.  ``min_points`` is passed through the
    typical points (:func:`~namo_fault_recovery.recovery.motion.typical_points`), and
    ``expand=False`` drops the gesture's DOF expansion stages.  Returns its
    :class:`~namo_fault_recovery.recovery.result.GestureResult` and the wall time (s).
    """
    if not expand:
        gesture = replace(gesture, expand=())
    lib = GestureLibrary((gesture,), '<bench>')
    settings = common.PAPER_SETTINGS.with_changes(trajectory_method=method,
                                                  tool_length_mm=float(tool_mm),
                                                  vq_distortion_mm=float(distortion_mm))
    start = time.monotonic()
    res = recover(robot, lib, faults, settings, seed=seed, clock=Clock(None),
                  quantisations=typical_points(robot, lib, distortion_mm, min_points))
    return res[gesture.name], time.monotonic() - start


def _motion_row(name, label, method, gesture, g, wall):
    """Return one row of ``bench motion``: a motion, scenario and method's figures."""
    return {'motion': name, 'scenario': label, 'method': method,
            'points': len(gesture.keyframes),
            'typical': (g.typical_points if method == 'kriging'
                        else len(gesture.keyframes)),
            'nfev': g.nfev, 'wall_ms': 1000 * wall,
            'tip_error_before_mm': g.tip_error_before_mm,
            'tip_error_mean_mm': g.tip_error_mm,
            'tip_error_max_mm': g.tip_error_max_mm,
            'recovery_pct': 100 * (1 - g.tip_error_mm
                                   / max(g.tip_error_before_mm, 1e-9)),
            'score_before': g.score_before_mean, 'score_mean': g.score_mean,
            'score_max': g.score_after,
            'jump_designed_deg': g.max_jump_designed_deg,
            'jump_before_deg': g.max_jump_before_deg,
            'jump_after_deg': g.max_jump_deg,
            'kriging_sigma_max_deg': max(g.kriging_sigma_deg, default=0.0),
            'expansion_stage': g.expansion_stage,
            'free_joints': list(g.free_joints),
            'paper': PAPER[label]}


def _motion_rows(out, robot, name, gesture, seed, distortion_mm):
    """Run one motion under every scenario and method; print and return its rows."""
    rows = []
    # A short keyframed motion is quantised too here, to show the method on it, with
    # a threshold to suit its small fingertip excursion.
    min_points = 2
    threshold = distortion_mm if len(gesture.keyframes) > 20 else WAVE_DISTORTION_MM
    out.write(f'\n## {name}: {len(gesture.keyframes)} points, distortion threshold '
              f'{threshold:g} mm\n')
    out.write(f'{"scenario":36s} {"method":10s} {"K":>3s} {"evals":>7s} {"cost":>6s} '
              f'{"time ms":>8s} {"err0 mm":>8s} {"mean mm":>8s} {"max mm":>7s} '
              f'{"recov":>6s} {"score":>7s} {"jump0":>6s} {"jump":>6s} {"stage":>5s}\n')
    for label, kwargs in SCENARIOS:
        pair = {}
        for method in METHODS:
            g, wall = run_case(robot, gesture, method, seed, min_points,
                               distortion_mm=threshold, **kwargs)
            pair[method] = g
            rows.append(_motion_row(name, label, method, gesture, g, wall))
        base = pair['per_point'].nfev
        for row in rows[-2:]:
            row['cost_pct'] = 100.0 * row['nfev'] / base if base else math.nan
            out.write(f'{label:36s} {row["method"]:10s} {row["typical"]:3d} '
                      f'{row["nfev"]:7d} {row["cost_pct"]:5.1f}% {row["wall_ms"]:8.0f} '
                      f'{row["tip_error_before_mm"]:8.1f} {row["tip_error_mean_mm"]:8.1f} '
                      f'{row["tip_error_max_mm"]:7.1f} {row["recovery_pct"]:5.1f}% '
                      f'{row["score_mean"]:7.2f} {row["jump_before_deg"]:6.1f} '
                      f'{row["jump_after_deg"]:6.1f} '
                      f'{row["expansion_stage"]:5d}\n')
    return rows


def bench_motion(out, out_dir, seed=0, motions=MOTIONS, robot_file=None, gesture_file=None,
                 distortion_mm=DEFAULT_DISTORTION_MM):
    """
    Run every motion x scenario x method; print the table, write motion.json.

    ``gesture_file`` None reads the demo library of motions, which holds the circle.
    """
    robot = load_robot(robot_file)
    library = load_library(robot, gesture_file if gesture_file is not None
                           else config_path(DEMO_MOTION_FILE))
    out.write(f'# bench motion: seed {seed}; '
              f'{common.format_machine(common.machine_info())}\n')
    rows = []
    for name in motions:
        rows += _motion_rows(out, robot, name, library[name], seed, distortion_mm)
    out.write('\nK: points explored; cost: evaluations of the method / those of per-point '
              'exploration in the same run; err0: mean fingertip error of the unadapted '
              'motion; recov: 1 - mean error '
              '/ err0 (the paper\'s "97% similar"); score: mean similarity score (lower is '
              'better); jump0 / jump: largest joint step (deg) between successive points, '
              'unadapted (locks applied) / adapted; designed '
              f'{rows[0]["jump_designed_deg"]:.1f} deg for the circle; stage: DOF expansion '
              'stages used.\n\nThe paper (its own 3-DOF arm; compare shapes, not values):\n')
    for label, text in PAPER.items():
        out.write(f'  {label:36s} {text}\n')
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, 'motion.json')
    with open(path, 'w', encoding='utf-8') as stream:
        json.dump({'seed': seed, 'distortion_mm': distortion_mm, 'rows': rows}, stream,
                  indent=1)
    out.write(f'written: {path}\n')
    return rows


def library_holding(robot, name, gesture_file=None):
    """Return ``gesture_file``'s library (default: the demo motions); it must hold ``name``."""
    library = load_library(robot, gesture_file if gesture_file is not None
                           else config_path(DEMO_MOTION_FILE))
    if not any(g.name == name for g in library):
        raise ValueError(f'{library.source}: no gesture {name!r}; expected one of '
                         f'{", ".join(g.name for g in library)}')
    return library


def deadline_cases(robot):
    """Return the node-case scenarios: every single fault, the tools, the elbow at 0."""
    cases = [(f'{j} (average lock)', {'faults': {j: None}})
             for side in ARMS for j in robot.arms[side].joint_names]
    return cases + [('tool 50 mm', {'tool_mm': 50.0}), ('tool 100 mm', {'tool_mm': 100.0}),
                    ('elbow locked at 0, with expansion', {'faults': {ELBOW: 0.0}})]


def _deadline_legend(out, motion, designed):
    """Print what the columns of the motion-deadline table mean."""
    out.write(f'\nmet: deadline met by the whole library (auto, node settings); wall: its '
              f"recover() time; tip / pp tip: the {motion}'s mean fingertip error (mm), auto "
              f'within the deadline / per point without one (same locks); diff: tip - pp '
              f'tip (target <= +1 mm); step / pp st: largest joint step (deg), designed '
              f'{designed:.2f} (target <= {1.5 * designed:.2f}); score: mean similarity '
              f'score; coll: the adapted motion collides somewhere.\n')


def bench_motion_deadline(out, out_dir, seed=0, deadline=1.0, robot_file=None,
                          gesture_file=None, motion='circle', cases=None):
    """
    Run the node's case for every scenario; print the table, write motion_deadline.json.

    ``auto`` adapts the whole library holding ``motion`` with the node's settings within
    ``deadline`` (s); the reference is ``per_point`` on that motion alone, with the same
    locks and no deadline.
    """
    robot = load_robot(robot_file)
    library = library_holding(robot, motion, gesture_file)
    designed = None
    out.write(f'# bench motion --deadline {deadline:g}: {motion} in a library of '
              f'{len(library)} gestures, seed {seed}; '
              f'{common.format_machine(common.machine_info())}\n')
    out.write(f'{"case":36s} {"met":>4s} {"wall ms":>8s} {"method":>10s} '
              f'{"tip mm":>7s} {"pp tip":>7s} {"diff":>6s} {"step":>5s} {"pp st":>5s} '
              f'{"score":>6s} {"pp sc":>6s} {"coll":>4s}\n')
    rows = []
    for label, kwargs in (cases or deadline_cases(robot)):
        faults, tool = kwargs.get('faults', {}), kwargs.get('tool_mm', 0.0)
        settings = RecoverySettings(deadline_sec=float(deadline), trajectory_method='auto',
                                    tool_length_mm=float(tool))
        start = time.monotonic()
        res = recover(robot, library, faults, settings, seed=seed,
                      clock=Clock(float(deadline)))
        wall = time.monotonic() - start
        g = res[motion]
        locks, _ = resolve_locks(robot, library, faults, settings.lock_strategy)
        ref = recover(robot, GestureLibrary((library[motion],), '<bench>'), locks,
                      settings.with_changes(trajectory_method='per_point'), seed=seed,
                      clock=Clock(None))[motion]
        designed = g.max_jump_designed_deg
        row = {'case': label, 'deadline_met': bool(res.deadline_met), 'wall_ms': 1000 * wall,
               'method': g.method, 'tip_error_mean_mm': g.tip_error_mm,
               'tip_error_max_mm': g.tip_error_max_mm,
               'per_point_tip_error_mean_mm': ref.tip_error_mm,
               'tip_error_vs_per_point_mm': g.tip_error_mm - ref.tip_error_mm,
               'max_step_deg': g.max_jump_deg, 'per_point_max_step_deg': ref.max_jump_deg,
               'designed_step_deg': designed, 'score_mean': g.score_mean,
               'per_point_score_mean': ref.score_mean, 'collides': bool(g.collides),
               'notes': list(res.notes)}
        rows.append(row)
        out.write(f'{label:36s} {"yes" if row["deadline_met"] else "NO":>4s} '
                  f'{row["wall_ms"]:8.0f} {g.method:>10s} {g.tip_error_mm:7.2f} '
                  f'{ref.tip_error_mm:7.2f} {row["tip_error_vs_per_point_mm"]:+6.2f} '
                  f'{g.max_jump_deg:5.2f} {ref.max_jump_deg:5.2f} {g.score_mean:6.2f} '
                  f'{ref.score_mean:6.2f} {"yes" if g.collides else "no":>4s}\n')
    _deadline_legend(out, motion, designed)
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, 'motion_deadline.json')
    with open(path, 'w', encoding='utf-8') as stream:
        json.dump({'seed': seed, 'deadline': deadline, 'motion': motion, 'rows': rows},
                  stream, indent=1)
    out.write(f'written: {path}\n')
    return rows
