"""
One play that carries on through a stuck joint (no ROS): hold, wait, blend, go on.

A guest sees a gesture; when a joint sticks halfway, starting it again from the
beginning is what they notice most.  :class:`CarryOn` plays a planned motion and, when
a fault arrives mid-play (its own :class:`~.monitor.Playback` detects a stuck joint, or
anyone reports one):

1. **hold**: the stuck joint is commanded where it is (its measured angle) from now
   on, at every point; the other joints stop, as fast as the acceleration limits allow
   (:func:`~.blend.stop`), and the gesture's phase waits where it was (the stopped arm
   is not judged: the body may hold a healthy joint off the stop, as the torso does
   the forearm of a stuck shoulder; the blend starts from where it is): the old motion
   with a joint missing was never checked for self-contact (a two-handed gesture may
   bring the arms together elsewhere), and the new gesture then goes on from that
   phase, so the guest sees all of it;
2. **wait** (at most ``wait`` seconds) for a library version that arrived after the
   fault and whose gesture holds every stuck joint still (the reconfigured one:
   ``recovery_node`` answers within its 1 s deadline, a contingency-table hit within
   milliseconds);
3. **blend**: the reconfigured gesture is planned on the gesture's own timeline
   (``planner``, from the play's start pose, the stuck joints at their angles), its
   instant at the phase where the arm stopped found (:func:`~.blend.phase_time`), and the arm
   blended from its measured pose and velocity onto it within the velocity and
   acceleration limits (:func:`~.blend.blend`: each joint rejoins it at the earliest
   instant it can; the gesture's phase waits up to ``REJOIN_WAIT`` where that brings
   the last joint onto it sooner, and then goes on);
4. **go on** to the end of the reconfigured gesture, watched as any play (a second
   fault starts again at 1).

The arm is *back on the reconfigured trajectory* at the first measured pose within
``goal_tolerance`` of the reconfigured trajectory at the current phase, every joint.
The play's :class:`~.monitor.Outcome` says that it carried on, with the times of the
fault, the switch and the return to the trajectory (:attr:`CarryOn.events`).  With
``wait`` 0 a fault ends the play, as it did before carrying on existed.  Times are
seconds since the play started, on the caller's clock.
"""

from dataclasses import dataclass
import math

import numpy as np

from .blend import blend, phase_time, stop
from .monitor import Outcome, Playback

REJOIN_WAIT = 1.0       # s: the longest the gesture's phase may wait while the arm rejoins it


@dataclass(frozen=True)
class Step:
    """What to do after an input: ``send`` a new motion (from now), report ``faults``, end."""

    send: object = None          # PlannedMotion to command from now on, or None
    faults: tuple = ()           # ((joint, measured angle), ...) newly detected: report them
    outcome: object = None       # Outcome once the play ended


def holds_still(frames, columns):
    """Return True if every column of ``frames`` (keyframes, joints) in ``columns`` is constant."""
    frames = np.atleast_2d(np.asarray(frames, dtype=float))
    return all(float(np.ptp(frames[:, c])) <= 1e-9 for c in columns)


