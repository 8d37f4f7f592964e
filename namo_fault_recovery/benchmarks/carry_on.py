"""
``namo-recovery bench carry-on``: a joint sticks mid-gesture, the arm gets back on track.

For every gesture x joint, the player's own play (:class:`..playback.carry.CarryOn`:
planning, detection, hold, blend) drives the simulator's MuJoCo core
(:class:`..sim.physics.NamoSim`) in this process, in lock-step with a 100 Hz command and
measurement loop, as ``bench detection`` does.  The gesture is played from rest; the
joint sticks where it is at the moment its commanded speed peaks (mid-motion, moving);
the player detects it and holds it; the library is reconfigured by the engine in this
process (:func:`..recovery.engine.recover` with the node's settings and 1 s deadline,
warmed up and with its typical points kept, as the node's engine process does), and the
simulated arm goes on with the old motion (the joint held) for the engine's real wall
time before the new library is offered to the play, which then blends onto it.

Per case: the time from the stick to the first measured pose within the goal tolerance
of the reconfigured trajectory at the current phase (``stuck_to_back_s``), and its
parts (detection, reconfiguration, blend); whether the play finished; how many
commanded points moved the stuck joint after the fault was detected (0 expected); the
executed-vs-planned score gap at the final keyframe; and the self-contacts the physics
counted.  A joint that the gesture moves by less than 1.5 x the fault threshold after
the stick is not exercised (it cannot be told from a healthy one, and the play is right
without carrying on).  Exercised cases that never get back on the trajectory count as
infinitely long in the percentiles.  Not included: DDS latency (``bench latency``:
milliseconds), and ``recovery_node``'s own handling around the engine.
"""

import contextlib
import functools
import math
import time

import numpy as np

from .common import percentile
from .deadline import CpuBurner
from ..model.self_contact import pressed_joints
from ..objective.score import ScoreWeights, SimilarityScore
from ..playback.blend import BlendLimits
from ..playback.carry import CarryOn
from ..playback.clearance import PathClearance
from ..playback.monitor import MonitorThresholds
from ..playback.timing import plan_motion, PlayTiming

RATE = 100.0                    # Hz: command and measurement loop
ACCELERATION = math.radians(600.0)   # rad/s^2: the player's default acceleration_limit_deg
WAIT = 3.0                      # s: the player's default carry_on_wait_sec
LIMIT = 30.0                    # s of simulated time per case at most
TARGET_P95 = 1.0                # s: the target, stuck -> back on trajectory


def keyframe_arrays(times, positions):
    """Return (times (K,), frames (K, 14)) as float arrays."""
    return np.asarray(times, dtype=float), np.atleast_2d(np.asarray(positions, dtype=float))


class Reconfigurer:
    """The engine as the node runs it: warmed up, typical points kept, real wall time."""

    def __init__(self, robot, library, deadline=1.0, seed=0):
        """Warm the engine up on ``library`` (a run with a first-arm joint locked)."""
        from ..recovery.engine import recover, RecoverySettings
        from ..recovery.motion import typical_points
        self.robot, self.library, self.seed = robot, library, seed
        self.settings = RecoverySettings(deadline_sec=deadline)
        self._recover = recover
        self.quantisations = typical_points(robot, library, self.settings.vq_distortion_mm)
        self({robot.joint_names[0]: None})

    def __call__(self, faults):
        """
        Return (result, wall time s) of reconfiguring for ``faults`` {joint: angle}.

        The angles are read as the node reads a fault report (:func:`..runtime.inputs.
        parse_fault`): one measured a little past its stop (the physics overshoots it)
        is clamped onto the limit, one further off is refused (BadInput); None (NaN in a
        report) leaves the angle to the lock strategy.
        """
        from ..runtime.inputs import parse_fault
        faults = parse_fault(self.robot, list(faults),
                             [math.nan if a is None else a for a in faults.values()])
        began = time.monotonic()
        result = self._recover(self.robot, self.library, faults, self.settings,
                               seed=self.seed, quantisations=self.quantisations)
        return result, time.monotonic() - began


def stick_time(plan, column):
    """Return the time at which ``column``'s commanded speed peaks (the middle of a move)."""
    t = np.linspace(0.0, plan.duration, 400)
    return float(t[int(np.argmax(np.abs(plan.velocity_at(t)[:, column])))])


