"""
``namo-recovery bench detection-suite``: the stuck-joint detector as a guest would see it.

Every gesture of the packaged library and of the demo library, on the MuJoCo core of
the simulator (:class:`..sim.physics.NamoSim`) stepped in lock-step with a 100 Hz
command and measurement loop, watched by the player's own monitor
(:class:`..playback.monitor.Playback`), under two conditions, ``idle`` and ``busy``:

- **readings**: each joint reading carries Gaussian noise (``noise_deg``, default 0.1
  deg, five times the ``namo_sim`` node's default);
- **arrival**: each reading reaches the detector late by a lateness measured on this
  machine, just before the plays, by :func:`..ros.joint_state_stream.reading_lateness`:
  a 100 Hz ``/joint_states`` stream from another process received over DDS by a
  subscriber like the player's, with the machine as it is (``idle``) or with a
  busy-looping process pinned to the other core (``busy``).  The measured sequence is
  replayed, from a random place per play, in order (a burst stays a burst).  As the
  ``gesture_player`` node does, the detector judges each reading at its stamp (where
  the arm was when it was read), when it arrives: a late reading delays the decision,
  not the prediction.  The motion is stamped with the play's start; the simulated
  controller takes it on as late as one reading's lateness (the goal's own delivery),
  holding the arm until then, and then joins it where the play is, as a trajectory
  controller does with a past stamp.  What it does not model: a controller slowed by
  the load (the physics stays in lock-step) and message loss.

Per condition and library:

- **normal plays**: every gesture ``reps`` times from rest (plus a uniform start spread
  of ``start_spread_deg`` per joint): false alarms (plays that report any fault),
  playability (plays that finish within ``goal_time`` of their planned duration), the
  executed-vs-planned score gap at the final pose, and the self-contacts the physics
  counted (a gesture that its own body blocks is a library error, not a detector one);
- **stuck plays**: every joint x gesture ``stuck_reps`` times, the joint stuck where it
  starts: detection latency from the moment its command leaves the stuck angle by 2 deg
  (median, p95, max; the target is 0.3 s), joints never detected although the command
  left them by 2 deg, and other joints wrongly reported.

The tracking model of the monitor is also fitted (:func:`..playback.tracking.
fit_tracking`) on a noise-free healthy play of every gesture, and printed beside the
values in use: that is how the stored defaults were measured.
"""

from dataclasses import dataclass, field, replace
import functools
import math
import time

import numpy as np

from . import common
from ..model.gestures import load_library
from ..model.self_contact import pressed_joints, reference_contact
from ..objective.score import ScoreWeights, SimilarityScore
from ..playback.clearance import PathClearance
from ..playback.monitor import MonitorThresholds, Playback
from ..playback.timing import plan_motion, PlayTiming
from ..playback.tracking import fit_tracking
from ..resources import config_path, DEFAULT_GESTURE_FILE, DEMO_MOTION_FILE

RATE = 100.0                  # Hz: command and measurement loop
DEPARTURE_DEG = 2.0           # the command has left the stuck angle by this much
TARGET_LATENCY_S = 0.3
NOISE_DEG = 0.1
LIBRARIES = {'packaged': DEFAULT_GESTURE_FILE, 'demo': DEMO_MOTION_FILE}


@dataclass(frozen=True)
class SuiteOptions:
    """What the suite plays and how the readings are made."""

    reps: int = 100
    stuck_reps: int = 1
    noise_deg: float = NOISE_DEG
    start_spread_deg: float = 1.0
    seed: int = 0
    monitor: MonitorThresholds = field(default_factory=MonitorThresholds)
    timing: PlayTiming = field(default_factory=PlayTiming)


