"""
Noticing a change the model does not know: the tracked fingertip leaves the designed path.

While a gesture plays, each tracked fingertip sample (``msg_docs/fingertip_tracker.md``)
is compared, at its *capture* stamp, with two predictions of the planner's own model:

- the **designed path**: the model's FK of the planned joints at the moment of the play
  that the arm is really at.  A controller runs behind its command (a little always, and
  more on a loaded machine, or when the simulator falls behind real time), so that
  moment is read off the measured joints: the time, within the last ``max_lag_s`` of the
  commanded motion, whose commanded joints are nearest the measured ones.  The distance
  is then taken to the nearest designed fingertip over the ``lag_s`` before it (as the
  joint monitor does with ``tracking_lag_sec``).  A structure change moves the fingertip,
  not the joints, so it keeps its full distance; only a lag is taken out.  An explored
  version is timed by its own joints (another approach, other segments slowed down), so
  its moment maps to the design's keyframe for keyframe;
- the **model's fingertip for the measured joints**: FK of the joint angles measured at
  the capture stamp (interpolated between ``/joint_states``).  A stuck joint or a lag
  moves the fingertip off the designed path *and* the joints off their command; the
  model then still explains the fingertip, so it is not a structure change (the joint
  monitor names a stuck joint).  A tool, a bent link, an encoder offset or a longer link
  leave the joints on their command while the fingertip is elsewhere: the model cannot
  explain it.

A sample deviates by the smaller of the two distances.  The change is *suspected* for
an arm when, over the last ``sustain_s`` of capture time (a full window, with at least
``min_samples`` samples, so dropouts only delay the decision), at least ``share`` of the
samples deviate by more than ``threshold_mm``.  Noise (a few mm) and single outliers do
not make a window; a real change of more than the threshold makes every one.  Once
suspected, an arm is not reported again during that play.
"""

from collections import deque
from dataclasses import dataclass
import math

import numpy as np

from ..model.kinematics import forward_kinematics

_JOINT_HISTORY = 400        # joint states kept (4 s at 100 Hz)
_JOINT_GAP = 0.1            # s: a joint state further than this from a capture is no use


@dataclass(frozen=True)
class DeviationThresholds:
    """When a deviation is a suspected change (the player's ``structure_*`` parameters)."""

    threshold_mm: float = 10.0
    sustain_s: float = 0.5
    lag_s: float = 0.1
    share: float = 0.8
    min_samples: int = 5
    max_lag_s: float = 1.0       # the most the arm is taken to run behind its command

    def __post_init__(self):
        """Refuse thresholds that cannot decide (one line naming the value)."""
        for name, ok in (('threshold_mm', self.threshold_mm > 0),
                         ('sustain_s', self.sustain_s > 0), ('lag_s', self.lag_s >= 0),
                         ('max_lag_s', self.max_lag_s >= 0),
                         ('share', 0.0 < self.share <= 1.0),
                         ('min_samples', self.min_samples >= 1)):
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ValueError(f'structure change {name}: {value!r}; expected a '
                                 'positive number (share in (0, 1])')


@dataclass(frozen=True)
class Suspicion:
    """A suspected structure change of one arm, as the window that confirmed it saw it."""

    side: str
    error_mm: float          # median distance to the designed path over the window
    unexplained_mm: float    # median distance to the model's fingertip of the measured joints
    stamp: float             # capture stamp of the sample that completed the window (s)
    play_time: float         # that moment in the play (s from the start of the motion)
    samples: int

    def describe(self) -> str:
        """Return e.g. ``right arm 49.8 mm off its designed path``."""
        return f'{self.side} arm {self.error_mm:.1f} mm off its designed path'


