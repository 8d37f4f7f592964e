"""
Fault intake: every accepted fault report is persisted before it is acknowledged.

Free of ROS.  The ``/actuator_fault`` callback only validates a report and queues it
here, so that a burst is taken off the subscription as fast as it arrives.  One thread
drains the queue in batches: it applies every queued report (and ``clear``) in order to
the fault set, and ``commit`` writes the new fault set to the state file (atomically,
synced) and only then hands it to the run book; then ``on_accepted`` runs (it logs
``fault accepted``).  A crash at any moment therefore loses only reports that were never
acknowledged, and a burst of N reports costs one file write per batch, not N.
"""

from collections import deque
from dataclasses import dataclass
import threading

from .state_store import Fault


@dataclass(frozen=True)
class Report:
    """One validated fault report: joint -> lock angle (rad) or None."""

    joints: dict


@dataclass(frozen=True)
class Clear:
    """A ``/clear_faults`` request; ``done(count)`` is called once it is persisted."""

    done: object


@dataclass(frozen=True)
class After:
    """Call ``then()`` once every item queued before it is persisted and applied."""

    then: object


class FaultIntake:
    """The queue of fault-set changes and the thread that persists and applies them."""

    def __init__(self, book, commit, on_accepted, measured=lambda: {}, max_queue=100_000):
        self._book = book
        self._commit = commit              # commit(faults): persist, then book.set_faults
        self._on_accepted = on_accepted    # on_accepted(reports, cleared, faults)
        self._measured = measured          # latest measured angles (joint -> rad)
        self._queue = deque()
        self._max_queue = max_queue
        self._cond = threading.Condition()
        self._stopping = False
        self.dropped = 0
        self._thread = threading.Thread(target=self._loop, name='fault-intake', daemon=True)

    def start(self):
        """Start the intake thread."""
        self._thread.start()

    def submit(self, item):
        """Queue a :class:`Report`, :class:`Clear` or :class:`After` (cheap; never blocks)."""
        with self._cond:
            if len(self._queue) >= self._max_queue:
                self.dropped += 1           # far beyond any real burst: bounded memory
                return False
            self._queue.append(item)
            self._cond.notify()
        return True

    def _loop(self):
        while True:
            with self._cond:
                while not self._queue and not self._stopping:
                    self._cond.wait()
                if self._stopping:
                    return
                batch = list(self._queue)
                self._queue.clear()
            self._apply(batch)

    def _apply(self, batch):
        if all(isinstance(i, After) for i in batch):
            for item in batch:
                item.then()
            return
        faults = dict(self._book.faults)
        measured = self._measured() if any(isinstance(i, Report) for i in batch) else {}
        reports, clears, afters = [], [], []
        for item in batch:
            if isinstance(item, After):
                afters.append(item)
                continue
            if isinstance(item, Clear):
                clears.append((item, len(faults)))
                faults = {}
                continue
            for joint, angle in item.joints.items():
                old = faults.pop(joint, None)
                if angle is None and old is not None:
                    faults[joint] = old          # still stuck where it was reported
                else:
                    faults[joint] = Fault(angle, measured.get(joint))
            reports.append(item)
        self._commit(faults)                     # persisted before it is acknowledged
        self._on_accepted(reports, bool(clears), faults)
        for item, count in clears:
            item.done(count)
        for item in afters:
            item.then()

    def stop(self):
        """Stop the thread (queued items are dropped: they were never acknowledged)."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
