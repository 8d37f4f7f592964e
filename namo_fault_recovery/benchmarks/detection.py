"""
``namo-recovery bench detection``: stuck-joint detection and recovery on the simulator.

Runs the player's own planning and monitoring (:mod:`..playback`) against the MuJoCo
core of the simulator (:class:`..sim.physics.NamoSim`) in this process, stepping the
physics in lock-step with a 100 Hz command and measurement loop, so the figures are
deterministic and free of DDS and scheduling noise (they do not include message
latency; ``bench latency`` measures that part).  For every gesture:

- played normally from rest: false alarms (a fault reported on a healthy robot),
  whether it finished, and the gap between the score of the executed final pose
  (measured) and of the planned one;
- every joint stuck in turn at its rest angle: whether it was detected, the detection
  time (from the moment the command leaves the stuck angle by the threshold), and the
  joint's excursion in that gesture (a joint the gesture moves by less than the
  threshold cannot be told from a healthy one);
- for the gestures in ``recover_gestures``: the time from the stuck joint to the first
  correct play (detection + reconfiguration by the engine + the replay with the lock,
  simulated time plus the engine's wall time), the gap between the scores of the
  replay's executed final pose and of the library's final keyframe (for a one-keyframe
  gesture that is the library's own ``score_after``), and the self-contacts the
  physics counted during the replay.
"""

import math
import time

import numpy as np

from ..objective.score import ScoreWeights, SimilarityScore
from ..playback.clearance import PathClearance
from ..playback.monitor import MonitorThresholds, Playback
from ..playback.timing import plan_motion, PlayTiming

RATE = 100.0         # Hz: command and measurement loop


def _arrays(gesture):
    times = np.array([kf.time_from_start for kf in gesture.keyframes])
    frames = np.array([kf.positions() for kf in gesture.keyframes])
    return times, frames


def play_on_sim(sim, robot, times, frames, locks=None, monitor=MonitorThresholds(),
                timing=PlayTiming(), limit=30.0):
    """
    Play one motion on ``sim`` from where it is; return (outcome, plan, elapsed, trace).

    The trace is a list of (t, commanded, measured) at every control tick.
    """
    names = robot.joint_names
    limits = np.array(robot.joint_velocity_limits)
    lower = np.concatenate([robot.arms[s].lower for s in ('right', 'left')])
    upper = np.concatenate([robot.arms[s].upper for s in ('right', 'left')])
    plan = plan_motion(names, sim.positions(), times, frames, limits, locks=locks,
                       lower=lower, upper=upper, timing=timing,
                       clearance=PathClearance(robot, names))
    playback = Playback(plan, [names[:7], names[7:]], monitor)
    steps = max(1, int(round(1.0 / (RATE * sim.timestep))))
    trace = []
    t, outcome = 0.0, None
    while outcome is None and t < limit:
        tc = min(t, plan.duration)
        q_cmd = plan.command_at(tc)
        qd = plan.velocity_at(tc) if t < plan.duration else np.zeros(14)
        sim.set_targets(q_cmd, qd)
        sim.step(steps)
        t += steps * sim.timestep
        measured = sim.positions()
        trace.append((t, q_cmd, measured))
        outcome = playback.update(t, measured)
    if outcome is None:
        outcome = playback.abort(f'no outcome within {limit:g} s')
    if not outcome.ok:
        sim.set_targets(sim.positions())     # stop where the arm is, as the node does
    return outcome, plan, t, trace


def _score(robot, gesture, q14):
    scorer = SimilarityScore.for_gesture(robot, gesture, len(gesture.keyframes) - 1,
                                         ScoreWeights())
    return float(scorer(np.asarray(q14[:7]), np.asarray(q14[7:]))[0])