def _score(robot, gesture, q14):
    scorer = SimilarityScore.for_gesture(robot, gesture, len(gesture.keyframes) - 1,
                                         ScoreWeights())
    return float(scorer(np.asarray(q14[:7]), np.asarray(q14[7:]))[0])


class Bench:
    """What every case shares: the robot, the planner, the limits and the thresholds."""

    def __init__(self, robot, library, sim, reconfigure, monitor=MonitorThresholds(),
                 timing=PlayTiming(), acceleration=ACCELERATION, wait=WAIT):
        """Keep the models, the simulator and the engine wrapper."""
        self.robot, self.library, self.sim = robot, library, sim
        self.reconfigure, self.monitor, self.timing = reconfigure, monitor, timing
        self.names = list(robot.joint_names)
        self.velocity = np.array(robot.joint_velocity_limits, dtype=float)
        self.lower = np.concatenate([robot.arms[s].lower for s in ('right', 'left')])
        self.upper = np.concatenate([robot.arms[s].upper for s in ('right', 'left')])
        self.limits = BlendLimits(self.velocity, np.full(len(self.names), acceleration))
        self.clearance = PathClearance(robot, self.names)      # the player's clear_path
        self.wait = wait

    def plan(self, times, frames, start, locks):
        """Time keyframes as the player does (the CarryOn planner)."""
        return plan_motion(self.names, start, times, frames, self.velocity, locks=locks,
                           lower=self.lower, upper=self.upper, timing=self.timing,
                           clearance=self.clearance)

    def session(self, plan):
        """Return the player's CarryOn for ``plan``."""
        return CarryOn(plan, [self.names[:7], self.names[7:]], self.monitor, self.plan,
                       self.limits, self.wait, self.timing.sample_period,
                       functools.partial(pressed_joints, self.robot, self.names))

    def case(self, name, joint):
        """Play ``name`` from rest, stick ``joint`` mid-motion; return the case's figures."""
        times, frames = keyframe_arrays(*_arrays(self.library[name]))
        j = self.names.index(joint)
        plan = self.plan(times, frames, np.zeros(len(self.names)), {})
        t_stick = stick_time(plan, j)
        later = plan.command_at(np.linspace(t_stick, plan.duration, 200))[:, j]
        travel = float(np.max(np.abs(later - later[0])))
        entry = {'stick_s': t_stick, 'travel_after_deg': math.degrees(travel),
                 'exercised': travel > 1.5 * self.monitor.fault_threshold}
        if not entry['exercised']:
            return entry
        for k in list(self.sim.stuck):
            self.sim.release(k)
        self.sim.set_positions(np.zeros(len(self.names)))
        self.sim.reset_contact_count()
        entry.update(self._run(name, joint, plan, t_stick))
        return entry

    def _run(self, name, joint, plan, t_stick):
        """Run the lock-step loop of one case; return its figures."""
        sim, j = self.sim, self.names.index(joint)
        session = self.session(plan)
        steps = max(1, int(round(1.0 / (RATE * sim.timestep))))
        sent, sent_at, t = plan, 0.0, 0.0
        run = {'stuck_at_s': None, 'detected_s': None, 'engine_s': None, 'pending': None,
               'held_elsewhere': 0, 'wrong_joints': [], 'adapted': None}
        outcome = None
        while outcome is None and t < LIMIT:
            if run['stuck_at_s'] is None and t >= t_stick:
                sim.stick(joint)
                run['stuck_at_s'] = t
            tau = min(t - sent_at, sent.duration)
            moving = t - sent_at < sent.duration
            sim.set_targets(sent.command_at(tau),
                            sent.velocity_at(tau) if moving else np.zeros(len(self.names)))
            sim.step(steps)
            t += steps * sim.timestep
            pending = run['pending']
            if pending is not None and t >= pending[0]:
                session.offer(pending[1], pending[2], 'engine')
                run['pending'] = None
            step = session.update(t, sim.positions(), sim.velocities())
            self._faults(run, step.faults, session.holds, name, joint, t)
            if step.send is not None:
                sent, sent_at = step.send, t
                if run['detected_s'] is not None:
                    run['held_elsewhere'] += int(np.count_nonzero(
                        sent.positions[:, j] != session.holds.get(joint)))
            outcome = step.outcome or session.expire(t)
        return self._figures(name, session, outcome, run, t)

    def _faults(self, run, faults, holds, name, joint, t):
        """
        Reconfigure for the held joints after a detection, as recovery_node does.

        The library reaches the play after the engine's wall time.  A healthy joint
        reported (a wrong detection) is reconfigured for too, as the node would.
        """
        if not faults:
            return
        run['wrong_joints'] += [f for f, _ in faults if f != joint]
        if run['detected_s'] is None and any(f == joint for f, _ in faults):
            run['detected_s'] = t
        result, wall = self.reconfigure(dict(holds))
        adapted = next(g for g in result.gestures if g.name == name)
        run['engine_s'] = wall if run['engine_s'] is None else run['engine_s'] + wall
        run['adapted'] = adapted
        run['pending'] = (t + wall,) + keyframe_arrays(adapted.times, adapted.positions)

    def _figures(self, name, session, outcome, run, t):
        stuck, back = run['stuck_at_s'], session.back_at
        switch = next((when for when, kind, _ in session.events if kind == 'switch'), None)
        fig = {'ok': bool(outcome is not None and outcome.ok),
               'reason': outcome.reason if outcome else f'no outcome within {LIMIT:g} s',
               'stuck_at_s': stuck, 'detected_s': run['detected_s'],
               'engine_s': run['engine_s'], 'switch_s': switch, 'back_s': back,
               'blend_s': session.blend_duration,
               'stuck_to_back_s': back - stuck if back is not None else math.inf,
               'detection_after_stick_s': (run['detected_s'] - stuck
                                           if run['detected_s'] is not None else None),
               'switch_to_back_s': back - switch if back is not None and switch else None,
               'stuck_to_end_s': t - stuck if fig_ok(outcome) else math.inf,
               'held_elsewhere': run['held_elsewhere'], 'wrong_joints': run['wrong_joints'],
               'contact_events': self.sim.contact_events, 'elapsed_s': t}
        if run['adapted'] is not None:
            gesture = self.library[name]
            planned = _score(self.robot, gesture, run['adapted'].positions[-1])
            executed = _score(self.robot, gesture, self.sim.positions())
            fig.update(planned_score=planned, executed_score=executed,
                       score_gap=abs(executed - planned))
        return fig