class Arrival:
    """When the player receives each reading: a measured lateness sequence, replayed."""

    def __init__(self, lateness, rng):
        """Start at a random place of ``lateness`` (s; empty: every reading on time)."""
        self.lateness = np.asarray(lateness if len(lateness) else [0.0], dtype=float)
        self.k = int(rng.integers(len(self.lateness)))
        self.goal_delay = self._next()          # the goal's own delivery to the controller
        self.last = -math.inf

    def _next(self):
        value = self.lateness[self.k % len(self.lateness)]
        self.k += 1
        return float(value)

    def receipt(self, t):
        """Return the player's time at which the reading taken at play time ``t`` arrives."""
        self.last = max(self.last, t + self._next())
        return self.last


def _limits(robot):
    lower = np.concatenate([robot.arms[s].lower for s in ('right', 'left')])
    upper = np.concatenate([robot.arms[s].upper for s in ('right', 'left')])
    return np.array(robot.joint_velocity_limits), lower, upper


def play(sim, robot, gesture, arrival, options, limit=30.0):
    """
    Play ``gesture`` on ``sim`` from where it is; return (outcome, plan, trace).

    The trace is (play time, receipt time, commanded, reading) at every control tick;
    the sim's clock is the play's (the motion is stamped with the play's start).
    """
    names = robot.joint_names
    times = np.array([kf.time_from_start for kf in gesture.keyframes])
    frames = np.array([kf.positions() for kf in gesture.keyframes])
    limits, lower, upper = _limits(robot)
    plan = plan_motion(names, sim.readings(), times, frames, limits, lower=lower,
                       upper=upper, timing=options.timing,
                       clearance=PathClearance(robot, names))
    playback = Playback(plan, [names[:7], names[7:]], options.monitor,
                        functools.partial(pressed_joints, robot, names))
    steps = max(1, int(round(1.0 / (RATE * sim.timestep))))
    trace, t, outcome = [], 0.0, None
    held = plan.positions[0]
    while outcome is None and t < limit:
        tc = min(t, plan.duration)
        q_cmd = plan.command_at(tc)
        if t < arrival.goal_delay:          # not received yet: the arm holds
            sim.set_targets(held, np.zeros(14))
        else:
            sim.set_targets(q_cmd, plan.velocity_at(tc) if t < plan.duration
                            else np.zeros(14))
        sim.step(steps)
        t += steps * sim.timestep
        reading = sim.readings()
        at = arrival.receipt(t)
        trace.append((t, at, q_cmd, reading))
        outcome = playback.update(t, reading)
    if outcome is None:
        outcome = playback.abort(f'no outcome within {limit:g} s')
    return outcome, plan, trace


def _score(robot, gesture, q14):
    scorer = SimilarityScore.for_gesture(robot, gesture, len(gesture.keyframes) - 1,
                                         ScoreWeights())
    return float(scorer(np.asarray(q14[:7]), np.asarray(q14[7:]))[0])


def _start(sim, rng, spread_deg):
    for joint in list(sim.stuck):
        sim.release(joint)
    q0 = rng.uniform(-1.0, 1.0, 14) * math.radians(spread_deg)
    sim.set_positions(q0)
    sim.reset_contact_count()
    return q0


def normal_play(sim, robot, gesture, arrival, options, rng):
    """Play ``gesture`` on a healthy robot; return its entry."""
    _start(sim, rng, options.start_spread_deg)
    outcome, plan, trace = play(sim, robot, gesture, arrival, options)
    gap = abs(_score(robot, gesture, sim.positions()) - _score(robot, gesture, plan.final))
    late = [at - t for t, at, _, _ in trace]
    return {'ok': outcome.ok, 'faults': [f for f, _ in outcome.faults],
            'reason': outcome.reason, 'duration_s': plan.duration,
            'score_gap': gap, 'contact_events': sim.contact_events,
            'max_lateness_s': max(late, default=0.0)}