def _recover_and_replay(robot, library, sim, name, joint, angle, deadline, seed, monitor,
                        detection_s):
    """Recover the library for a detected stuck joint, replay ``name``; return figures."""
    from ..recovery.engine import recover, RecoverySettings
    gesture = library[name]
    j = robot.joint_names.index(joint)
    began = time.monotonic()
    result = recover(robot, library, {joint: angle}, RecoverySettings(deadline_sec=deadline),
                     seed=seed)
    engine = time.monotonic() - began
    adapted = next(g for g in result.gestures if g.name == name)
    lock = result.locks[joint]
    sim.reset_contact_count()
    replay, plan2, elapsed2, trace2 = play_on_sim(
        sim, robot, np.array(adapted.times), np.array(adapted.positions),
        locks={joint: lock}, monitor=monitor)
    commanded = np.array([cmd[j] for _, cmd, _ in trace2])
    executed = _score(robot, gesture, sim.positions())
    planned = _score(robot, gesture, adapted.positions[-1])
    return {'replay_ok': replay.ok, 'reason': replay.reason,
            'stuck_to_correct_play_s': detection_s + engine + elapsed2,
            'detection_s': detection_s, 'engine_s': engine, 'replay_s': elapsed2,
            'score_after': adapted.score_after, 'planned_score': planned,
            'executed_score': executed, 'score_gap': abs(executed - planned),
            'lock_commanded_elsewhere': int(np.count_nonzero(commanded != lock)),
            'contact_events': sim.contact_events}


def _stuck_play(robot, sim, joint, times, frames, monitor):
    """Play with ``joint`` stuck at 0; return (its entry, the detected angles, elapsed)."""
    j = robot.joint_names.index(joint)
    excursion = float(np.ptp(np.vstack([np.zeros(14), frames])[:, j]))
    for k in list(sim.stuck):
        sim.release(k)
    sim.set_positions(np.zeros(14))
    held = sim.stick(joint, 0.0)
    outcome, plan, elapsed, trace = play_on_sim(sim, robot, times, frames, monitor=monitor)
    detected = [a for f, a in outcome.faults if f == joint]
    wrong = [f for f, _ in outcome.faults if f != joint]
    departs = next((t for t, cmd, _ in trace
                    if abs(cmd[j] - held) > monitor.fault_threshold), None)
    entry = {'excursion_deg': math.degrees(excursion), 'detected': bool(detected),
             'wrong_joints': wrong, 'at_s': elapsed if detected else None,
             'after_departure_s': (elapsed - departs) if detected and departs
             is not None else None, 'reason': outcome.reason}
    return entry, detected, elapsed


def _normal_play(robot, sim, gesture, times, frames, monitor):
    """Play ``gesture`` on a healthy robot from rest; return its entry."""
    for j in list(sim.stuck):
        sim.release(j)
    sim.set_positions(np.zeros(14))
    sim.reset_contact_count()
    outcome, plan, elapsed, _ = play_on_sim(sim, robot, times, frames, monitor=monitor)
    gap = abs(_score(robot, gesture, sim.positions()) - _score(robot, gesture, frames[-1]))
    return {'ok': outcome.ok, 'false_alarms': len(outcome.faults),
            'reason': outcome.reason, 'duration_s': plan.duration,
            'elapsed_s': elapsed, 'score_gap': gap, 'contact_events': sim.contact_events}


def run(robot, library, sim_factory, gestures=None, joints=None, recover_gestures=('wai',),
        deadline=1.0, seed=0, monitor=MonitorThresholds(), progress=None):
    """Run the benchmark; return a JSON-ready dict of every figure."""
    gestures = list(gestures or library.names)
    joints = list(joints or robot.joint_names)
    doc = {'rate_hz': RATE, 'threshold_deg': math.degrees(monitor.fault_threshold),
           'hold_sec': monitor.fault_hold, 'tracking_lag_sec': monitor.tracking_lag,
           'normal': {}, 'stuck': {}, 'recovery': {}}
    sim = sim_factory()
    for name in gestures:
        gesture = library[name]
        times, frames = _arrays(gesture)
        normal = doc['normal'][name] = _normal_play(robot, sim, gesture, times, frames,
                                                    monitor)
        if progress:
            progress(f"{name:12s} normal: {normal['reason']}; score gap "
                     f"{normal['score_gap']:.4f}")
        for joint in joints:
            entry, detected, elapsed = _stuck_play(robot, sim, joint, times, frames, monitor)
            doc['stuck'].setdefault(name, {})[joint] = entry
            if not detected or name not in recover_gestures:
                continue
            rec = doc['recovery'].setdefault(name, {})[joint] = _recover_and_replay(
                robot, library, sim, name, joint, detected[0], deadline, seed, monitor,
                elapsed)
            if progress:
                progress(f'{name:12s} {joint}: detected {entry["after_departure_s"]:.2f} s '
                         f"after departure; replay {rec['reason']}; score "
                         f"{rec['executed_score']:.4f} vs planned {rec['planned_score']:.4f}")
    return doc