def fig_ok(outcome):
    """Return True if a play ended, and ended well."""
    return outcome is not None and outcome.ok


def _arrays(gesture):
    return ([kf.time_from_start for kf in gesture.keyframes],
            [kf.positions() for kf in gesture.keyframes])


def run(bench, gestures=None, joints=None, progress=None):
    """Run every gesture x joint case; return {gesture: {joint: figures}}."""
    doc = {}
    for name in gestures or bench.library.names:
        for joint in joints or bench.names:
            entry = doc.setdefault(name, {})[joint] = bench.case(name, joint)
            if progress and entry['exercised']:
                progress(f"{name:12s} {joint:17s} stuck at {entry['stuck_at_s']:.2f} s -> "
                         f"back {entry['stuck_to_back_s']:.2f} s later (detection "
                         f"{_fmt(entry['detection_after_stick_s'])}, engine "
                         f"{_fmt(entry['engine_s'])}, blend {_fmt(entry['blend_s'])}); "
                         f"{'finished' if entry['ok'] else 'FAILED: ' + entry['reason']}")
    return doc


def _fmt(value):
    return '-' if value is None else f'{value:.2f} s'


def _rank(values, q):
    return float(np.percentile(values, q, method='higher')) if values else None


def summary(doc):
    """Return the headline figures of a :func:`run` document."""
    cases = [e for g in doc.values() for e in g.values()]
    done = [e for e in cases if e['exercised']]
    back = [e['stuck_to_back_s'] for e in done]

    def stats(key, detected=False):
        values = [e[key] for e in done if e.get(key) is not None
                  and (not detected or e.get('detected_s') is not None)]
        if not values:
            return None
        return {'n': len(values), 'median': percentile(values, 50),
                'p95': percentile(values, 95), 'max': float(np.max(values))}
    return {
        'cases': len(cases), 'exercised': len(done),
        'finished': sum(e['ok'] for e in done),
        'back_on_trajectory': sum(math.isfinite(v) for v in back),
        # nearest rank, upwards: an exercised case never back (inf) counts as such
        'stuck_to_back_s': {'n': len(back),
                            'median': _rank(back, 50), 'p95': _rank(back, 95),
                            'max': float(np.max(back)) if back else None},
        'stuck_to_back_detected_s': stats('stuck_to_back_s', detected=True),
        'detected': sum(e.get('detected_s') is not None for e in done),
        'detection_after_stick_s': stats('detection_after_stick_s'),
        'engine_s': stats('engine_s'), 'blend_s': stats('blend_s'),
        'stuck_to_end_s': stats('stuck_to_end_s'),
        'switch_to_back_s': stats('switch_to_back_s'),
        'held_elsewhere': sum(e.get('held_elsewhere', 0) for e in done),
        'wrong_joint_reports': sum(len(e.get('wrong_joints', ())) for e in done),
        'score_gap_max': max((e['score_gap'] for e in done if 'score_gap' in e),
                             default=None),
        'contact_events': sum(e.get('contact_events', 0) for e in done),
    }