def stuck_play(sim, robot, gesture, joint, arrival, options, rng):
    """Play ``gesture`` with ``joint`` stuck where it starts; return its entry."""
    j = robot.joint_names.index(joint)
    q0 = _start(sim, rng, options.start_spread_deg)
    held = sim.stick(joint, q0[j])
    outcome, plan, trace = play(sim, robot, gesture, arrival, options)
    grid = np.arange(0.0, plan.duration + 1e-3, 1e-3)     # the sim's time of the command
    away = np.abs(plan.command_at(grid)[:, j] - held) > math.radians(DEPARTURE_DEG)
    departs = float(grid[np.argmax(away)]) if away.any() else None
    detected = [f for f, _ in outcome.faults if f == joint]
    # The detection happens when the player handles the reading: when it arrives.
    found = trace[-1][1] if detected else None
    return {'excursion_deg': math.degrees(float(np.ptp(plan.positions[:, j]))),
            'departs_s': departs, 'detected': bool(detected),
            'wrong_joints': [f for f, _ in outcome.faults if f != joint],
            'latency_s': (found - departs) if detected and departs is not None else None,
            'reason': outcome.reason}


def calibrate(robot, library, sim):
    """
    Fit the tracking model on one exact, on-time healthy play of every gesture.

    A play during which the physics counted a self-contact is left out (the body, not
    the controller, stopped the arm).
    """
    plays, blocked = [], []
    exact = SuiteOptions(noise_deg=0.0, start_spread_deg=0.0)
    noise, sim.reading_noise = sim.reading_noise, 0.0
    for gesture in library:
        _start(sim, np.random.default_rng(0), 0.0)
        _, plan, trace = play(sim, robot, gesture, Arrival([], np.random.default_rng(0)),
                              exact)
        if sim.contact_events:
            blocked.append(gesture.name)
            continue
        plays.append((plan.command_at, np.array([0.0] + [t for t, _, _, _ in trace]),
                      np.vstack([plan.positions[0]] + [q for _, _, _, q in trace])))
    sim.reading_noise = noise
    delay, tau, worst = fit_tracking(plays)
    return {'delay_s': delay, 'time_constant_s': tau, 'worst_error_deg': math.degrees(worst),
            'left_out': blocked}


def run_library(robot, library, lateness, options, progress=None):
    """Run the normal and the stuck plays of one library; return its document."""
    from ..sim.physics import designed_allowances, NamoSim
    sim = NamoSim(robot, allowances=designed_allowances(robot, library))
    sim.set_reading_noise(math.radians(options.noise_deg), options.seed)
    rng = np.random.default_rng(options.seed)
    doc = {'normal': {}, 'stuck': {}}
    for gesture in library:
        runs = doc['normal'][gesture.name] = [
            normal_play(sim, robot, gesture, Arrival(lateness, rng), options, rng)
            for _ in range(options.reps)]
        stuck = doc['stuck'][gesture.name] = {
            joint: [stuck_play(sim, robot, gesture, joint, Arrival(lateness, rng), options,
                               rng) for _ in range(options.stuck_reps)]
            for joint in robot.joint_names}
        if progress:
            alarms = sum(bool(r['faults']) for r in runs)
            lat = [e['latency_s'] for v in stuck.values() for e in v if e['latency_s']]
            progress(f'{gesture.name:12s} {len(runs)} plays, {alarms} false alarms; stuck: '
                     f'max latency {max(lat, default=math.nan):.3f} s')
    return doc


