"""
A periodic tick that runs only while it has work: it stops itself, and work restarts it.

Free of ROS.  The node parses the latest joint state and publishes a change of its
``/diagnostics`` on a 10 Hz tick, so that a 500 Hz stream or a flood of rejected inputs
costs at most ten of each a second.  An idle node (no stream, nothing changing) needs
no tick at all, and a timer that fires anyway wakes the executor ten times a second for
nothing.  :class:`DemandTick` is the timer's callback: after each run of the job it
cancels the timer unless a change is pending or ``has_work()``; :meth:`DemandTick.wake`
and :meth:`DemandTick.change` (called by whatever brings work, from any thread) reset
the timer, so the job runs one period later, as on a tick that never stopped.
"""

import threading


class DemandTick:
    """The callback of a periodic timer that cancels the timer while there is no work."""

    def __init__(self, work, has_work):
        """``work()`` is the tick's job; ``has_work()`` says whether a next tick is needed."""
        self._work = work
        self._has_work = has_work
        self._lock = threading.Lock()
        self._timer = None
        self._wake_executor = None
        self._changed = True              # the first tick publishes the initial state
        self.idle = False                 # True while the timer is cancelled

    def attach(self, timer, wake_executor):
        """
        Drive ``timer`` (``cancel()``, ``reset()``); ``wake_executor()`` after a reset.

        The executor may be waiting while the timer is cancelled: woken, it waits again
        with the timer running.
        """
        self._timer = timer
        self._wake_executor = wake_executor

    def tick(self):
        """Run the job, then cancel the timer if there is nothing left for the next tick."""
        self._work()
        with self._lock:
            if self._timer is not None and not self._changed and not self._has_work():
                self.idle = True
                self._timer.cancel()

    def take_change(self):
        """Return True (once) if :meth:`change` was called since the last time."""
        with self._lock:
            changed, self._changed = self._changed, False
        return changed

    def change(self):
        """Note a change for the job to take (:meth:`take_change`); restart the timer."""
        with self._lock:
            self._changed = True
            restart = self._restart()
        if restart:
            self._wake_executor()

    def wake(self):
        """Restart the timer if it stopped (any thread; a lock and a test if it runs)."""
        with self._lock:
            restart = self._restart()
        if restart:
            self._wake_executor()

    def _restart(self):
        """Reset a cancelled timer (with the lock held); return True if it was cancelled."""
        if not self.idle:
            return False
        self.idle = False
        self._timer.reset()
        return True