class DeviationWatch:
    """
    Watch one play: feed it joint states and tracked fingertips; it returns a Suspicion.

    ``plan`` is the player's :class:`~.timing.PlannedMotion` of the designed path;
    ``start`` the stamp (s, the clock of the tracker's stamps) at which the motion
    started.  ``played`` is the motion the controllers were sent, timed as ``plan`` (an
    explored version of it; None: ``plan`` itself): the measured joints are compared
    with it to tell where in the play the arm is.  Arms whose joints the plan does not
    all hold are not watched.
    """

    def __init__(self, robot, plan, start: float,
                 thresholds: DeviationThresholds = DeviationThresholds(), begin: float = 0.0,
                 played=None):
        """Watch ``plan`` from ``begin`` s into it (samples captured earlier are ignored)."""
        self.robot, self.start, self.thresholds = robot, float(start), thresholds
        self.begin = float(begin)
        self.duration = plan.duration
        self.times = np.asarray(plan.times, dtype=float)
        self.plan, self.played = plan, plan if played is None else played
        self.joints, self.designed, self._played_columns = {}, {}, {}
        for side, arm in robot.arms.items():
            if all(j in plan.joint_names for j in arm.joint_names) and \
                    all(j in self.played.joint_names for j in arm.joint_names):
                self.joints[side] = list(arm.joint_names)
                self._played_columns[side] = [self.played.joint_names.index(j)
                                              for j in arm.joint_names]
                q = plan.columns(arm.joint_names)[0]
                self.designed[side] = forward_kinematics(robot, q, side).tip
        self._states = deque(maxlen=_JOINT_HISTORY)      # (stamp, {joint: angle})
        self._samples = {side: deque() for side in self.designed}
        self._seen = dict.fromkeys(self.designed)      # first capture in the play
        self.suspected = {}

    def joint_state(self, stamp: float, names, positions) -> None:
        """Record one measured joint state (stamp in s, angles in rad)."""
        self._states.append((float(stamp), dict(zip(names, map(float, positions)))))

    def designed_distance(self, side: str, t: float, point) -> float:
        """Return the distance (mm) from ``point`` to the designed path over [t - lag, t]."""
        tips, times = self.designed[side], self.times
        lo, hi = min(max(t - self.thresholds.lag_s, 0.0), self.duration), \
            min(max(t, 0.0), self.duration)
        inside = (times > lo) & (times < hi)
        ends = np.array([[np.interp(x, times, tips[:, k]) for k in range(3)]
                         for x in (lo, hi)])
        path = np.vstack([ends, tips[inside]])
        return float(np.min(np.linalg.norm(path - np.asarray(point, float), axis=1)))

    def measured_joints(self, side: str, stamp: float):
        """Return the arm's measured joints (rad) at ``stamp``, interpolated, or None."""
        before = after = None
        for entry in self._states:
            if entry[0] <= stamp:
                before = entry
            elif after is None:
                after = entry
        near = [e for e in (before, after) if e is not None and abs(e[0] - stamp) < _JOINT_GAP]
        if not near or any(j not in e[1] for e in near for j in self.joints[side]):
            return None
        if len(near) == 2 and after[0] > before[0]:
            w = (stamp - before[0]) / (after[0] - before[0])
            return np.array([(1 - w) * before[1][j] + w * after[1][j]
                             for j in self.joints[side]])
        return np.array([near[0][1][j] for j in self.joints[side]])

    def executed_time(self, side: str, t: float, q) -> float:
        """
        Return the moment of the play (s) the arm is at: ``t``, less its lag behind command.

        The time within the last ``max_lag_s`` of the commanded motion whose commanded
        joints are nearest the measured ``q`` (10 ms steps; the latest of equals).
        """
        grid = np.arange(t, max(t - self.thresholds.max_lag_s, 0.0) - 1e-9, -0.01)
        if grid.size < 2:
            return t
        commanded = self.played.command_at(grid)[:, self._played_columns[side]]
        return float(grid[np.argmin(np.linalg.norm(commanded - q, axis=1))])

    def design_time(self, t: float) -> float:
        """
        Return the moment of the design that the played motion's moment ``t`` (s) plays.

        An explored version is timed by its own joints: its approach (from wherever the
        last trial left the arm) and its segments (slowed down where its joints would
        pass their speed limits) take other times than the design's.  Keyframe for
        keyframe it is the same motion, so the time maps through the keyframe times
        (identity when the two have different keyframes, or are one motion).
        """
        ours, theirs = self.played.waypoint_times, self.plan.waypoint_times
        if self.played is self.plan or len(ours) != len(theirs):
            return t
        u = np.interp(t, ours, np.arange(len(ours)))
        return float(np.interp(u, np.arange(len(theirs)), theirs)) + \
            max(t - ours[-1], 0.0)

    def explained_distance(self, side: str, q, point) -> float:
        """Return the distance (mm) from ``point`` to the model's fingertip at joints ``q``."""
        tip = forward_kinematics(self.robot, q, side).tip
        return float(np.linalg.norm(tip - np.asarray(point, float)))

    def fingertip(self, side: str, stamp: float, point_mm) -> Suspicion | None:
        """Take one tracked sample (capture stamp in s, point in mm); return a new Suspicion."""
        t = stamp - self.start
        if side not in self.designed or side in self.suspected:
            return None
        q = self.measured_joints(side, stamp)
        at = self.design_time(t if q is None else self.executed_time(side, t, q))
        if at < self.begin:
            return None
        designed = self.designed_distance(side, at, point_mm)
        explained = None if q is None else self.explained_distance(side, q, point_mm)
        value = designed if explained is None else min(designed, explained)
        samples = self._samples[side]
        samples.append((stamp, value, designed, designed if explained is None else explained))
        if self._seen[side] is None:
            self._seen[side] = stamp
        cut = stamp - self.thresholds.sustain_s
        while samples and samples[0][0] <= cut:
            samples.popleft()
        if self._seen[side] > cut or len(samples) < self.thresholds.min_samples:
            return None
        values = np.array([s[1] for s in samples])
        if np.mean(values > self.thresholds.threshold_mm) < self.thresholds.share:
            return None
        found = Suspicion(side, float(np.median([s[2] for s in samples])),
                          float(np.median([s[3] for s in samples])), float(stamp), float(t),
                          len(samples))
        self.suspected[side] = found
        return found
