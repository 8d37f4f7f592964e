"""
Watching a played motion on the measured joint states (no ROS).

:class:`StuckJointDetector` compares each joint's measured angle with what its
controller should have reached by now: the commanded trajectory passed through a
model of the controller's tracking (:class:`.tracking.TrackingModel`: a delay
``tracking_delay`` and a first-order lag ``tracking_time_constant``, measured once on a
healthy robot or the simulator with :func:`.tracking.fit_tracking`).  A joint's error is
the distance from its measured angle to the range of that prediction over the last
``tracking_lag`` seconds: the band absorbs what the model misses, chiefly the age of a
measurement (message latency, a busy executor), so that a late reading of a fast joint
is no error.  A joint off by more than ``fault_threshold`` for ``fault_hold`` seconds is
a fault when the other joints of its controller show that they track: at least one of
them (among those the motion moves by more than twice ``fault_threshold``) is
predicted, and was measured, away from its start by more than ``fault_threshold``, the
same way (it follows, even if it is off now), and no fewer follow than are off without
having followed (when a whole arm stays put, the arm or its controller is at fault, not
one actuator); its time off counts from the first reading that shows one of them
following (a controller that takes a motion on late leaves them all behind until
then).  A joint that moves alone in a motion is judged alone.  Of the joints of
one controller found in the same reading, only the one furthest off is reported: a
stuck shoulder can bring the forearm against the torso, and the body then holds the
healthy joints it pushes a few degrees off as well; they are judged again, in the motion
that follows the report.
:class:`Playback` adds the end of a play: finished when every joint is within
``goal_tolerance`` of the last point after the motion's duration, failed on a fault or
when ``goal_time`` has passed with a joint still off its goal.
"""

from dataclasses import dataclass
import math

import numpy as np

from .tracking import TrackingModel


# The defaults (the gesture_player's parameters): the tracking model is the simulator's,
# measured by ``namo-recovery bench detection`` (it fits and prints them); the threshold,
# hold and band are chosen with that benchmark's false alarms and detection times.
FAULT_THRESHOLD_DEG = 2.0
FAULT_HOLD = 0.1
TRACKING_LAG = 0.05
TRACKING_DELAY = 0.005
TRACKING_TIME_CONSTANT = 0.0
PRESSED_STEP = 0.02       # s: the grid on which a command's body contact is checked
WITNESS_FACTOR = 2.0      # a joint moved by this many thresholds can show its arm tracks


@dataclass(frozen=True)
class MonitorThresholds:
    """Detection and completion parameters (named as the node parameters)."""

    fault_threshold: float = math.radians(FAULT_THRESHOLD_DEG)   # rad off the prediction
    fault_hold: float = FAULT_HOLD                # s continuously off
    tracking_lag: float = TRACKING_LAG            # s: band of the prediction a reading may lag
    goal_tolerance: float = math.radians(2.0)     # rad: the last point is reached
    goal_time: float = 2.0                        # s allowed after the motion's duration
    tracking_delay: float = TRACKING_DELAY        # s: the controller's delay (measured)
    tracking_time_constant: float = TRACKING_TIME_CONSTANT   # s: its first-order lag

    def __post_init__(self):
        """Refuse values that would make detection meaningless."""
        for name in ('fault_threshold', 'fault_hold', 'goal_tolerance', 'goal_time'):
            if not getattr(self, name) > 0:
                raise ValueError(f'{name} must be > 0, got {getattr(self, name)}')
        for name in ('tracking_lag', 'tracking_delay', 'tracking_time_constant'):
            if not getattr(self, name) >= 0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)}')


