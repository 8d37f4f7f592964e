"""
Fault intake: every accepted fault report is persisted before it is acknowledged.

Free of ROS.  The ``/actuator_fault`` callback only validates a report and queues it
here, so that a burst is taken off the subscription as fast as it arrives.  One thread
drains the queue in batches: it applies every queued report (and ``clear``) in order to
the fault set, and ``commit`` hands the new fault set to the run book and returns only
once it is in the state file (atomically, synced; the engine may start meanwhile, but
nothing is published before the write ends); then ``on_accepted`` runs (it logs
``fault accepted``).  A crash at any moment therefore loses only reports that were never
acknowledged, and a burst of N reports costs one file write per batch, not N.

A batch of reports alone (no clear, no caller waiting) is acknowledged once its library
is out, or after ``SETTLE_SEC``: a table hit is published by the dispatcher within a
millisecond or two of the write, and the acknowledgement (a log line, a wake-up of the
executor) made at the same moment held the interpreter lock that the publication needed
(measured: the lock handed to the dispatcher 2.8 ms after the write, p50, on a busy
machine).  A live search keeps computing; its faults are acknowledged ``SETTLE_SEC``
after they are on disk.
"""

from collections import deque
from dataclasses import dataclass
import threading

from .state_store import Fault

SETTLE_SEC = 0.01      # s: a batch of reports waits at most this long for its library


@dataclass(frozen=True)
class Report:
    """
    One validated fault report: joint -> lock angle (rad) or None.

    ``received`` is the ``time.monotonic()`` instant the message arrived, if known: the
    commit is told the earliest of a batch (the node shows ``fault_to_request_sec``).
    """

    joints: dict
    received: float = None


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

    def __init__(self, book, commit, on_accepted, measured=lambda: {}, max_queue=100_000,
                 on_error=None):
        self._book = book
        # commit(faults[, received_at=]): book.set_faults, persisted before it returns
        self._commit = commit
        self._on_accepted = on_accepted    # on_accepted(reports, cleared, faults)
        self._measured = measured          # latest measured angles (joint -> rad)
        self._queue = deque()
        self._max_queue = max_queue
        self._cond = threading.Condition()
        self._stopping = False
        self._on_error = on_error          # on_error(exc): the batch failed (a bug)
        self.dropped = 0
        self._applying = False
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
                self._applying = True
            try:
                self._apply(batch)
            except Exception as exc:  # noqa: B902 - the intake must outlive any bug
                if self._on_error is not None:
                    self._on_error(exc)
                for item in batch:             # nobody waits for an answer forever
                    if isinstance(item, After):
                        item.then()
                    elif isinstance(item, Clear):
                        item.done(0)
            finally:
                with self._cond:
                    self._applying = False

    def _apply(self, batch):
        if all(isinstance(i, After) for i in batch):
            for item in batch:
                item.then()
            return
        faults = dict(self._book.faults)
        measured = self._measured() if any(isinstance(i, Report) for i in batch) else {}
        reports, clears, afters = [], [], []
        received = [i.received for i in batch
                    if isinstance(i, Report) and i.received is not None]
        for item in batch:
            if isinstance(item, After):
                afters.append(item)
                continue
            if isinstance(item, Clear):
                clears.append((item, len(faults)))
                faults = {}
                continue
            for joint, angle in item.joints.items():
                old = faults.get(joint)          # a joint keeps its place (arrival order)
                if angle is None and old is not None:
                    continue                     # still stuck where it was reported
                faults[joint] = Fault(angle, measured.get(joint) if old is None
                                      else old.measured)
            reports.append(item)
        if received:                             # persisted before it is acknowledged
            self._commit(faults, received_at=min(received))
        else:
            self._commit(faults)
        if reports and not clears and not afters:
            self._book.wait_published(SETTLE_SEC)   # a table hit goes out first
        self._on_accepted(reports, bool(clears), faults)
        for item, count in clears:
            item.done(count)
        for item in afters:
            item.then()

    def busy(self):
        """
        Return True from a report's arrival until its library is out (or its run failed).

        What the node's followers of a publication (markers, the table's next plan) wait
        for: while it holds, a table hit is milliseconds from its publication.
        """
        with self._cond:
            if self._queue or self._applying:
                return True
        return self._book.pending()

    def stop(self):
        """Stop the thread (queued items are dropped: they were never acknowledged)."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
