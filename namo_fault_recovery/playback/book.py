"""
What the gesture player knows between plays (no ROS): library versions and locks.

Library versions arrive one gesture at a time; a version is the set of gestures that
share a header stamp, and the newest stamp is the current one.  Lock angles come from
two sources: ``recovery_node``'s diagnostics (the failed joints and their lock angles)
and the faults the player held in a play (its own reports, and those others published
mid-play, at the angle they were measured), kept until the node's diagnostics list that
joint (then the node's lock angle is authoritative; when it no longer lists it, the
fault was cleared).
"""

from dataclasses import dataclass
import math

import numpy as np


@dataclass(frozen=True)
class GestureTrack:
    """One gesture of one library version: joint names, keyframe times and angles."""

    name: str
    joint_names: tuple
    times: np.ndarray
    positions: np.ndarray     # (keyframes, joints), rad
    stamp: int                # ns; the version key


class PlayerBook:
    """The library versions received and the known locks."""

    def __init__(self):
        """Start with no library and no fault."""
        self.versions = {}          # stamp -> {gesture: GestureTrack}
        self.arrivals = {}          # stamp -> arrival time of its first gesture
        self.node_failed = None     # joints the node lists as failed (None: not heard)
        self.node_locks = {}        # joint -> lock angle (rad) from the node
        self.own_reports = {}       # joint -> (report time, measured angle)
        self.last_report = None     # time of the player's last fault report

    def add_gesture(self, track, now):
        """Store one gesture of a library version received at ``now``."""
        self.versions.setdefault(track.stamp, {})[track.name] = track
        self.arrivals.setdefault(track.stamp, now)
        for old in sorted(self.versions)[:-2]:      # keep the newest two versions
            del self.versions[old]
            del self.arrivals[old]

    @property
    def current_stamp(self):
        """Return the newest version's stamp, or None before any library."""
        return max(self.versions) if self.versions else None

    def gesture(self, name):
        """Return the newest GestureTrack of ``name``, or None."""
        for stamp in sorted(self.versions, reverse=True):
            if name in self.versions[stamp]:
                return self.versions[stamp][name]
        return None

    def names(self):
        """Return every gesture name received, sorted."""
        return sorted({n for v in self.versions.values() for n in v})

    def newer_than(self, when):
        """Return True if a library version first arrived after time ``when``."""
        return any(t > when for t in self.arrivals.values())

    def node_status(self, failed, locks):
        """Take the node's failed joints and lock angles (rad; None when pending)."""
        self.node_failed = list(failed)
        self.node_locks = {j: a for j, a in locks.items() if j in failed and a is not None}
        for joint in failed:
            self.own_reports.pop(joint, None)

    def report(self, joint, angle, now):
        """Record a fault the player detected (until the node acknowledges it)."""
        self.own_reports[joint] = (now, float(angle))
        self.last_report = now

    def library_outdated(self):
        """Return True while no library version arrived since the last fault report."""
        return self.last_report is not None and not self.newer_than(self.last_report)

    def locks(self, measured=None):
        """
        Return {joint: lock angle} for every known failed joint.

        A joint the node lists as failed with its lock angle still pending is held where
        it was reported or, failing that, where it is measured (``measured`` dict).
        """
        out = {j: a for j, (_, a) in self.own_reports.items()}
        for joint in self.node_failed or ():
            if joint in self.node_locks:
                out[joint] = self.node_locks[joint]
            elif joint not in out and measured and joint in measured:
                out[joint] = measured[joint]
        return out


def parse_lock_angle(text):
    """Return a ``lock_angle_rad`` diagnostics value as float, or None when empty/bad."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None
