"""
The trial-robot protocol: command one arm's pose, let it settle, read the tracker.

Exploration on the robot (the second source paper) learns from *measured* fingertip
positions, never from the model's.  A :class:`TrialRobot` is whatever can do one trial:
the simulator with a changed copy of the robot (the benchmark's), a kinematic stand-in
(the tests' and quick runs'), or a real robot behind the node.  A :class:`TrialSession`
wraps one and is what the explorers call: it checks every pose before it is commanded
(:class:`SafetyCheck`), honours a stop callback between trials (a new fault or a stop
request ends exploration within one trial), and counts the trials and the robot
seconds they cost (move + settle + tracker latency).
"""

from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, NamedTuple, Optional, Protocol

import numpy as np

SMOOTH_PEAK = 1.5        # a cubic (smoothstep) move's peak speed / its mean speed
MIN_MOVE_SEC = 0.2       # the shortest move a trial commands
CLEAR_BEYOND_MM = 2.0    # pose solves keep the safety margin's clearance plus this (keep_clear)


class Trial(NamedTuple):
    """One trial: the joint angles reached (encoder readings) and the measured tip."""

    q: np.ndarray          # (n,) rad, the arm's joints as measured after settling
    tip: np.ndarray        # (3,) mm in the base frame, as the tracker measured it
    seconds: float         # robot time of the trial: move + settle + latency


class TrialRobot(Protocol):
    """What the explorers need of a robot: one arm, its limits, and one trial at a time."""

    joint_names: tuple
    lower: np.ndarray       # (n,) rad
    upper: np.ndarray       # (n,) rad
    velocity: np.ndarray    # (n,) rad/s

    def current(self) -> np.ndarray:
        """Return the arm's joint angles now (rad)."""

    def trial(self, q: np.ndarray, duration: float) -> Trial:
        """Move the arm to ``q`` (rad) in ``duration`` s, settle, and measure the tip."""


class ExplorationStopped(Exception):
    """Raised between trials when the stop callback asks exploration to end."""


class UnsafeTrial(ValueError):
    """Raised when a trial pose fails a safety check; nothing was commanded."""


@contextmanager
def recording_end(out):
    """
    Run an explorer's trials; a stop request or an unsafe trial ends them, said on ``out``.

    ``out`` (a :class:`.task.PointOutcome`) gets status ``stopped`` or ``refused`` and the
    reason in its notes; what it holds so far stays, as every explorer reports it.
    """
    try:
        yield out
    except ExplorationStopped as stop:
        out.status = 'stopped'
        out.notes.append(str(stop))
    except UnsafeTrial as why:
        out.status = 'refused'
        out.notes.append(str(why))


def move_duration(q_from, q_to, velocity, peak=SMOOTH_PEAK, shortest=MIN_MOVE_SEC):
    """Return the duration (s) of a smooth move whose peak joint speed meets ``velocity``."""
    step = np.abs(np.asarray(q_to, dtype=float) - np.asarray(q_from, dtype=float))
    return float(max(shortest, peak * np.max(step / np.asarray(velocity, dtype=float))))


@dataclass(frozen=True)
class SafetyCheck:
    """
    The checks every trial pose passes before it is commanded.

    Within the joint limits (shrunk by ``limit_margin`` rad), reached within the
    velocity limits (the smooth move's peak speed), and clear of self-collision by the
    model: ``clearance(q_path)`` returns, per pose (N, n), the smallest capsule
    clearance in mm, which must stay >= ``margin_mm`` at every sampled pose of the move.
    """

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    clearance: Optional[Callable[[np.ndarray], np.ndarray]] = None
    margin_mm: float = 5.0
    limit_margin: float = 0.0
    path_samples: int = 8

    def keep_clear(self):
        """
        Return the pose solves' ``keep_clear`` (:func:`.corrections.solve_poses`), or None.

        A model's solution knows nothing of self-collision, and on a redundant arm it may
        lie on a branch through the body where no step towards it would be allowed (the
        circle's elbow lock with the wrist free: 20 points of 100 in a row left 55-132 mm
        off, on one seed of ten): the solves keep this check's clearance, a little beyond
        its margin (:data:`CLEAR_BEYOND_MM`).  None without a clearance check.
        """
        if self.clearance is None:
            return None
        return self.clearance, self.margin_mm + CLEAR_BEYOND_MM

    def clip(self, q):
        """Return ``q`` clipped into the limits less their margin (a step never leaves them)."""
        return np.clip(q, self.lower + self.limit_margin, self.upper - self.limit_margin)

    def problem(self, q_from, q_to, duration):
        """Return why the move is unsafe (one line), or '' if it is safe."""
        q_to = np.asarray(q_to, dtype=float)
        if not np.isfinite(q_to).all():
            return f'trial pose {q_to!r}: expected finite angles'
        low, high = self.lower + self.limit_margin, self.upper - self.limit_margin
        bad = np.flatnonzero((q_to < low - 1e-9) | (q_to > high + 1e-9))
        if bad.size:
            j = int(bad[0])
            return (f'trial pose: joint {j} at {np.degrees(q_to[j]):.2f} deg is outside its '
                    f'limits [{np.degrees(low[j]):.2f}, {np.degrees(high[j]):.2f}] deg')
        speed = SMOOTH_PEAK * np.abs(q_to - q_from) / max(duration, 1e-9)
        fast = np.flatnonzero(speed > self.velocity * (1 + 1e-9))
        if fast.size:
            j = int(fast[0])
            return (f'trial move: joint {j} would peak at {np.degrees(speed[j]):.1f} deg/s; '
                    f'expected <= {np.degrees(self.velocity[j]):.1f} deg/s')
        if self.clearance is not None:
            s = np.linspace(0.0, 1.0, self.path_samples + 1)[1:, None]
            path = q_from[None] + s * (q_to - q_from)[None]
            worst = float(np.min(self.clearance(path)))
            if worst < self.margin_mm:
                return (f'trial move: self-collision clearance {worst:.1f} mm by the model; '
                        f'expected >= {self.margin_mm:g} mm')
        return ''


