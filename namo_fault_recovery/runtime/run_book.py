"""
The node's run bookkeeping: which library is wanted, which is running, who waits for it.

Free of ROS and thread-safe.  Every change that makes the published library out of date
(a new fault set, a parameter, a call of ``/reconfigure_gestures``) *requests* a new
generation.  The dispatcher takes the newest request, runs it, and *publishes* it only
if no newer request arrived meanwhile ("a stale run is never published").  A caller
waits for the generation current when it asked: it is told once that generation (or a
newer one, which supersedes it) is published, failed, or the node stops.  Callers are
told through a callback, so that no executor thread ever blocks waiting.
"""

from dataclasses import dataclass
import threading
import time


@dataclass(frozen=True)
class Run:
    """One generation to compute: the fault set it is for and when it was requested."""

    generation: int
    faults: dict                 # joint -> Fault
    requested_at: float          # time.monotonic() of the request (the deadline starts)
    learned: tuple = ()          # corrections learned on the robot (LearnedArm), if any


@dataclass(frozen=True)
class Outcome:
    """What a waiting caller is told."""

    published: bool
    result: object = None        # the LibraryResult now published
    version: int = 0             # library version number of ``result``
    stamp_ns: int = 0
    reason: str = ''             # why nothing new was published


class RunBook:
    """The fault set, the request generations and the waiting callers."""

    def __init__(self, on_request=None):
        self._cond = threading.Condition()
        self._on_request = on_request    # e.g. cancel the run under way (cheap, non-blocking)
        self.faults = {}             # joint -> Fault, in arrival order
        self.learned = ()            # LearnedArm per arm: corrections measured on the robot
        self.fault_version = 0
        self._requested = 0
        self._requested_at = time.monotonic()
        self._taken = 0              # highest generation given to the dispatcher
        self._running = None
        self._refine_next = None     # generation whose publication a refinement follows
        self._published = 0
        self._failed = None          # (generation, reason) of the last failed run
        self.current = None          # LibraryResult last published
        self.version = 0             # library version number
        self.stamp_ns = 0
        self.request_to_publish = None   # s from the request to the publication, last run
        self.publish_path = None     # s from the result in hand to its last message published
        self.fault_to_request = None     # s from the first report of a batch to its request
        self.fault_sync = None       # s the last fault set took to reach the disk (synced)
        self.fault_to_publish = None     # s from a batch's first report to its library sent
        self._report = None          # (generation, received_at) of the newest batch unsent
        self._durable = ({}, 0)      # (faults, fault_version) on disk: what others are shown
        self._waiters = []           # (generation, callback)
        self.stopping = False

    # --- requests -------------------------------------------------------------------

    def set_faults(self, faults, request=True, durable=True, received_at=None):
        """
        Replace the fault set and request a new library.

        ``durable=False`` says the fault set is still being written: the dispatcher may
        start computing its library at once (the write overlaps the engine run), but the
        fault set is shown (:meth:`snapshot`) only once :meth:`faults_durable` says it is
        on disk.  The caller keeps anything from acknowledging it until then (the node's
        :class:`~.persistence.Persistence` holds its lock over the write, and every
        publication takes that lock).  ``received_at`` (``time.monotonic()`` of the
        first fault report that led here) gives ``fault_to_request``.
        """
        with self._cond:
            self.faults = dict(faults)
            self.fault_version += 1
            if received_at is not None:
                self.fault_to_request = time.monotonic() - received_at
            if durable:
                self._durable = (self.faults, self.fault_version)
            if request:
                self._request_locked()
                if received_at is not None:
                    self._report = (self._requested, received_at)

    def faults_durable(self, sync_sec=None):
        """Record that the current fault set is on disk (``sync_sec``: the write's span)."""
        with self._cond:
            self._durable = (self.faults, self.fault_version)
            if sync_sec is not None:
                self.fault_sync = sync_sec

    def request(self):
        """Request a new library for the current fault set and settings."""
        with self._cond:
            self._request_locked()

    def _request_locked(self):
        self._requested += 1
        self._requested_at = time.monotonic()
        self._cond.notify_all()
        if self._on_request is not None and self._running is not None:
            self._on_request()

    def set_learned(self, learned, request=False):
        """Replace the learned corrections (one LearnedArm per arm); optionally request."""
        with self._cond:
            self.learned = tuple(learned)
            if request:
                self._request_locked()

    def publish_explored(self, result, publish):
        """
        Publish ``result``, a version explored on the robot, unless a run is pending.

        A new library version with nobody to tell (no call waits for it).  Returns
        False, publishing nothing, while a requested library is still to come (it would
        supersede this one) or the node is stopping.
        """
        with self._cond:
            if self.stopping or self._pending_locked():
                return False
            self.current = result
            self.version += 1
            self.stamp_ns = publish(result)
            return True

    def call(self, callback):
        """
        Register ``callback(Outcome)`` for the library of the current state.

        A pending request is joined; with none pending the current fault set is run
        again.  The callback runs in the thread that completes the generation (or here,
        at once, if the node is stopping).
        """
        with self._cond:
            if self.stopping:
                outcome = Outcome(False, reason='the node is shutting down')
            else:
                failed_gen = self._failed[0] if self._failed else 0
                if self._requested <= max(self._published, failed_gen):
                    self._request_locked()
                self._waiters.append((self._requested, callback))
                return
        callback(outcome)

    def mark_published_without_run(self, result, stamp_ns):
        """Publish ``result`` for the newest request at once (no engine run needed)."""
        with self._cond:
            self._taken = self._requested
            return self._published_locked(self._requested, result, stamp_ns)

    # --- the dispatcher -------------------------------------------------------------

    def next_run(self, timeout=None):
        """Block until a new generation is requested; return its Run (None if stopping)."""
        with self._cond:
            end = None if timeout is None else time.monotonic() + timeout
            while not self.stopping and self._requested <= self._taken:
                remaining = None if end is None else end - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return None
                self._cond.wait(remaining)
            if self.stopping:
                return None
            self._taken = self._running = self._requested
            return Run(self._requested, dict(self.faults), self._requested_at, self.learned)

    def pending(self):
        """Return True while a requested library is neither published nor failed yet."""
        with self._cond:
            return self._pending_locked()

    def wait_published(self, timeout):
        """Wait up to ``timeout`` s until nothing is pending; return True if nothing is."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._pending_locked() or self.stopping,
                                       timeout)

    def _pending_locked(self):
        failed_gen = self._failed[0] if self._failed else 0
        return self._requested > max(self._published, failed_gen)

    def is_current(self, generation):
        """Return True while ``generation`` is the newest request (not yet superseded)."""
        return not self.stopping and generation == self._requested

    def publish(self, generation, result, publish, in_hand=None):
        """
        Publish ``result`` of ``generation`` if it is still the newest request.

        ``in_hand`` is the ``time.monotonic()`` instant the result was available (the
        engine's answer received): ``publish_path`` is measured from it to the moment
        ``publish`` returned, its last message sent.

        ``publish(result)`` returns the stamp (ns) and runs under the book's lock, so no
        newer request can slip in between
        the check and the messages.  Returns the callbacks to tell (call :meth:`notify`
        with them outside any lock), or None if the generation went stale.
        """
        with self._cond:
            # Still running when a refinement follows: clients see one span, not a gap.
            self._running = generation if self._refine_next == generation else None
            self._refine_next = None
            if generation != self._requested or self.stopping:
                self._running = None
                return None
            stamp_ns = publish(result)
            now = time.monotonic()
            if in_hand is not None:
                self.publish_path = now - in_hand
            if self._report is not None and generation >= self._report[0]:
                self.fault_to_publish = now - self._report[1]
                self._report = None
            return self._published_locked(generation, result, stamp_ns)

    def refinement_follows(self, generation):
        """
        Say that ``generation``'s publication will be followed by its refinement.

        The book then reports the run as still running from the publication until
        :meth:`refined`, so a client that waits for ``running`` false waits for the
        library the node settles on, not for the gap before the refinement starts.
        """
        with self._cond:
            self._refine_next = generation

    def refining(self, generation):
        """
        Mark ``generation``'s published library as being refined; return its version.

        Returns the library version number of that published library (0 if stale,
        nothing to refine).  While it refines, a new request cancels it
        (``on_request``) as it would a run.
        """
        with self._cond:
            if generation != self._requested or self._published != generation \
                    or self.stopping:
                if self._running == generation:
                    self._running = None
                return 0
            self._running = generation
            return self.version

    def publish_refined(self, generation, result, publish):
        """
        Publish a better library for the already published ``generation``, if current.

        A new library version with nobody to tell (its callers were told at the first
        publication); ``request_to_publish`` keeps the first publication's span.  Returns
        True if published, False if ``generation`` went stale.
        """
        with self._cond:
            if generation != self._requested or self._published != generation \
                    or self.stopping:
                return False
            self.current = result
            self.version += 1
            self.stamp_ns = publish(result)
            return True

    def refined(self, generation):
        """Mark the end of ``generation``'s refinement (done, converged or cancelled)."""
        with self._cond:
            if self._running == generation:
                self._running = None

    def _published_locked(self, generation, result, stamp_ns):
        # From the request to the publication: the span the deadline covers.
        self.request_to_publish = time.monotonic() - self._requested_at
        self._published = generation
        self.current = result
        self.version += 1
        self.stamp_ns = stamp_ns
        outcome = Outcome(True, result, self.version, stamp_ns)
        return self._release_locked(generation, outcome)

    def failed(self, generation, reason):
        """Record a failed run; return the callbacks to tell (see :meth:`published`)."""
        with self._cond:
            self._running = None
            if generation != self._requested:
                return []                      # stale anyway: the newer run will answer
            self._failed = (generation, reason)
            outcome = Outcome(False, self.current, self.version, self.stamp_ns,
                              f'reconfiguration failed: {reason}; previous library kept')
            return self._release_locked(generation, outcome)

    def _release_locked(self, generation, outcome):
        ready = [(cb, outcome) for gen, cb in self._waiters if gen <= generation]
        self._waiters = [(gen, cb) for gen, cb in self._waiters if gen > generation]
        self._cond.notify_all()
        return ready

    @staticmethod
    def notify(ready):
        """Tell the callers returned by :meth:`published` or :meth:`failed`."""
        for callback, outcome in ready or ():
            callback(outcome)

    def stop(self):
        """Stop: wake the dispatcher and tell every waiting caller."""
        with self._cond:
            self.stopping = True
            ready = [(cb, Outcome(False, reason='the node is shutting down'))
                     for _, cb in self._waiters]
            self._waiters = []
            self._cond.notify_all()
        self.notify(ready)

    # --- views ----------------------------------------------------------------------

    def snapshot(self):
        """Return a consistent dict of the state, for diagnostics."""
        with self._cond:
            faults, fault_version = self._durable
            return {
                'faults': dict(faults), 'fault_version': fault_version,
                'current': self.current, 'version': self.version, 'stamp_ns': self.stamp_ns,
                'pending': self._requested > self._published,
                'running': self._running is not None, 'failed': self._failed,
                'waiting_callers': len(self._waiters),
                'request_to_publish': self.request_to_publish,
                'publish_path': self.publish_path,
                'fault_to_request': self.fault_to_request, 'fault_sync': self.fault_sync,
                'fault_to_publish': self.fault_to_publish,
            }