class CarryOn:
    """Play one motion and carry on through stuck joints (see the module docstring)."""

    def __init__(self, plan, groups, thresholds, planner, limits, wait, sample_period=0.05,
                 pressed=None):
        """
        Play ``plan`` (a PlannedMotion from the play's start pose; time 0 = the start).

        ``groups`` and ``thresholds`` are the :class:`~.monitor.Playback`'s;
        ``planner(times, frames, start, holds)`` returns the PlannedMotion of keyframes
        ``frames`` (in the plan's joint order) from pose ``start``, the held joints
        ``holds`` at their angles and any other lock the caller knows of now (its
        knowledge when the library arrives, not when the play began: a fault cleared
        meanwhile is no lock);
        ``limits`` is the :class:`~.blend.BlendLimits`; ``wait`` the longest wait for
        the reconfigured library (s; 0: a fault ends the play); ``pressed`` the
        :class:`~.monitor.StuckJointDetector`'s (joints a command drives into the body).
        """
        self.pressed = pressed
        self.groups, self.thresholds = groups, thresholds
        self.planner, self.limits = planner, limits
        self.wait, self.sample_period = float(wait), sample_period
        self.base, self.base_time = plan, 0.0   # the gesture's timeline, at segment start
        self.segment_start = 0.0                # play time of the current motion's t = 0
        self.motion = plan                      # what the controllers play now
        self.playback = Playback(plan, groups, thresholds, pressed)
        self.holds = {}                         # joint -> held angle (rad)
        self.waiting_since = None               # play time of the fault being waited on
        self.candidate = None                   # (times, frames, label) to switch to
        self.target = None                      # the reconfigured plan, once switched
        self.events = []                        # (play time, kind, text)
        self.back_at = None                     # play time back on the reconfigured path
        self.blend_duration = None
        self.rejoin_wait = 0.0                  # s the blend's target waited at its phase
        self._blend_unsent = False              # a blend waits for :meth:`sent`

    @property
    def waiting(self):
        """Return True while a fault waits for its reconfigured library."""
        return self.waiting_since is not None

    @property
    def end_time(self):
        """Return the play time at which the current motion's last point is due."""
        return self.segment_start + self.motion.duration

    def phase(self, t):
        """Return the time on the gesture's timeline (``self.base``) at play time ``t``."""
        if self.waiting:
            return self.base_time         # stopped: the gesture waits where it was
        return self.base_time + max(t - self.segment_start - self.rejoin_wait, 0.0)

    def sent(self, t):
        """
        Take the play time ``t`` at which the current motion was sent.

        A blend starts then, not at the reading it was planned on: the arm waited,
        stopped, while it was planned (planning can take tens of ms), and a controller
        joining the blend that far in would jump.  A stop keeps its time (it goes on
        from the motion the controller was playing meanwhile).
        """
        if self._blend_unsent and t > self.segment_start:
            self.segment_start = t
        self._blend_unsent = False

    def fault(self, t, faults):
        """
        Take faults reported at play time ``t``: ((joint, angle held), ...).

        Returns the Step: the motion that holds them (nothing if all were known).
        """
        new = [(j, float(a)) for j, a in faults
               if j in self.motion.joint_names and j not in self.holds]
        if not new or self.wait <= 0:
            return Step()
        return self._hold(t, new, report=False)

    def offer(self, times, frames, label=''):
        """
        Offer a library version's keyframes of the played gesture (plan's joint order).

        Kept (returns True) while waiting, if it holds every stuck joint still within
        ``goal_tolerance`` of where it is held (a version made for these faults, not an
        older one); the switch happens at the next measured pose.
        """
        if not self.waiting or not self.fits(frames):
            return False
        self.candidate = (np.asarray(times, dtype=float), np.asarray(frames, dtype=float),
                          label)
        return True

    def fits(self, frames):
        """Return True if keyframes ``frames`` hold every stuck joint still where it is held."""
        frames = np.atleast_2d(np.asarray(frames, dtype=float))
        names = self.motion.joint_names
        columns = [names.index(j) for j in self.holds]
        return holds_still(frames, columns) and all(
            abs(frames[0, names.index(j)] - a) <= self.thresholds.goal_tolerance
            for j, a in self.holds.items())

    def update(self, t, measured, velocity=None):
        """Feed the measured pose (and velocity, if known) at play time ``t``; return a Step."""
        q = np.asarray(measured, dtype=float)
        if self.candidate is not None:
            return self._switch(t, q, velocity)
        self._watch_return(t, q)
        if self.waiting:
            # Stopped, waiting: no judging.  The body may hold healthy joints off the
            # stop (a stuck shoulder presses the forearm on the torso); the blend starts
            # from where they are, and the arm is watched again from there.
            return Step(outcome=self.expire(t))
        outcome = self.playback.update(t - self.segment_start, q)
        if outcome is not None and outcome.faults and self.wait > 0:
            new = [(j, a) for j, a in outcome.faults if j not in self.holds]
            if new:
                return self._hold(t, new, report=True)
        if outcome is None:
            return Step()
        return Step(faults=outcome.faults if self.wait <= 0 else (),
                    outcome=self._final(t, outcome))

    def expire(self, t):
        """Return the failed Outcome if the wait for the library is over at ``t``, else None."""
        if not self.waiting or t - self.waiting_since <= self.wait:
            return None
        held = ', '.join(f'{j} held at {math.degrees(a):.1f} deg' for j, a in self.holds.items())
        return Outcome(False, f'actuator fault detected: {held}; no reconfigured library '
                              f'holding it arrived within {self.wait:g} s',
                       tuple(self.holds.items()))

    # --- the steps ----------------------------------------------------------------

    def _hold(self, t, new, report):
        self.holds.update(new)
        tau = t - self.segment_start
        self.base_time, self.segment_start = self.phase(t), t
        self.rejoin_wait = 0.0
        self.motion = stop(self.motion, tau, self.limits, self.holds, self.sample_period)
        self.playback = Playback(self.motion, self.groups, self.thresholds, self.pressed)
        self.waiting_since, self.candidate = t, None
        self.target = self.back_at = None
        for joint, angle in new:
            self.events.append((t, 'fault', f'{joint} held at {math.degrees(angle):.1f} deg'))
        return Step(send=self.motion, faults=tuple(new) if report else ())

    def _switch(self, t, q, velocity):
        times, frames, label = self.candidate
        self.candidate = None
        start = self.base.waypoints[0].copy()
        target = self.planner(times, frames, start, dict(self.holds))
        t_target = phase_time(self.base, target, self.phase(t))
        if velocity is None:
            velocity = self.motion.velocity_at(t - self.segment_start)
        joined = blend(target, t_target, q, velocity, self.limits, self.holds,
                       self.sample_period, REJOIN_WAIT)
        motion, duration = joined.motion, joined.duration
        self.base, self.base_time, self.segment_start = target, t_target, t
        self.motion, self.target, self.rejoin_wait = motion, target, joined.wait
        self.playback = Playback(motion, self.groups, self.thresholds, self.pressed)
        self.waiting_since = None
        self._blend_unsent = True
        self.blend_duration = abs(duration)
        note = '' if duration >= 0 else ' (beyond the limits: no shorter blend fits)'
        self.events.append((t, 'switch', f'reconfigured {label or "gesture"} at phase '
                                         f'{t_target:.2f} s (waited {joined.wait:.2f} s), '
                                         f'blend {abs(duration):.2f} s' + note))
        return Step(send=motion)

    def _watch_return(self, t, q):
        if self.target is None or self.back_at is not None:
            return
        t_target = self.phase(t)
        if np.all(np.abs(q - self.target.command_at(t_target)) <= self.thresholds.goal_tolerance):
            self.back_at = t
            self.events.append((t, 'back', 'back on the reconfigured trajectory'))

    def _final(self, t, outcome):
        """Return the Outcome of the ended play, saying that it carried on (the events)."""
        if not self.events:
            return outcome
        if outcome.ok:
            reason = f'finished in {t:.2f} s, carried on: '
        else:
            reason = f'{outcome.reason}; after carrying on: '
        reason += '; '.join(f'{text} at {when:.2f} s' for when, kind, text in self.events)
        return Outcome(outcome.ok, reason, tuple(self.holds.items()))
