"""
The engine in its own process, so that it never shares an interpreter lock with the node.

Free of ROS.  :class:`EngineProcess` starts one child process (``spawn``: no DDS thread is
forked) that loads the robot and the library once, keeps the typical points, and answers
one request at a time over a pipe with :func:`~namo_fault_recovery.recovery.engine.recover`.
The deadline's start travels as a ``time.monotonic()`` instant (one system-wide clock on
Linux), and a shared counter cancels a run as soon as a newer one is wanted.  A child
that dies or hangs is replaced, and the run is reported failed.

A deadline run computes at the nice value the node gives (``engine_nice``: a fault's
recovery comes before the robot's best-effort work); the warm-up and the background
refinements compute at the child's own nice value.
"""

import ctypes
import multiprocessing
import os
import signal
import time
import traceback

from .realtime import leave_fifo, set_nice

_STOP = None
_REFINE = 'refine'
_PR_SET_PDEATHSIG = 1


class EngineError(RuntimeError):
    """The engine process failed a run (the message says why)."""


def die_with_parent(parent_pid=None):
    """
    Ask Linux to kill this (child) process when its parent dies, even by SIGKILL.

    The request is made by the child once it runs, so a parent that died while the
    child was still starting would never deliver the signal: with ``parent_pid`` (the
    parent's pid, taken before the start) the child then exits at once.
    """
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass            # not Linux: the pipe's EOF still ends the child
    if parent_pid is not None and os.getppid() != parent_pid:
        os._exit(0)     # the parent is already gone: nobody is left to read our answers


def _load_models(conn):
    """
    Child: return the (robot, library, nice) the first message names; None if told to stop.

    The files come over the pipe: a child started before the node knew them
    (:meth:`EngineProcess.early`) has done its imports meanwhile.
    """
    from .robot_source import load_models
    try:
        files = conn.recv()
    except (EOFError, OSError):
        return None                                  # the node went away (or refused)
    if files is _STOP:
        return None
    # files[0]: a RobotSource (a profile and its URDF), or a DH robot file (None: Namo's).
    # The node reports the library's warnings; the engine child loads it silently.
    return (*load_models(files[0], files[1], on_warning=lambda line: None), files[2])


def _run_nice(nice):
    """
    Child: return ``(its own nice, the nice value of deadline runs, the refusal or None)``.

    The refusal is sent to the node (which logs it) and the runs keep the child's own.
    """
    base = os.getpriority(os.PRIO_PROCESS, 0)
    if nice == base:
        return base, base, None
    refused = set_nice(nice)
    set_nice(base)            # back (a nice raised above base may stay: not permitted)
    return (base, base, refused) if refused else (base, nice, None)


def _serve(conn, current, parent_pid=None):
    """Child main loop: import, load the models, warm up, then answer until told to stop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # Ctrl-C is the parent's to handle
    leave_fifo()             # a real-time node's child computes under the normal scheduler
    die_with_parent(parent_pid)
    # Imported before the files come: an early child does it while the node starts.
    from ..recovery.engine import recover  # noqa: F401 - _warm_up and _run use it
    from ..recovery.motion import typical_points

    models = _load_models(conn)
    if models is None:
        return
    robot, library, nice = models
    base, run_nice, refused = _run_nice(nice)
    cache = {}

    def quantisations(vq_distortion_mm, clock=None):
        """Typical points per threshold; computed within the run's clock, kept if whole."""
        if vq_distortion_mm in cache:
            return cache[vq_distortion_mm]
        found = typical_points(robot, library, vq_distortion_mm, clock=clock)
        if not any(q is not None and q.note for q in found.values()):
            cache.clear()
            cache[vq_distortion_mm] = found      # complete: reuse it in every later run
        return found

    _warm_up(robot, library, quantisations)
    conn.send(('ready', os.getpid(), refused))
    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError):
            return                                   # the node went away
        if request is _STOP:
            return
        # Each run computes at its own nice (allowed: both were tried at start).
        if request[0] == _REFINE:
            set_nice(base)
            _refine(conn, robot, library, request[1:], current, quantisations)
        else:
            set_nice(run_nice)
            _run(conn, robot, library, request, current, quantisations)


