"""
``bench notice``: how fast a structure change is noticed, and how often it cries wolf.

In process, on the simulator's clock (load-independent): the player's plan of a gesture
from rest is commanded at every physics step of a changed copy of Namo (MuJoCo), joint
states are fed at 100 Hz and the simulated tracker's samples (30 Hz, 50 ms latency,
sigma 1 or 4 mm) at their delivery, stamped at capture, to the player's
:class:`~..playback.deviation.DeviationWatch`.  Per change kind: the play time at which
the change is suspected (from the start of the motion), the arm and error reported; on
the unchanged robot: the false alarms over N plays of every gesture and noise seed.
"""

import numpy as np

from ..model.gestures import load_library
from ..model.robot import load_robot
from ..model.urdf import urdf_string
from ..playback.deviation import DeviationThresholds, DeviationWatch
from ..playback.timing import plan_motion
from ..resources import config_path, DEMO_MOTION_FILE
from ..sim.physics import NamoSim
from ..sim.structure_change import apply_changes, parse_change
from ..sim.tracker import FingertipTracker, TrackerSettings, TrueFingertips

CHANGES = ('tool:right_arm_fingertip_joint:50', 'tool:right_arm_fingertip_joint:100',
           'bend:right_arm_joint5:10', 'encoder_offset:right_arm_joint4:5',
           'link_length:right_arm_joint5:30')
STATE_EVERY = 5          # physics steps between joint states (100 Hz at 2 ms)
AFTER = 1.0              # s simulated after the planned end (the goal check)


def plan_from_rest(robot, gesture):
    """Return the player's plan of ``gesture`` from the rest pose (all zero)."""
    frames = [np.concatenate([kf.right, kf.left]) for kf in gesture.keyframes]
    return plan_motion(robot.joint_names, np.zeros(len(robot.joint_names)),
                       [kf.time_from_start for kf in gesture.keyframes], frames,
                       list(robot.joint_velocity_limits))


def play_watched(robot, plan, urdf, tracker_settings, thresholds=DeviationThresholds(),
                 stuck=None):
    """Play ``plan`` on the copy ``urdf`` under the watch; return (watch, suspicions)."""
    sim, truth = NamoSim(robot, urdf=urdf), TrueFingertips(urdf)
    tracker = FingertipTracker(tracker_settings)
    if stuck:
        sim.stick(*stuck)
    names = list(robot.joint_names)
    watch, found = DeviationWatch(robot, plan, 0.0, thresholds), []
    times = np.arange(int((plan.duration + AFTER) / sim.timestep)) * sim.timestep
    commands, velocities = plan.command_at(times), plan.velocity_at(times)
    for k in range(len(times)):
        sim.set_targets(commands[k], velocities[k])
        sim.step(1)
        now = times[k] + sim.timestep
        q = sim.positions()
        if k % STATE_EVERY == 0:
            watch.joint_state(now, names, q)
        if tracker.due(now):
            tracker.capture(now, truth(dict(zip(names, q))))
        for m in tracker.deliver(now):
            hit = watch.fingertip(m.side, m.capture, m.point_mm)
            if hit is not None:
                found.append(hit)
    return watch, found


def run_notice(out, gestures=('bye', 'circle'), sigmas=(1.0, 4.0), seeds=3,
               progress=True) -> dict:
    """Measure time to notice per change kind and false alarms; print and return them."""
    robot = load_robot()
    library = load_library(robot, config_path(DEMO_MOTION_FILE))
    nominal = urdf_string(robot)
    rows, alarms = [], []
    for gesture in gestures:
        plan = plan_from_rest(robot, library[gesture])
        for sigma in sigmas:
            for spec in CHANGES:
                urdf = apply_changes(nominal, [parse_change(spec)])
                for seed in range(seeds):
                    _, found = play_watched(robot, plan, urdf, TrackerSettings(sigma, seed=seed))
                    first = found[0] if found else None
                    rows.append({'gesture': gesture, 'sigma_mm': sigma, 'change': spec,
                                 'seed': seed, 'noticed': first is not None,
                                 'arm': first.side if first else '',
                                 'time_s': first.play_time if first else None,
                                 'error_mm': first.error_mm if first else None})
            for seed in range(seeds):
                _, found = play_watched(robot, plan, nominal, TrackerSettings(sigma, seed=seed))
                alarms.append({'gesture': gesture, 'sigma_mm': sigma, 'seed': seed,
                               'false_alarms': len(found)})
            if progress:
                out.write(f'  {gesture} sigma {sigma:g} mm done\n')
    summary = {'rows': rows, 'unchanged': alarms, 'thresholds': vars(DeviationThresholds())}
    _print(out, rows, alarms)
    return summary


def _print(out, rows, alarms):
    out.write('change | gesture | sigma mm | noticed | time to notice s (median, max) '
              '| arm | error mm (median)\n')
    keys = sorted({(r['change'], r['gesture'], r['sigma_mm']) for r in rows})
    for change, gesture, sigma in keys:
        sel = [r for r in rows if (r['change'], r['gesture'], r['sigma_mm'])
               == (change, gesture, sigma)]
        hit = [r for r in sel if r['noticed']]
        times = [r['time_s'] for r in hit]
        arms = ','.join(sorted({r['arm'] for r in hit})) or '-'
        figures = (f'{np.median(times):.2f}, {max(times):.2f} | {arms} | '
                   f'{np.median([r["error_mm"] for r in hit]):.1f}' if hit else '- | - | -')
        out.write(f'{change} | {gesture} | {sigma:g} | {len(hit)}/{len(sel)} | {figures}\n')
    for sigma in sorted({a['sigma_mm'] for a in alarms}):
        sel = [a for a in alarms if a['sigma_mm'] == sigma]
        out.write(f'unchanged robot, sigma {sigma:g} mm: '
                  f'{sum(a["false_alarms"] for a in sel)} false alarms in {len(sel)} plays\n')
