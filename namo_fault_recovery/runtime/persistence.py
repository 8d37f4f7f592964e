"""
The node's persistence: the state file, in the order the run book needs, off the hot paths.

Free of ROS.  A new fault set is made durable before anything acknowledges it, under one
lock with a sequence number: appended to the fault journal and synced (one line and one
``fdatasync``, see :mod:`.state_store`; the whole state file is rewritten only if the
journal cannot be written).  The state file (faults and library) follows each
publication: queued for a background writer under the same lock, so the numbers
say which of a library and a newer fault set came last and a slow write never
overwrites a newer state.  The run book gets the new fault set just before the write
(a table hit or the engine starts while the disk syncs), but every publication and
every answer waits for it: publishing takes the same lock, and the fault intake tells
its callers only after :meth:`Persistence.commit_faults` returns.  A write failure is
reported once and kept for ``/diagnostics``, never fatal.
"""

import itertools
import threading
import time

from .restore import plan_restart
from .state_store import BackgroundWriter, fingerprint, StateStore
from ..errors import shorten


class Persistence:
    """The state file of one node: fault commits, library writes, the restart plan."""

    def __init__(self, directory, robot, library, book, on_error):
        self.store = StateStore(directory)
        self.fingerprint = fingerprint(robot.source, library.source)
        self._robot = robot
        self._library = library
        self._book = book
        self._on_error = on_error          # on_error(text): log it
        self._lock = threading.Lock()
        # Above every change number on disk: a record of this run is never taken as older.
        self._seq = itertools.count(self.store.newest_seq() + 1)
        self._writer = BackgroundWriter(self._save)
        self.problem = None                # the last write problem, or a set-aside file
        self.corrections = ()              # ArmCorrection per arm, written with each state
        self._journal_failed = False

    def start(self):
        """Start the background writer."""
        self._writer.start()

    def commit_faults(self, faults, received_at=None):
        """
        Hand a new fault set to the run book and write it (synced): one step.

        The run book may start its run at once, but nothing is published before the
        write ends (publication takes this lock), and this returns only after it.
        ``received_at`` is when its first report arrived (``time.monotonic()``).  The
        journal line is written before the run is requested and synced right after, so
        that the run's first work (a table look-up) overlaps the disk's wait instead of
        holding the interpreter lock that the write needs to get there (measured: the
        sync began 0.43 ms after the request, p50, with the write after it).
        """
        with self._lock:
            library = self._book.current
            seq = next(self._seq)
            began = time.monotonic()
            problem = self._write_journal(seq, faults)
            self._book.set_faults(faults, durable=False, received_at=received_at)
            self._sync_journal(problem, faults, library, seq)
            self._book.faults_durable(time.monotonic() - began)

    def publish_and_queue(self, generation, faults, result, publish, in_hand=None):
        """
        Publish a run's library with ``publish`` if still current; queue it for the file.

        Returns the run book's callers to tell, or None if the run went stale.
        ``in_hand``: when the result became available (see :meth:`RunBook.publish`).
        """
        with self._lock:
            ready = self._book.publish(generation, result, publish, in_hand)
            if ready is not None:
                self._writer.submit(faults, result, next(self._seq))
        return ready

    def publish_refined_and_queue(self, generation, faults, result, publish):
        """Publish a refinement of ``generation`` if still current; queue it; return True."""
        with self._lock:
            published = self._book.publish_refined(generation, result, publish)
            if published:
                self._writer.submit(faults, result, next(self._seq))
        return published

    def adopt(self, learned, result, publish):
        """
        Take corrections measured on the robot (LearnedArm per arm) and their version.

        Under the lock: the run book gets ``learned``; ``result`` (the explored library
        version, or None) is published unless a run is pending, in which case (or with
        no result) a run on the corrected model is requested; then the state, the
        corrections with it, is queued for the file.  Returns True if ``result`` was
        published.
        """
        with self._lock:
            self.corrections = tuple(a.correction for a in learned)
            self._book.set_learned(learned)
            published = result is not None and self._book.publish_explored(result, publish)
            if not published:
                self._book.request()
            self._writer.submit(self._book.faults, self._book.current, next(self._seq))
        return published

    def plan_restart(self, settings):
        """Read the state file and return the RestartPlan (a bad file is set aside)."""
        plan = plan_restart(self.store, self._robot, self._library, self.fingerprint,
                            settings)
        if plan.problem:
            self.problem = shorten(plan.problem, 500)
        return plan

    def _write_journal(self, seq, faults):
        """Write the fault set to the journal, not synced; return the error, or None."""
        try:
            self.store.journal.write(seq, faults)
        except (OSError, ValueError) as exc:
            return exc
        return None

    def _sync_journal(self, problem, faults, library, seq):
        """Sync the journal written (``problem``: its write's error); else rewrite the file."""
        if problem is None:
            try:
                self.store.journal.sync()
                self._journal_failed = False
                return
            except (OSError, ValueError) as exc:
                problem = exc
        if not self._journal_failed:           # reported once, like a write failure
            self._on_error(f'cannot append to the fault journal {self.store.journal.path}: '
                           f'{problem}; rewriting the state file instead')
        self._journal_failed = True
        self._save(faults, library, seq)

    def _save(self, faults, library, seq=None):
        try:
            self.store.save(faults, library, self.fingerprint, seq, self.corrections)
            self.problem = None
        except (OSError, ValueError) as exc:
            if self.problem is None:
                self._on_error(f'cannot write the state file {self.store.path}: {exc}; the '
                               f'state will not survive a restart')
            self.problem = shorten(f'cannot write {self.store.path}: {exc}')

    def stop(self):
        """Write what is queued, then stop the writer and close the journal."""
        self._writer.stop()
        self.store.journal.close()