def run_on_sim(robot, library, gestures=None, joints=None, busy=False, deadline=1.0,
               seed=0, progress=None, **options):
    """
    Return the document of :func:`run` on the simulator's physics, with its summary.

    ``busy`` runs it with a CPU burner on the other core; ``options`` go to
    :class:`Bench` (``monitor``, ``timing``, ``acceleration``, ``wait``).
    """
    from ..sim.physics import designed_allowances, NamoSim
    began = time.monotonic()
    with (CpuBurner() if busy else contextlib.nullcontext()):
        reconfigure = Reconfigurer(robot, library, deadline, seed)
        sim = NamoSim(robot, allowances=designed_allowances(robot, library))
        bench = Bench(robot, library, sim, reconfigure, **options)
        cases = run(bench, gestures, joints, progress)
    return {'rate_hz': RATE, 'busy': bool(busy), 'deadline_sec': deadline,
            'acceleration_limit_deg': math.degrees(bench.limits.acceleration[0]),
            'carry_on_wait_sec': bench.wait,
            'threshold_deg': math.degrees(bench.monitor.fault_threshold),
            'goal_tolerance_deg': math.degrees(bench.monitor.goal_tolerance),
            'cases': cases, 'summary': summary(cases),
            'wall_time_s': time.monotonic() - began}


def write_summary(out, doc):
    """Print the figures of a :func:`run_on_sim` document."""
    s = doc['summary']
    b = s['stuck_to_back_s']
    condition = 'busy (CPU burner on the other core)' if doc['busy'] else 'idle'
    out.write(f'\n{condition}: {s["cases"]} gesture x joint cases, {s["exercised"]} '
              f'exercised (the joint moves > 1.5 x {doc["threshold_deg"]:g} deg after the '
              f'stick); finished {s["finished"]}, back on the reconfigured trajectory '
              f'{s["back_on_trajectory"]}\n')
    if b['n']:
        verdict = 'met' if b['p95'] <= TARGET_P95 else 'NOT met'
        out.write(f'stuck -> back on the reconfigured trajectory (within '
                  f'{doc["goal_tolerance_deg"]:g} deg): median {b["median"]:.2f} s, p95 '
                  f'{b["p95"]:.2f} s, max {b["max"]:.2f} s (target p95 <= {TARGET_P95:g} s:'
                  f' {verdict})\n')
    out.write(f'detected {s["detected"]} of {s["exercised"]}\n')
    for key, label in (('stuck_to_back_detected_s', 'stuck -> back, the detected cases'),
                       ('detection_after_stick_s', 'detection after the stick'),
                       ('engine_s', 'reconfiguration (engine wall time)'),
                       ('blend_s', 'blend duration'),
                       ('switch_to_back_s', 'switch -> back on the trajectory'),
                       ('stuck_to_end_s', 'stuck -> the end of the (carried-on) play')):
        v = s[key]
        if v:
            out.write(f"  {label}: median {v['median']:.2f} s, p95 {v['p95']:.2f} s, max "
                      f"{v['max']:.2f} s (n={v['n']})\n")
    gap = s['score_gap_max']
    gap = '-' if gap is None else f'{gap:.4f}'
    out.write(f'stuck joint commanded away after detection: {s["held_elsewhere"]} points; '
              f'wrong joint reported {s["wrong_joint_reports"]}; executed-vs-planned score '
              f'gap max {gap}; self-contact events {s["contact_events"]}\n')
    out.write(f"wall time {doc['wall_time_s']:.1f} s\n")