def _warm_up(robot, library, quantisations):
    """Child: pay the one-off costs (first allocations, caches) before any fault."""
    from ..optimize.base import Clock
    from ..recovery.engine import recover, RecoverySettings
    try:
        joint = robot.arms['right'].joint_names[0]
        recover(robot, library, {joint: None}, RecoverySettings(trajectory_method='kriging'),
                seed=0, clock=Clock(0.3), quantisations=quantisations(
                    RecoverySettings().vq_distortion_mm))
    except Exception:  # noqa: B902 - a warm-up problem is reported by the real runs
        pass


def _run(conn, robot, library, request, current, quantisations):
    """Child: answer one deadline run (its result, or why it failed)."""
    from ..optimize.base import Clock
    from ..recovery.engine import recover
    run_id, faults, settings, seed, start, measured, learned = request

    def cancel():
        return current.value != run_id

    try:
        clock = Clock(settings.deadline_sec, cancel, start=start)
        began = time.monotonic()
        quant = quantisations(settings.vq_distortion_mm, clock)
        result = recover(robot.with_learned(learned), library, faults, settings,
                         seed=seed, clock=clock, measured=measured, quantisations=quant)
        conn.send(('ok', run_id, result, time.monotonic() - began))
    except Exception as exc:  # noqa: B902 - report every failure to the node
        conn.send(('error', run_id, f'{type(exc).__name__}: {exc}'[:500],
                   traceback.format_exc(limit=5)[-2000:]))


def _refine(conn, robot, library, request, current, quantisations):
    """Child: send each better library of a refinement, then its end."""
    from ..optimize.base import Clock
    from ..recovery.refine import refinements

    run_id, published, settings, budget, learned = request
    robot = robot.with_learned(learned)

    def cancel():
        return current.value != run_id

    tries = 0
    try:
        clock = Clock(budget, cancel)
        quant = quantisations(settings.vq_distortion_mm, clock)
        for better in refinements(robot, library, published, settings, clock=clock,
                                  quantisations=quant):
            tries += 1
            conn.send(('improved', run_id, better))
        reason = 'cancelled' if cancel() else ('budget' if clock.expired() else 'converged')
        conn.send(('refined', run_id, reason))
    except Exception as exc:  # noqa: B902 - report every failure to the node
        conn.send(('refined', run_id, f'failed: {type(exc).__name__}: {exc}'[:500]))


