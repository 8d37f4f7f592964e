"""
A fingertip tracker as a camera gives it: noisy, late, at its own rate, sometimes blind.

The second source paper measures where the end effector really is with a camera; a real
robot has an AprilTag on the hand seen by a head camera, or a motion-capture marker.
This module turns the simulator's noise-free fingertip (the true, possibly changed
kinematics) into what such a tracker delivers, so that whatever consumes it (noticing a
change, exploring) sees the same kind of data it will see on the robot:

- one measurement per hand every ``1 / rate_hz`` of the simulator's clock (default
  30 Hz, a camera's frame rate), *captured* at that moment;
- Gaussian noise of ``sigma_mm`` on each axis (default 1 mm: a mocap system or a close
  camera; a head camera is nearer 4 mm);
- *delivered* ``latency_s`` after the capture (default 50 ms: cameras measure 40-60 ms),
  still stamped with the capture time, so a consumer can line it up with what the robot
  did at that moment;
- a dropout (the tag occluded, out of view) with probability ``dropout`` per hand and
  frame: that measurement is never delivered; nothing else marks it.

The random numbers come from one seeded generator, so a run is reproducible.  Positions
are in millimetres in the robot's base frame; the ROS node converts to metres.  The
noise-free truth travels with each measurement for benchmarks only: the simulator never
publishes it unless asked (see ``msg_docs/fingertip_tracker.md``).
"""

from collections import deque
from dataclasses import dataclass
import math
import os

import numpy as np

from ..model.robot_profile import load_profile
from ..resources import config_path, NAMO_PROFILE_FILE


@dataclass(frozen=True)
class TrackerSettings:
    """How good the tracker is (the node's ``tracker_*`` parameters)."""

    sigma_mm: float = 1.0        # noise per axis (standard deviation)
    latency_s: float = 0.05      # capture -> delivery
    rate_hz: float = 30.0        # captures per second, per hand
    dropout: float = 0.0         # probability that one capture of one hand is lost
    seed: int | None = 0         # None: a fresh seed each run

    def __post_init__(self):
        """Refuse settings no tracker can have (one line naming the value)."""
        checks = (('sigma_mm', self.sigma_mm >= 0, '>= 0'),
                  ('latency_s', self.latency_s >= 0, '>= 0'),
                  ('rate_hz', self.rate_hz > 0, '> 0'),
                  ('dropout', 0.0 <= self.dropout < 1.0, 'in [0, 1)'))
        for name, ok, expected in checks:
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ValueError(f'tracker {name}: {value!r}; expected a number {expected}')


@dataclass(frozen=True)
class Measurement:
    """One tracked fingertip: the hand, when it was captured and delivered (s), where."""

    side: str
    capture: float
    delivery: float
    point_mm: tuple          # measured (x, y, z), base frame
    truth_mm: tuple          # noise-free, for benchmarks only


class FingertipTracker:
    """
    Capture fingertips on the simulator's clock; hand them out once their latency passed.

    Not thread-safe: one caller (the simulator's physics loop) drives it.
    """

    def __init__(self, settings: TrackerSettings = TrackerSettings(), start: float = 0.0):
        self.settings = settings
        self.period = 1.0 / settings.rate_hz
        self.rng = np.random.default_rng(settings.seed)
        self.next_capture = float(start)
        self.captured = 0           # captures per hand so far
        self.dropped = 0            # measurements lost (all hands)
        self._pending = deque()     # Measurement, in delivery order

    def due(self, now: float) -> bool:
        """Return True when a capture is due at ``now`` (s, the simulator's clock)."""
        return now >= self.next_capture

    def capture(self, now: float, truths: dict) -> int:
        """
        Capture every hand of ``truths`` ({side: (x, y, z) mm}) at ``now``; return how many.

        A capture falls on the tracker's own grid (``start + k / rate_hz``): the one due
        at ``now`` is stamped ``now``, and a late call skips the frames it missed, as a
        camera does, rather than bursting.
        """
        if not self.due(now):
            return 0
        missed = math.floor((now - self.next_capture) / self.period)
        self.next_capture += (missed + 1) * self.period
        self.captured += 1
        kept = 0
        for side in sorted(truths):
            truth = np.asarray(truths[side], dtype=float)
            noise = self.rng.normal(0.0, self.settings.sigma_mm, 3)
            lost = self.rng.random() < self.settings.dropout
            if lost:
                self.dropped += 1
                continue
            self._pending.append(Measurement(
                side, float(now), float(now) + self.settings.latency_s,
                tuple(float(v) for v in truth + noise), tuple(float(v) for v in truth)))
            kept += 1
        return kept

    def deliver(self, now: float) -> list:
        """Return the measurements whose delivery time has come by ``now``, oldest first."""
        out = []
        while self._pending and self._pending[0].delivery <= now:
            out.append(self._pending.popleft())
        return out

    @property
    def pending(self) -> int:
        """Return how many captured measurements still wait for their latency."""
        return len(self._pending)


class TrueFingertips:
    """
    Where the fingertips really are: FK of the simulator's own (changed) URDF copy, in mm.

    MuJoCo fuses a URDF's fixed fingertip link into the hand, so the fingertip is not a
    MuJoCo body; the robot's profile compiles the changed URDF's chains instead (batched
    FK from the base link, landmark ``tip``), evaluated at the simulated joint angles.
    """

    def __init__(self, urdf: str, profile: str | os.PathLike | None = None):
        loaded = load_profile(profile or config_path(NAMO_PROFILE_FILE), urdf=urdf)
        self.chains = {side: arm.chain for side, arm in loaded.arms.items()}
        self.frame = loaded.tree.root      # the base frame the positions are in
        self.fingertip_joints = {
            side: loaded.tree.parent_joint[arm.landmark_links['tip']].name
            for side, arm in loaded.arms.items()
            if arm.landmark_links['tip'] in loaded.tree.parent_joint}

    def __call__(self, angles: dict) -> dict:
        """
        Return {side: (x, y, z) mm} for ``angles`` ({joint: rad}).

        A chain joint missing from ``angles`` is at 0: a joint the simulator holds fixed
        (a profile robot's legs or head); the torso's joints, which the simulator node
        actuates, come with the arms'.
        """
        return {side: chain.forward([angles.get(j, 0.0) for j in chain.joint_names]).tip
                for side, chain in self.chains.items()}
