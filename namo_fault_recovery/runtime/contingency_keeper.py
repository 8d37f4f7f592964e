"""
The node's contingency table: looked up before a live run, built in the background.

Free of ROS.  :class:`ContingencyKeeper` holds the
:class:`~namo_fault_recovery.recovery.contingency.ContingencyTable` for the robot, the
library and the settings in use (their fingerprint), kept in ``state_dir`` so that a
restart reuses it and a changed setting starts a new one.  A table built offline
(``namo-recovery precompute``) can be loaded too, if its fingerprint matches.

The entries still missing (every single fault; once faults are active, every further
single fault on top of them) are built by one child process (``spawn``) at the lowest
CPU priority (``nice`` 19, set by the node as soon as the child exists, so its start-up
is at that priority too), and stopped (``SIGSTOP``) while a live run computes, once it has
armed its death signal (a live run that began before is stopped then), so that it never
competes with one.  Each entry arrives over a pipe, joins the table, and the
table file is rewritten atomically.  :meth:`ContingencyKeeper.lookup` is a dictionary
look-up: a hit is published at once.  Its work is done when an entry joins the table
(loaded or built), off the fault's path: the entry is checked there
(:func:`~.restore.check_result`, an entry that fails it is dropped, so a hit needs no
check of its own), and ``prepare(result)``, given by the node, converts it to its
messages in advance.  A new plan (after each publication) waits
``HOLD_POLL`` s, and longer while ``hold()`` says a fault is being handled: planning and
starting a builder process hold the interpreter lock for milliseconds, which a fault's
intake and publication need more.
"""

from dataclasses import replace
import math
import multiprocessing
import os
import signal
import threading
import time

from . import diagnostic_keys as dk
from .engine_process import die_with_parent
from .realtime import leave_fifo
from .restore import check_result
from ..recovery.contingency import (ContingencyTable, entry_key, fault_sets, measure_entry,
                                    table_fingerprint, table_locks)
from ..recovery.motion import typical_points

TABLE_FILE = 'contingency_table.json'
BUILD_SEEDS = (0, 1, 2, 3)
HOLD_POLL = 0.05          # s: a new plan waits this long, then while hold() is true