class EngineProcess:
    """A child process running the engine; one run at a time, cancellable."""

    def __init__(self, robot_file=None, gesture_file=None, start_timeout=60.0, nice=0):
        self._files = (robot_file, gesture_file, nice)
        self._ctx = multiprocessing.get_context('spawn')
        self._current = self._ctx.Value('q', 0, lock=False)
        self._start_timeout = start_timeout
        self._proc = None
        self._conn = None
        self.pid = None
        self.nice_refused = None     # why the child could not take its nice value, if so
        self.restarts = 0

    @classmethod
    def early(cls):
        """
        Return an engine whose child is started now, before its files are known.

        The child imports the engine (about a second) while the node still imports and
        reads its parameters; :meth:`load` then gives it the files.  Measured on 2
        idle cores: the engine ready 1.7 s after ``recovery_node``'s exec (2.7 s when
        started after the node's imports).
        """
        engine = cls()
        engine._files = None
        engine.start()
        return engine

    def start(self):
        """Start the child (returns at once; :meth:`run` waits until it is ready)."""
        parent, child = self._ctx.Pipe()
        self._proc = self._ctx.Process(
            target=_serve, args=(child, self._current, os.getpid()),
            name='namo-recovery-engine', daemon=True)
        self._proc.start()
        child.close()
        self._conn = parent
        self.pid = None
        if self._files is not None:
            self._conn.send(self._files)

    def load(self, robot, gesture_file, start_timeout, nice=0):
        """
        Give the engine its robot, library, start timeout and nice (an early child or new).

        ``robot`` is a :class:`~.robot_source.RobotSource`, or a DH robot file (None:
        Namo's); ``gesture_file`` None is the packaged library.  Deadline runs compute at
        ``nice`` (:attr:`nice_refused` says why not, once ready).
        """
        self._start_timeout = start_timeout
        early = self._files is None and self._proc is not None
        self._files = (robot, gesture_file, nice)
        if not early:
            self._kill()
            self.start()
            return
        try:
            self._conn.send(self._files)
        except (OSError, ValueError):
            self._kill()                             # it died while importing: a new one
            self.start()

    def wait_ready(self, timeout=60.0, keep_waiting=lambda: True):
        """
        Wait until the child has loaded the models and warmed up; raise EngineError if not.

        Polls in short steps so that ``keep_waiting()`` returning False (e.g. ROS was shut
        down by a signal) ends the wait at once.
        """
        end = time.monotonic() + timeout
        while self.pid is None:
            if not keep_waiting():
                raise EngineError('start-up was interrupted')
            remaining = end - time.monotonic()
            if remaining <= 0:
                raise EngineError(f'the engine process was not ready within {timeout:.0f} s')
            try:
                if self._conn.poll(min(remaining, 0.05)):
                    kind, pid, self.nice_refused = self._conn.recv()
                    self.pid = pid
            except (EOFError, OSError):
                raise EngineError('the engine process died while starting') from None

    def _ensure_ready(self, deadline):
        if self.pid is None:
            self.wait_ready(max(deadline - time.monotonic(), 0.0))

    def cancel(self):
        """Cancel the run under way (it returns soon with its best so far)."""
        self._current.value = -1

    def run(self, run_id, faults, settings, seed, start, measured, learned=(),
            hang_margin=5.0):
        """
        Run the engine for one request; return ``(LibraryResult, seconds in the child)``.

        ``learned`` are the corrections learned on the robot (``model.structure``'s
        LearnedArm, compiled in the node): the search runs on that corrected model.

        ``start`` is the ``time.monotonic()`` instant the request was made: the deadline
        ``settings.deadline_sec`` counts from there, across the processes.  Raises
        :class:`EngineError` if the run fails, or if the child dies or does not answer
        within the deadline plus ``hang_margin`` (the child is then replaced).
        """
        end = start + settings.deadline_sec + hang_margin
        answer = self._exchange(run_id, (run_id, faults, settings, seed, start, measured,
                                         tuple(learned)), end, lambda answer: answer)
        if answer[0] == 'ok':
            return answer[2], answer[3]
        raise EngineError(answer[2])

    def refine(self, run_id, published, settings, budget, on_improved, learned=(),
               hang_margin=5.0):
        """
        Refine ``published`` in the child for ``budget`` seconds; return why it ended.

        Calls ``on_improved(result)`` for each better library as it arrives.  A newer run
        cancels it (:meth:`cancel`).  Raises :class:`EngineError` as :meth:`run` does.
        """
        def handle(answer):
            if answer[0] == 'improved':
                on_improved(answer[2])
                return None
            return answer[2]
        end = time.monotonic() + budget + hang_margin
        return self._exchange(run_id, (_REFINE, run_id, published, settings, budget,
                                       tuple(learned)), end, handle)

    def _exchange(self, run_id, request, end, handle):
        """
        Send ``request``; give each answer of ``run_id`` to ``handle`` until it returns one.

        Answers of an earlier run (e.g. a refinement's last message) are skipped.  A child
        that dies, or is silent until ``end`` (monotonic s), is replaced: EngineError.
        """
        try:
            self._ensure_ready(time.monotonic() + self._start_timeout)
            self._current.value = run_id
            self._conn.send(request)
            while True:
                limit = max(end - time.monotonic(), 0.0)
                if not self._conn.poll(limit):
                    raise EngineError('the engine process did not answer in time; it was '
                                      'restarted')
                answer = self._conn.recv()
                if answer[1] != run_id:
                    continue
                done = handle(answer)
                if done is not None:
                    return done
        except (EOFError, OSError, BrokenPipeError) as exc:
            self._restart()
            raise EngineError(f'the engine process died ({type(exc).__name__}); it was '
                              f'restarted') from None
        except EngineError:
            self._restart()
            raise

    def _restart(self):
        self.restarts += 1
        self._kill()
        self.start()

    def _kill(self):
        if self._proc is not None and self._proc.is_alive():
            self._proc.kill()
            self._proc.join(timeout=2.0)
        if self._conn is not None:
            self._conn.close()

    def stop(self, timeout=2.0):
        """Ask the child to stop; kill it if it does not (at once if it is not ready yet)."""
        if self._proc is None:
            return
        if self.pid is None:
            # Still importing or loading (e.g. the node refused its configuration): it
            # holds nothing, and waiting would hold up the node's exit for as long.
            self._kill()
            self._proc = None
            return
        self.cancel()
        try:
            self._conn.send(_STOP)
        except (OSError, ValueError):
            pass
        self._proc.join(timeout=timeout)
        self._kill()
        self._proc = None