def summary(doc, blocked=()):
    """Return the headline figures of one library-and-condition document."""
    normal = [r for runs in doc['normal'].values() for r in runs]
    clear = [r for g, runs in doc['normal'].items() if g not in blocked for r in runs]
    stuck = [e for g in doc['stuck'].values() for v in g.values() for e in v]
    stuck_clear = [e for g, joints in doc['stuck'].items() if g not in blocked
                   for v in joints.values() for e in v]
    exercised = [e for e in stuck if e['departs_s'] is not None]
    latency = [e['latency_s'] for e in exercised if e['latency_s'] is not None]
    gaps = [r['score_gap'] for r in normal]
    return {
        'normal_plays': len(normal),
        'false_alarm_plays': sum(bool(r['faults']) for r in normal),
        'clear_plays': len(clear),
        'false_alarm_plays_clear': sum(bool(r['faults']) for r in clear),
        'false_alarms_by_gesture': {g: sum(bool(r['faults']) for r in runs)
                                    for g, runs in doc['normal'].items()},
        'finished_within_goal_time': sum(r['ok'] for r in normal),
        'score_gap': {'median': common.percentile(gaps, 50),
                      'p95': common.percentile(gaps, 95), 'max': max(gaps, default=math.nan)},
        'contact_plays': sum(r['contact_events'] > 0 for r in normal),
        'max_lateness_s': max((r['max_lateness_s'] for r in normal), default=0.0),
        'stuck_runs': len(stuck),
        'exercised_runs': len(exercised),
        'detected': sum(e['detected'] for e in exercised),
        'missed': sum(not e['detected'] for e in exercised),
        'wrong_joint_reports': sum(len(e['wrong_joints']) for e in stuck),
        'wrong_joint_reports_clear': sum(len(e['wrong_joints']) for e in stuck_clear),
        'latency_s': {'n': len(latency), 'median': common.percentile(latency, 50),
                      'p95': common.percentile(latency, 95),
                      'max': max(latency, default=math.nan),
                      'within_target': sum(v <= TARGET_LATENCY_S for v in latency)},
    }


def measure_lateness(condition, seconds, domain_id=None):
    """Return the measured lateness (s) of readings under ``condition`` (idle, busy)."""
    import contextlib
    from .deadline import CpuBurner
    from ..ros.joint_state_stream import reading_lateness
    with (CpuBurner() if condition == 'busy' else contextlib.nullcontext()):
        return reading_lateness(seconds, domain_id)


def _lateness_stats(values):
    v = np.asarray(values, dtype=float)
    if not v.size:
        return {'n': 0}
    return {'n': int(v.size), 'median_ms': float(np.median(v) * 1e3),
            'p99_ms': float(np.percentile(v, 99) * 1e3), 'max_ms': float(v.max() * 1e3)}


def run_suite(robot, libraries, conditions, options, lateness, progress=None):
    """
    Run every (condition, library); return the JSON-ready document with summaries.

    ``libraries`` maps a label to a GestureLibrary; ``conditions`` are ``idle`` and/or
    ``busy``; ``lateness`` maps each condition to its measured reading lateness (s, in
    arrival order; see :func:`measure_lateness`), kept in the document.
    """
    began = time.monotonic()
    doc = {'rate_hz': RATE, 'noise_deg': options.noise_deg, 'reps': options.reps,
           'stuck_reps': options.stuck_reps, 'start_spread_deg': options.start_spread_deg,
           'monitor': {k: getattr(options.monitor, k) for k in (
               'fault_threshold', 'fault_hold', 'tracking_lag', 'tracking_delay',
               'tracking_time_constant', 'goal_tolerance', 'goal_time')},
           'calibration': {}, 'blocked': {}, 'conditions': {}}
    from ..sim.physics import designed_allowances, NamoSim
    for label, library in libraries.items():
        contacts = [reference_contact(robot, g) for g in library]
        doc['blocked'][label] = {c.gesture: {'keyframes': c.keyframes_touching,
                                             'pair': c.pair, 'depth_mm': c.depth_mm}
                                 for c in contacts if c is not None}
        doc['calibration'][label] = calibrate(robot, library, NamoSim(
            robot, allowances=designed_allowances(robot, library)))
    # Each library draws its own noise, start poses and lateness offsets (the two
    # libraries share gestures: the same draws would only repeat the same plays).
    seeds = {label: options.seed + 1000 * (list(LIBRARIES).index(label) if label in LIBRARIES
                                           else len(LIBRARIES)) for label in libraries}
    for condition in conditions:
        entry = doc['conditions'][condition] = {
            'lateness': _lateness_stats(lateness[condition]),
            'lateness_s': list(lateness[condition]), 'libraries': {}}
        for label, library in libraries.items():
            if progress:
                progress(f'--- {condition}, {label} library')
            plays = run_library(robot, library, lateness[condition],
                                replace(options, seed=seeds[label]), progress)
            entry['libraries'][label] = dict(plays, summary=summary(plays,
                                                                    doc['blocked'][label]))
    doc['wall_time_s'] = time.monotonic() - began
    return doc