def summary(doc):
    """Return the headline figures of a benchmark document."""
    normal = doc['normal'].values()
    stuck = [e for g in doc['stuck'].values() for e in g.values()]
    exercised = [e for e in stuck if e['excursion_deg'] > doc['threshold_deg'] * 1.5]
    times = [e['after_departure_s'] for e in stuck if e['after_departure_s'] is not None]
    rec = [e for g in doc['recovery'].values() for e in g.values()]
    out = {
        'normal_plays': len(normal),
        'false_alarms': sum(e['false_alarms'] for e in normal),
        'normal_finished': sum(e['ok'] for e in normal),
        'normal_score_gap_max': max((e['score_gap'] for e in normal), default=None),
        'stuck_runs': len(stuck),
        'exercised_runs': len(exercised),
        'exercised_detected': sum(e['detected'] for e in exercised),
        'detected_total': sum(e['detected'] for e in stuck),
        'wrong_joint_reports': sum(len(e['wrong_joints']) for e in stuck),
        'detection_after_departure_s': _stats(times),
        'recoveries': len(rec),
        'replays_ok': sum(e['replay_ok'] for e in rec),
        'stuck_to_correct_play_s': _stats([e['stuck_to_correct_play_s'] for e in rec
                                           if e['replay_ok']]),
        'recovered_score_gap_max': max((e['score_gap'] for e in rec), default=None),
        'lock_commanded_elsewhere': sum(e['lock_commanded_elsewhere'] for e in rec),
        'replay_contact_events': sum(e['contact_events'] for e in rec),
    }
    return out


def run_on_sim(robot, library, **options):
    """
    Return :func:`run` on the simulator's physics (``NamoSim``), with its summary.

    ``options`` are those of :func:`run`; the document gains ``summary`` and
    ``wall_time_s``.
    """
    from ..sim.physics import designed_allowances, NamoSim
    allowances = designed_allowances(robot, library)
    began = time.monotonic()
    doc = run(robot, library, lambda: NamoSim(robot, allowances=allowances), **options)
    doc['summary'] = summary(doc)
    doc['wall_time_s'] = time.monotonic() - began
    return doc


def write_summary(out, doc):
    """Print the figures of a :func:`run_on_sim` document."""
    s = doc['summary']
    out.write(f"\nthreshold {doc['threshold_deg']:g} deg for {doc['hold_sec']:g} s, lag "
              f"window {doc['tracking_lag_sec']:g} s, {doc['rate_hz']:g} Hz\n")
    out.write(f"normal plays: {s['normal_plays']}, finished {s['normal_finished']}, false "
              f"alarms {s['false_alarms']}, executed-vs-planned score gap max "
              f"{s['normal_score_gap_max']:.4f}\n")
    out.write(f"stuck joints: {s['stuck_runs']} runs, {s['exercised_runs']} where the "
              f"gesture moves the joint by > 1.5 x threshold: {s['exercised_detected']} "
              f"detected; detected in all {s['detected_total']}; wrong joint reported "
              f"{s['wrong_joint_reports']}\n")
    d = s['detection_after_departure_s']
    if d:
        out.write('detection time after the command leaves the stuck angle: median '
                  f"{d['median']:.2f} s, min {d['min']:.2f} s, max {d['max']:.2f} s "
                  f"(n={d['n']})\n")
    r = s['stuck_to_correct_play_s']
    out.write(f"recoveries: {s['recoveries']}, correct replays {s['replays_ok']}"
              + (f"; stuck joint -> first correct play: median {r['median']:.2f} s, max "
                 f"{r['max']:.2f} s" if r else '') + '\n')
    if s['recovered_score_gap_max'] is not None:
        out.write('replay executed-vs-library score gap max '
                  f"{s['recovered_score_gap_max']:.4f}; lock commanded elsewhere "
                  f"{s['lock_commanded_elsewhere']} times; self-contact events in "
                  f"replays {s['replay_contact_events']}\n")
    out.write(f"wall time {doc['wall_time_s']:.1f} s\n")


def _stats(values):
    if not values:
        return None
    a = np.asarray(values, dtype=float)
    return {'n': int(a.size), 'min': float(a.min()), 'median': float(np.median(a)),
            'max': float(a.max())}
