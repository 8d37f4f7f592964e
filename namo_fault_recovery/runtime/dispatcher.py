"""
The dispatcher: takes the newest request from the run book, runs it, publishes it.

Free of ROS.  One plain thread (never an executor thread) waits for a request, sends it
to the engine process with the deadline counted from the moment it was requested (the
engine keeps a margin of it for the work after the search, publishing included), checks
the result and publishes it, unless a newer request superseded it meanwhile (the node then
writes it to the state file, off this path).  Publishing is a callable given by the node.
A run with no structure change (no fault, no tool, no correction learned on the robot)
needs no engine: the reference library is published at once.  With a learned correction
(the run's ``learned``) the engine searches on the corrected model and the contingency
table, computed on the nominal one, is not consulted.  A table hit was checked when its
entry joined the table (:mod:`.contingency_keeper`): it is published without a check of
its own, so that the fault's path is the durable write and the messages alone.
"""

from dataclasses import replace
import math
import threading
import time

from .engine_process import EngineError
from .restore import check_result
from ..recovery.engine import recover, structure_changed
from ..recovery.result import summary


class Dispatcher:
    """The thread between the run book and the engine process."""

    def __init__(self, book, engine, robot, library, config, publish, log,
                 publish_refined=None, table=None):
        self._book = book
        self._engine = engine
        self._robot = robot
        self._library = library
        self._config = config              # callable: the current NodeConfig
        # publish(generation, faults, result, in_hand) -> callers; in_hand: the
        # time.monotonic() the result became available (for ``publish_path_sec``)
        self._publish = publish
        self._log = log                    # log(level, text)
        # publish_refined(generation, faults, result) -> True if published
        self._publish_refined = publish_refined
        self._table = table                # a ContingencyKeeper, or None
        self._thread = threading.Thread(target=self._loop, name='dispatcher', daemon=True)
        self.last_engine_time = 0.0

    def start(self):
        """Start the dispatcher thread."""
        self._thread.start()

    def join(self, timeout=5.0):
        """Wait for the thread to end (after the run book stopped)."""
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _loop(self):
        while True:
            run = self._book.next_run()
            if run is None:
                return
            try:
                self._handle(run)
            except Exception as exc:  # noqa: B902 - the dispatcher must outlive any bug
                if self._book.stopping:
                    return
                self._book.notify(self._book.failed(run.generation,
                                                    f'{type(exc).__name__}: {exc}'))
                try:
                    self._log('error', f'reconfiguration: {type(exc).__name__}: {exc}; '
                                       f'previous library kept')
                except Exception:  # noqa: B902 - not even a logging problem stops it
                    pass

    def _handle(self, run):
        config = self._config()
        settings = config.settings
        faults = {j: f.angle for j, f in run.faults.items()}
        checked = False                           # a table hit: checked in advance
        if not structure_changed(faults, settings) and not run.learned:
            # No structure change: the engine returns the reference library at once.
            result = recover(self._robot, self._library, faults, settings, seed=config.seed)
        else:
            measured = {j: f.measured for j, f in run.faults.items() if f.measured is not None}
            # The table was computed on the nominal model: not for a corrected arm.
            result = None if run.learned else self._lookup(faults, settings, measured, config)
            checked = result is not None
            if result is None:
                if self._table is not None:
                    self._table.pause()            # the live run gets the CPU
                try:
                    result, self.last_engine_time = self._engine.run(
                        run.generation, faults, settings, config.seed, run.requested_at,
                        measured, run.learned)
                except EngineError as exc:
                    self._fail(run, str(exc))
                    return
                finally:
                    if self._table is not None:
                        self._table.resume()
        in_hand = time.monotonic()
        if not self._book.is_current(run.generation):
            return                                # superseded: a newer run answers
        problem = None if checked else check_result(self._robot, self._library, result,
                                                    run.faults)
        if problem:
            self._fail(run, problem)
            return
        refine = result.origin == 'deadline' and config.refine_budget_sec > 0 \
            and self._publish_refined is not None
        if refine:
            self._book.refinement_follows(run.generation)
        # Published if still current, then written to the state file off this path.
        ready = self._publish(run.generation, run.faults, result, in_hand)
        if ready is None:
            return
        self._book.notify(ready)
        level = 'info' if result.success else 'warning'
        if all(math.isfinite(g.score_after) for g in result.gestures):
            self._log(level, summary(result))
        if self._table is not None and config.contingency_table:
            # The table is keyed by the arms' locks: a torso held where it stuck is not in it.
            self._table.configure(settings, active={
                j: a for j, a in result.locks.items() if j in self._robot.joint_names})
        if refine:
            self._refine(run, result, config)

    def _lookup(self, faults, settings, measured, config):
        """Return the contingency table's library for ``faults``, or None (a miss)."""
        if self._table is None or not config.contingency_table:
            return None
        return self._table.lookup(faults, settings, measured)

    def _refine(self, run, result, config):
        """Keep improving ``run``'s library in the engine until done or superseded."""
        version = self._book.refining(run.generation)     # the deadline result's
        if not version:
            return

        def improved(better):
            if check_result(self._robot, self._library, better, run.faults):
                return                            # never publish a library that fails it
            better = replace(better, refines_version=version)
            if self._publish_refined(run.generation, run.faults, better):
                self._log('info', f'refined: {summary(better)}')

        try:
            self._engine.refine(run.generation, result, config.settings,
                                config.refine_budget_sec, improved, run.learned)
        except EngineError as exc:
            self._log('warning', f'refinement stopped: {exc}; the published library stays')
        finally:
            self._book.refined(run.generation)

    def _fail(self, run, reason):
        ready = self._book.failed(run.generation, reason)
        self._book.notify(ready)
        if ready or self._book.is_current(run.generation):
            self._log('error', f'reconfiguration failed: {reason}; previous library kept')