def load_libraries(robot, labels, gesture_file=None):
    """Return {label: library} for ``labels`` of LIBRARIES (``gesture_file``: one more)."""
    out = {label: load_library(robot, config_path(LIBRARIES[label])) for label in labels}
    if gesture_file:
        out[str(gesture_file)] = load_library(robot, gesture_file)
    return out


def write_summary(out, doc):
    """Print the figures of a :func:`run_suite` document."""
    m = doc['monitor']
    out.write(f"\nmonitor: threshold {math.degrees(m['fault_threshold']):g} deg for "
              f"{m['fault_hold']:g} s, band {m['tracking_lag']:g} s, model delay "
              f"{m['tracking_delay']:g} s, time constant {m['tracking_time_constant']:g} s; "
              f"readings: noise {doc['noise_deg']:g} deg, {doc['rate_hz']:g} Hz\n")
    for label, fit in doc['calibration'].items():
        out.write(f'fitted on the {label} library (exact readings): delay '
                  f"{fit['delay_s']:g} s, time constant {fit['time_constant_s']:g} s, "
                  f"worst error {fit['worst_error_deg']:.3f} deg"
                  + (f" (left out, self-contact: {', '.join(fit['left_out'])})"
                     if fit['left_out'] else '') + '\n')
    for label, blocked in doc['blocked'].items():
        for g, b in blocked.items():
            out.write(f'library warning ({label}): the reference {g} grazes the body in '
                      f"{b['keyframes']} keyframes ({b['pair']}, {b['depth_mm']:.1f} mm; "
                      'deeper ones are refused when the library is loaded)\n')
    for condition, entry in doc['conditions'].items():
        lt = entry['lateness']
        out.write(f'\n{condition}: reading lateness over DDS ' + (
            f"median {lt['median_ms']:.2f} ms, p99 {lt['p99_ms']:.2f} ms, max "
            f"{lt['max_ms']:.2f} ms (n={lt['n']})\n" if lt['n'] else 'not measured (0)\n'))
        for label, lib in entry['libraries'].items():
            s = lib['summary']
            lat, gap = s['latency_s'], s['score_gap']
            alarms = ', '.join(f'{g} {n}' for g, n in s['false_alarms_by_gesture'].items()
                               if n)
            out.write(
                f"  {label}: false alarms {s['false_alarm_plays']} / {s['normal_plays']} "
                f"plays{' (' + alarms + ')' if alarms else ''}, of which on clear "
                f"references {s['false_alarm_plays_clear']} / {s['clear_plays']}; "
                'finished within goal time '
                f"{s['finished_within_goal_time']} / {s['normal_plays']}; plays with "
                f"self-contact {s['contact_plays']}; score gap median {gap['median']:.4f}, "
                f"max {gap['max']:.4f}\n"
                f"    stuck: {s['exercised_runs']} runs whose command leaves the joint by "
                f"{DEPARTURE_DEG:g} deg (of {s['stuck_runs']}): detected {s['detected']}, "
                f"missed {s['missed']}, wrong joint {s['wrong_joint_reports']} (on clear "
                f"references {s['wrong_joint_reports_clear']}); latency "
                f"median {lat['median']:.3f} s, p95 {lat['p95']:.3f} s, max {lat['max']:.3f}"
                f" s; within {TARGET_LATENCY_S:g} s: {lat['within_target']} / {lat['n']}\n")
    out.write(f"wall time {doc['wall_time_s']:.1f} s\n")