class StuckJointDetector:
    """Detect joints that do not follow their command, from measured samples."""

    def __init__(self, joint_names, groups, command, duration,
                 thresholds=MonitorThresholds(), pressed=None):
        """
        Watch ``joint_names`` (the columns of the measured samples).

        ``pressed(poses)``, if given, returns (n, J) bool for commanded poses (n, J):
        the joints whose arm the command itself drives into the body (e.g.
        :func:`..model.self_contact.pressed_joints`); while it does, the body, not an
        actuator, holds them, and they are not judged.

        ``groups`` lists the joint names of each controller; ``command(t)`` returns the
        commanded pose (J,) at time ``t`` or (n, J) at times (n,), for a motion of
        ``duration`` seconds.
        """
        self.joint_names = tuple(joint_names)
        self.thresholds = thresholds
        self._command = command
        index = {j: i for i, j in enumerate(self.joint_names)}
        self._group_of = {}
        for group in groups:
            members = [index[j] for j in group if j in index]
            for i in members:
                self._group_of[i] = [m for m in members if m != i]
        whole = np.atleast_2d(command(np.linspace(0.0, duration, 200)))
        self._start = whole[0]       # replaced by the first reading (the model's start)
        # A witness that its controller tracks must move clearly beyond the threshold:
        # one that barely crosses it (a few degrees of a correction) may never show it.
        self._movers = np.ptp(whole, axis=0) > WITNESS_FACTOR * thresholds.fault_threshold
        self._moved = np.zeros(len(self.joint_names), dtype=bool)
        self._moved_at = np.full(len(self.joint_names), math.inf)   # when first _moved
        self.model = TrackingModel(command, thresholds.tracking_delay,
                                   thresholds.tracking_time_constant, thresholds.tracking_lag)
        self._pressed = None
        if pressed is not None:
            self._grid = np.arange(0.0, duration + PRESSED_STEP, PRESSED_STEP)
            self._pressed = np.asarray(pressed(np.atleast_2d(command(self._grid))), bool)
        self._started = False
        self._off_since = {}
        self.reported = {}      # joint name -> (time, measured angle)

    def errors(self, t, measured):
        """
        Return each joint's distance (rad) to the band of its predicted angle at ``t``.

        The first call starts the model from ``measured``; later calls must not go back
        in time (an older ``t`` is judged against the band of the newest).
        """
        q = np.asarray(measured, dtype=float)
        if not self._started:
            self.model.reset(t, q)
            self._start = q.copy()    # moves are measured from where the arm was read
            self._started = True
        self.model.advance(t)
        low, high = self.model.band()
        return np.maximum(0.0, np.maximum(low - q, q - high))

    def update(self, t, measured):
        """Feed one measured pose at time ``t``; return the newly detected faults."""
        errors = self.errors(t, measured)
        off = errors > self.thresholds.fault_threshold
        limit = self.thresholds.fault_threshold
        predicted = self.model.at(t) - self._start
        went = np.asarray(measured, dtype=float) - self._start
        self._moved |= (np.abs(predicted) > limit) & (np.abs(went) > limit) & \
            (np.sign(predicted) == np.sign(went))
        self._moved_at[self._moved & np.isinf(self._moved_at)] = t
        found = []
        excused = self._pressed_now(t)
        for i, name in enumerate(self.joint_names):
            if not off[i] or excused[i]:
                self._off_since.pop(i, None)
                continue
            # Off counts from when its controller is seen playing the motion: one that
            # took it on late (a busy controller joins a stamped motion mid-way, then
            # catches up) leaves every joint behind until then.
            since = max(self._off_since.setdefault(i, t), self._taken_on(i))
            if name in self.reported or t - since < self.thresholds.fault_hold - 1e-9:
                continue
            if self._others_track(i, off):
                found.append(i)
        new = []
        for i in found:
            rivals = [k for k in found if k in self._group_of.get(i, ())]
            if any(errors[k] > errors[i] or (errors[k] == errors[i] and k < i)
                   for k in rivals):
                continue         # another joint of its controller is further off
            name = self.joint_names[i]
            self.reported[name] = (t, float(measured[i]))
            new.append((name, float(measured[i])))
        return new

    def _pressed_now(self, t):
        """Return (J,) bool: joints the command pressed into the body over the last hold."""
        if self._pressed is None:
            return np.zeros(len(self.joint_names), dtype=bool)
        span = self.thresholds.fault_hold + self.thresholds.tracking_lag
        near = (self._grid >= t - span - PRESSED_STEP) & (self._grid <= t + PRESSED_STEP)
        if not near.any():
            return self._pressed[-1] if t > self._grid[-1] else self._pressed[0]
        return self._pressed[near].any(axis=0)

    def _taken_on(self, i):
        """Return when another joint of ``i``'s controller first followed (0: none moves)."""
        movers = [k for k in self._group_of.get(i, []) if self._movers[k]]
        return min((self._moved_at[k] for k in movers), default=0.0)

    def _others_track(self, i, off):
        movers = [k for k in self._group_of.get(i, []) if self._movers[k]]
        if not movers:
            return True
        following = sum(1 for k in movers if self._moved[k])
        failing = sum(1 for k in movers if off[k] and not self._moved[k])
        return following >= 1 and following >= failing


@dataclass(frozen=True)
class Outcome:
    """How a play ended: ``ok``, a one-line ``reason``, and the faults it detected."""

    ok: bool
    reason: str
    faults: tuple = ()


class Playback:
    """One play of a planned motion: feed measured poses, get an Outcome once it ends."""

    def __init__(self, plan, groups, thresholds=MonitorThresholds(), pressed=None):
        """Watch ``plan`` (a PlannedMotion) whose joints are split into ``groups``."""
        self.plan = plan
        self.thresholds = thresholds
        self.detector = StuckJointDetector(plan.joint_names, groups, plan.command_at,
                                           plan.duration, thresholds, pressed)
        self.outcome = None
        self.faults = []

    def update(self, t, measured):
        """Feed the measured pose (in the plan's joint order) ``t`` s after the start."""
        if self.outcome is not None:
            return self.outcome
        measured = np.asarray(measured, dtype=float)
        new = self.detector.update(t, measured)
        if new:
            self.faults.extend(new)
            text = ', '.join(f'{j} held at {math.degrees(a):.1f} deg' for j, a in new)
            self.outcome = Outcome(False, f'actuator fault detected: {text}', tuple(new))
            return self.outcome
        if t < self.plan.duration:
            return None
        off = np.abs(measured - self.plan.final)
        if np.all(off <= self.thresholds.goal_tolerance):
            self.outcome = Outcome(True, f'finished in {t:.2f} s (planned '
                                   f'{self.plan.duration:.2f} s, stretch {self.plan.stretch:.2f})')
        elif t > self.plan.duration + self.thresholds.goal_time:
            worst = int(np.argmax(off))
            self.outcome = Outcome(False, f'timeout: {self.plan.joint_names[worst]} still '
                                   f'{math.degrees(off[worst]):.1f} deg off its goal '
                                   f'{self.thresholds.goal_time:g} s after the end of the motion')
        return self.outcome

    def abort(self, reason):
        """End the play as failed (a rejected goal, a shutdown, a newer play)."""
        if self.outcome is None:
            self.outcome = Outcome(False, reason)
        return self.outcome