def _build(conn, robot, library, settings, plan, seeds, parent_pid=None):
    """Child: build each fault set of ``plan`` at the lowest priority; send each entry."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # Ctrl-C is the node's to handle
    leave_fifo()             # a real-time node's child computes under the normal scheduler
    die_with_parent(parent_pid)
    conn.send(('armed', None, None, 0.0))            # from now on it may be stopped
    try:
        os.nice(19)
    except OSError:
        pass
    quantisations = typical_points(robot, library, settings.vq_distortion_mm)
    for faults in plan:
        built = measure_entry(robot, library, faults, settings, seeds,
                              quantisations=quantisations)
        conn.send(('entry', built.locks, built.result, built.cpu_sec))
    conn.send(('done', None, None, time.process_time()))   # the whole process's CPU


def load_tables(path, offline_file, fingerprint, admit, log):
    """
    Return (the table for ``fingerprint``: ``path``'s, then ``offline_file``'s; lines to log).

    An entry is kept if ``admit(locks, result)`` (checked, then prepared); a file made
    for another fingerprint adds nothing (``offline_file``'s reason is logged at once).
    """
    table, reason = ContingencyTable.load(path, fingerprint)
    said = [] if reason else [f'contingency table: {len(table)} entries reused from {path}']
    if offline_file:
        offline, why = ContingencyTable.load(offline_file, fingerprint)
        if why is None:
            for key, (locks, result) in offline.entries.items():
                table.entries.setdefault(key, (locks, result))
            said.append(f'contingency table: {len(offline)} entries loaded from '
                        f'{offline_file}')
        else:
            log('warning', why)
    for key, (locks, result) in list(table.entries.items()):
        if not admit(locks, result):
            del table.entries[key]
    return table, said


class ContingencyKeeper:
    """The table of one node: lookup, background build, persistence."""

    def __init__(self, robot, library, state_dir, log, offline_file=None, seeds=BUILD_SEEDS,
                 hold=lambda: False, prepare=None):
        self._hold = hold                     # hold() true: plan later (a fault is handled)
        self._prepare = prepare               # prepare(result): an entry joined the table
        self._robot = robot
        self._library = library
        self._path = os.path.join(os.path.expanduser(str(state_dir)), TABLE_FILE)
        self._offline = offline_file or None
        self._log = log                       # log(level, text)
        self._seeds = tuple(seeds)
        self._lock = threading.Lock()
        self._ctx = multiprocessing.get_context('spawn')
        self._table = None
        self._fp_cache = None
        self._wanted = None                   # (settings, active) to apply next
        self._wanted_cond = threading.Condition()
        self._thread = None
        self._stopping = False
        self._plan_keys = ()
        self._asked = None                    # the settings of the newest configure()
        self._applied = None                  # the settings whose table is in use
        self._proc = None
        self._conn = None
        self._reader = None
        self._paused = self._armed = False  # armed: the builder set its death signal
        self._pause_wanted = False          # a live run computes (stop it once armed)
        self.building = False

    # --- lookup ---------------------------------------------------------------------

    def lookup(self, faults, settings, measured=None):
        """
        Return the table's library for ``faults`` (origin ``table``), or None.

        A library returned passed :func:`~.restore.check_result` for its fault set when
        its entry joined the table (the robot and the library do not change).
        The hit is served now, within the node's deadline (``settings.deadline_sec``):
        that is its deadline, met.  The search that made the entry in advance keeps its
        own time and statuses (the library's ``wall_time``, each gesture's), so an
        entry built under a small budget does not read as a deadline missed now.
        """
        with self._lock:
            table = self._table
            if table is None or table.fingerprint != self._fingerprint(settings):
                return None
        try:
            locks = table_locks(self._robot, self._library, faults, settings, measured)
        except ValueError:
            return None
        hit = table.lookup(locks)
        if hit is None:
            return None
        return replace(hit, faults=dict(faults), origin='table',
                       deadline=settings.deadline_sec or None, deadline_met=True,
                       success=not hit.cancelled and all(
                           math.isfinite(g.score_after) for g in hit.gestures))

    @property
    def entries(self):
        """Return the number of entries of the table in use."""
        with self._lock:
            return 0 if self._table is None else len(self._table)

    def status(self) -> tuple:
        """Return (``loading``, ``building`` or ``complete``; entries; missing) of the table."""
        with self._lock:
            table = self._table
            if table is None or self._applied != self._asked:
                return dk.TABLE_LOADING, 0 if table is None else len(table), 0
            # Entries of the plan not in yet: being built (or about to be, between plans).
            missing = sum(key not in table.entries for key in self._plan_keys)
            return (dk.TABLE_BUILDING if missing else dk.TABLE_COMPLETE), len(table), \
                missing

    # --- configuration and build ----------------------------------------------------

    def configure(self, settings, active=None):
        """
        Use the table for ``settings``; build what is missing for the ``active`` locks.

        Returns at once: the keeper's thread loads the table file (or the offline one)
        when the fingerprint changed, then (re)starts the builder on the fault sets not
        yet in the table.
        """
        with self._lock:
            self._asked = settings               # status(): loading until _apply has it
        with self._wanted_cond:
            self._wanted = (settings, dict(active or {}))
            self._wanted_cond.notify()
            if self._thread is None:
                self._thread = threading.Thread(target=self._keep, name='table-keeper',
                                                daemon=True)
                self._thread.start()

    def _keep(self):
        while True:
            with self._wanted_cond:
                while self._wanted is None and not self._stopping:
                    self._wanted_cond.wait()
                if self._stopping:
                    return
            time.sleep(HOLD_POLL)                     # the publication's followers first
            while self._hold() and not self._stopping:
                time.sleep(HOLD_POLL)
            with self._wanted_cond:
                if self._stopping:
                    return
                settings, active = self._wanted
                self._wanted = None
            try:
                self._apply(settings, active)
            except Exception as exc:  # noqa: B902 - the table is an optimisation only
                self._log('warning', f'contingency table: {type(exc).__name__}: {exc}')

    def _apply(self, settings, active):
        fingerprint = self._fingerprint(settings)
        with self._lock:
            table = self._table
        if table is None or table.fingerprint != fingerprint:
            table, said = load_tables(self._path, self._offline, fingerprint, self._admit,
                                      self._log)         # checked and prepared, off the lock
            with self._lock:
                self._table, self._plan_keys = table, ()
            for text in said:                        # in use from now on: say so
                self._log('info', text)
        try:
            plan = fault_sets(self._robot, self._library, settings, active=active)
        except ValueError as exc:
            self._log('warning', f'contingency table: {exc}; nothing more is built')
            plan = []
        keys = [entry_key(table_locks(self._robot, self._library, f, settings)) for f in plan]
        missing = [(k, f) for k, f in zip(keys, plan) if k not in table.entries]
        keys = tuple(k for k, _ in missing)
        with self._lock:
            # The table and its plan's missing entries in one step: status() never
            # reads the new settings with the previous plan (a 'complete' in between).
            self._applied = settings
            if keys == self._plan_keys and (self.building or not keys):
                return
            self._plan_keys = keys
        self._stop_builder()
        if missing and not self._stopping:
            self._start_builder(settings, [f for _, f in missing])

    def _fingerprint(self, settings):
        cached = self._fp_cache
        if cached is not None and cached[0] == settings:
            return cached[1]
        fingerprint = table_fingerprint(self._robot, self._library, settings)
        self._fp_cache = (settings, fingerprint)
        return fingerprint

    def _admit(self, locks, result):
        """Return True if an entry may be served (checked, then prepared); log why not."""
        problem = check_result(self._robot, self._library, result, locks)
        if problem:
            self._log('warning', f'contingency table: the entry for {sorted(locks)} is not '
                                 f'served: {problem}')
            return False
        if self._prepare is not None:
            self._prepare(result)
        return True

    def _start_builder(self, settings, plan):
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_build, name='namo-recovery-table', daemon=True,
                                 args=(child, self._robot, self._library, settings, plan,
                                       self._seeds, os.getpid()))
        proc.start()
        child.close()
        try:
            # At once, from here: its start-up (imports) must not compete with a live run
            # either, and it may not be stopped before it has armed its death signal.
            os.setpriority(os.PRIO_PROCESS, proc.pid, 19)
        except OSError:
            pass
        with self._lock:
            self._proc, self._conn, self.building = proc, parent, True
            self._paused = self._armed = self._pause_wanted = False
        self._reader = threading.Thread(target=self._receive, args=(parent, proc),
                                        name='table-builder', daemon=True)
        self._reader.start()
        count = f'{len(plan)} entries' if len(plan) != 1 else '1 entry'
        self._log('info', f'contingency table: building {count} in the background (pid '
                          f'{proc.pid}, nice 19)')

    def _receive(self, conn, proc):
        began = time.monotonic()
        built = 0
        cpu_total = 0.0
        while True:
            try:
                kind, locks, result, cpu = conn.recv()
            except (EOFError, OSError):
                return                               # stopped (a new plan, or the node)
            if kind == 'armed':
                pause = False
                with self._lock:
                    if self._proc is proc:
                        self._armed = True
                        pause = self._pause_wanted
                if pause:
                    self.pause()                     # a live run began while it started
                continue
            if kind == 'done':
                with self._lock:
                    if self._proc is proc:
                        self.building = False
                self._log('info', f'contingency table: {built} entries built in '
                                  f'{time.monotonic() - began:.1f} s ({cpu:.1f} s of CPU in '
                                  f'the builder process, {cpu_total:.1f} s of it searching)')
                return
            admitted = self._admit(locks or result.locks, result)
            with self._lock:
                if self._proc is not proc or self._table is None:
                    return
                if admitted:
                    self._table.add(result, locks)
                cpu_total += cpu
                table = self._table
            built += 1
            self._save(table)

    def _save(self, table):
        try:
            table.save(self._path)
        except OSError as exc:
            self._log('warning', f'contingency table: cannot write {self._path}: {exc}')

    @property
    def builder_pid(self):
        """Return the pid of the builder process, None when none runs."""
        proc = self._proc
        return None if proc is None else proc.pid

    @property
    def armed(self):
        """Return whether the builder armed its death signal (only then is it ever stopped)."""
        return self._armed

    # --- the live run comes first ---------------------------------------------------

    def pause(self):
        """Stop the builder while a live run computes (SIGSTOP)."""
        self._signal(signal.SIGSTOP, True)

    def resume(self):
        """Let the builder go on (SIGCONT)."""
        self._signal(signal.SIGCONT, False)

    def _signal(self, signum, paused):
        with self._lock:
            proc = self._proc
            self._pause_wanted = paused
            if proc is None or self._paused == paused or not proc.is_alive():
                return
            if paused and not self._armed:
                # Still starting: stopped now, it could never arm its death signal, and
                # a node killed meanwhile would leave it stopped for ever.  It is stopped
                # once armed, if the live run still computes.
                return
            try:
                os.kill(proc.pid, signum)
                self._paused = paused
            except OSError:
                pass

    def _stop_builder(self):
        with self._lock:
            proc, conn = self._proc, self._conn
            self._proc = self._conn = None
            self.building = False
            self._paused = False
        if proc is None:
            return
        try:
            os.kill(proc.pid, signal.SIGCONT)
        except OSError:
            pass
        proc.kill()
        proc.join(timeout=2.0)
        conn.close()

    def stop(self):
        """Stop the keeper's thread and the builder (the file keeps what was built)."""
        with self._wanted_cond:
            self._stopping = True
            self._wanted_cond.notify()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self._stop_builder()
        reader = self._reader
        if reader is not None:
            reader.join(timeout=5.0)     # an entry received is saved before stop returns
