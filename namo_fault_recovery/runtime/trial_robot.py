"""
A :class:`~..explore.trial.TrialRobot` behind the nodes: one arm's controller, its tracker.

A trial commands one pose on the arm's trajectory controller (one point, reached in the
trial's duration), waits for the move to end and the arm to settle (every joint of the
arm slower than ``still_deg_s`` in ``/joint_states``, or ``max_settle_sec``), then takes
the next ``samples`` fingertip readings of the tracker (``msg_docs/fingertip_tracker.md``)
whose *capture* stamps are after the settled reading, and returns their mean with the
arm's joint readings over the same span.  It never runs in a callback: the explorer's
worker thread calls :meth:`RosTrialRobot.trial`, which waits on a condition that the
node's subscription callbacks (:meth:`~RosTrialRobot.joint_state`,
:meth:`~RosTrialRobot.fingertip`) notify; the executor keeps spinning meanwhile.
"""

from dataclasses import dataclass
import math
import threading
import time
from typing import Callable, Sequence

import numpy as np

from ..explore.trial import Trial


class TrialTimeout(RuntimeError):
    """Raised when the arm's readings or the tracker's stop coming during a trial."""


@dataclass(frozen=True)
class TrialTiming:
    """How a trial settles and measures (the player's ``explore_*`` parameters)."""

    still_deg_s: float = 0.5       # every arm joint slower than this: settled
    max_settle_sec: float = 1.5    # settled anyway after this long
    samples: int = 3               # tracker readings averaged per trial
    tracker_wait_sec: float = 1.0  # the readings must come within this after settling

    def __post_init__(self):
        """Refuse a timing that cannot settle or measure (one line naming the value)."""
        for name, ok in (('still_deg_s', self.still_deg_s > 0),
                         ('max_settle_sec', self.max_settle_sec >= 0),
                         ('samples', self.samples >= 1),
                         ('tracker_wait_sec', self.tracker_wait_sec > 0)):
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ValueError(f'exploration {name}: {value!r}; expected a positive number')


class RosTrialRobot:
    """
    One arm of the robot behind ROS, as the explorers' trial robot.

    ``send(q, duration)`` commands the arm's joints (``joint_names`` order, rad) to reach
    ``q`` in ``duration`` s; ``now()`` is the ROS clock (s) the readings are stamped on.
    """

    def __init__(self, joint_names: Sequence[str], limits: tuple,
                 send: Callable[[np.ndarray, float], None], now: Callable[[], float],
                 timing: TrialTiming = TrialTiming()):
        """Take the arm's joints, ``limits`` = (lower, upper, velocity) in rad and rad/s."""
        self.joint_names = tuple(joint_names)
        self.lower, self.upper, self.velocity = (np.asarray(v, dtype=float) for v in limits)
        self._send, self._now, self.timing = send, now, timing
        self._cond = threading.Condition()
        self._q = None                 # latest arm reading (rad)
        self._v = None                 # latest arm velocities (rad/s), or None
        self._stamp = None             # its stamp (s)
        self._received = None          # when it came (time.monotonic())
        self._window = None            # (from stamp, [joint readings], [tips]) while measuring

    # --- fed by the node's callbacks --------------------------------------------------

    def joint_state(self, stamp: float, names, positions, velocities) -> None:
        """Take one ``/joint_states`` reading (stamp in s; velocities may be empty)."""
        index = {n: i for i, n in enumerate(names)}
        if any(j not in index for j in self.joint_names):
            return
        q = np.array([positions[index[j]] for j in self.joint_names], dtype=float)
        v = (np.array([velocities[index[j]] for j in self.joint_names], dtype=float)
             if len(velocities) == len(names) else None)
        with self._cond:
            if v is None and self._q is not None and stamp > self._stamp:
                v = (q - self._q) / (stamp - self._stamp)
            self._q, self._v, self._stamp = q, v, float(stamp)
            self._received = time.monotonic()
            if self._window is not None and stamp >= self._window[0]:
                self._window[1].append(q)
            self._cond.notify_all()

    def fingertip(self, stamp: float, point_mm) -> None:
        """Take one tracker reading of this arm's hand (capture stamp in s, point in mm)."""
        with self._cond:
            if self._window is not None and stamp >= self._window[0]:
                self._window[2].append(np.asarray(point_mm, dtype=float))
                self._cond.notify_all()

    # --- the TrialRobot protocol ------------------------------------------------------

    def current(self) -> np.ndarray:
        """Return the arm's latest joint readings (rad); TrialTimeout if there are none."""
        with self._cond:
            if self._q is None:
                raise TrialTimeout(f'no /joint_states for {", ".join(self.joint_names[:3])}')
            return self._q.copy()

    def trial(self, q: np.ndarray, duration: float) -> Trial:
        """Move to ``q`` in ``duration`` s, settle, and measure the tip (mean of samples)."""
        began = time.monotonic()
        self._send(np.asarray(q, dtype=float), float(duration))
        settled = self._settle(began + float(duration))
        timing = self.timing
        with self._cond:
            self._window = (settled, [], [])
            try:
                end = time.monotonic() + timing.tracker_wait_sec
                while len(self._window[2]) < timing.samples:
                    left = end - time.monotonic()
                    if left <= 0:
                        raise TrialTimeout(
                            f'{len(self._window[2])} of {timing.samples} tracker readings '
                            f'within {timing.tracker_wait_sec:g} s of settling; is the '
                            f'fingertip tracker running?')
                    self._cond.wait(left)
                readings = self._window[1] or [self._q]
                tip = np.mean(self._window[2][:timing.samples], axis=0)
            finally:
                self._window = None
        return Trial(np.mean(readings, axis=0), tip, time.monotonic() - began)

    def _settle(self, move_end: float) -> float:
        """Wait for the move's end, then for the arm to be still; return that reading's stamp."""
        still = math.radians(self.timing.still_deg_s)
        give_up = move_end + self.timing.max_settle_sec
        with self._cond:
            while True:
                now = time.monotonic()
                fresh = self._received is not None and self._received >= move_end
                if fresh and self._v is not None and float(np.max(np.abs(self._v))) < still:
                    return self._stamp
                if now >= give_up:
                    if self._stamp is None:
                        raise TrialTimeout('no /joint_states while the arm settled')
                    return self._now()       # not still within max_settle_sec: from now
                self._cond.wait(min(max(move_end - now, 0.01), give_up - now))
