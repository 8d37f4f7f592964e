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
"""

from dataclasses import replace
import json
import math
import os
import time

from . import common
from ..model.gestures import GestureLibrary, load_library
from ..model.robot import load_robot
from ..optimize.base import Clock
from ..recovery.engine import recover
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
        gesture = library[name]
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
                row = {'motion': name, 'scenario': label, 'method': method,
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
                rows.append(row)
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