@dataclass
class TrialSession:
    """
    One exploration's access to the robot: safety-checked, stoppable, counted trials.

    ``should_stop`` is called before every trial; when it returns True the session
    raises :class:`ExplorationStopped`, so at most the trial under way completes.
    """

    robot: TrialRobot
    safety: SafetyCheck
    should_stop: Callable[[], bool] = lambda: False
    trials: int = 0
    refused: int = 0
    seconds: float = 0.0
    log: list = field(default_factory=list)      # (point id, q commanded, Trial)

    def problem(self, q):
        """
        Return why a trial at ``q`` would be refused now, or '' if it is safe.

        Nothing is commanded and nothing is counted: an explorer may shorten a step
        the checks would refuse instead of ending its exploration on it.
        """
        q = np.asarray(q, dtype=float)
        here = np.asarray(self.robot.current(), dtype=float)
        return self.safety.problem(here, q, move_duration(here, q, self.robot.velocity))

    def trial(self, q, point=-1):
        """Run one trial at ``q`` (rad) for typical point ``point``; return its Trial."""
        if self.should_stop():
            raise ExplorationStopped(f'exploration stopped after {self.trials} trials')
        q = np.asarray(q, dtype=float)
        here = np.asarray(self.robot.current(), dtype=float)
        duration = move_duration(here, q, self.robot.velocity)
        why = self.safety.problem(here, q, duration)
        if why:
            self.refused += 1
            raise UnsafeTrial(why)
        out = self.robot.trial(q, duration)
        self.trials += 1
        self.seconds += float(out.seconds)
        self.log.append((int(point), q.copy(), out))
        return out


class KinematicTrialRobot:
    """
    A trial robot without physics: the arm reaches its command exactly (locks hold).

    ``truth(q)`` (N, n) -> (N, 3) mm is the changed robot's true fingertip; the tracker
    adds Gaussian noise of ``sigma_mm`` (seeded).  ``timing`` is (settle, latency) in s:
    the robot time of a trial is its move's duration plus both.  For tests and quick
    runs: the benchmark's default trial robot is the simulator.
    """

    joint_names = ()

    def __init__(self, truth, lower, upper, velocity, locks=None, sigma_mm=1.0, seed=0,
                 timing=(0.3, 0.05), start=None):
        self.truth = truth
        self.lower, self.upper = np.asarray(lower, float), np.asarray(upper, float)
        self.velocity = np.asarray(velocity, float)
        self.locks = dict(locks or {})           # arm index -> angle (rad)
        self.sigma = float(sigma_mm)
        self.settle, self.latency = (float(t) for t in timing)
        self.rng = np.random.default_rng(seed)
        self.q = np.zeros(len(self.lower)) if start is None else np.array(start, float)
        self._hold()

    def _hold(self):
        for j, angle in self.locks.items():
            self.q[j] = angle

    def current(self):
        """Return the arm's joint angles now (rad)."""
        return self.q.copy()

    def trial(self, q, duration):
        """Reach ``q`` (locked joints stay), settle, and measure the tip with noise."""
        self.q = np.array(q, dtype=float)
        self._hold()
        tip = np.asarray(self.truth(self.q[None]), dtype=float)[0]
        noisy = tip + self.rng.normal(0.0, self.sigma, 3)
        return Trial(self.q.copy(), noisy, float(duration) + self.settle + self.latency)
