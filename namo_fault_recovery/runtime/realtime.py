"""
Real-time scheduling (``SCHED_FIFO``) for a process's own threads, as robots' nodes ask for it.

Free of ROS.  On a busy robot a fault's table hit is a few milliseconds of work spread
over several wake-ups (the middleware's threads, the executor, the intake, the
publisher), and under the normal scheduler each wake-up can wait behind a process that
computes: measured with a CPU burner on the other core, the hit seen by an outside
client went from p95 3.9 ms to 7-9 ms.  ros2_control's controller manager meets the
same problem with its ``thread_priority`` parameter (``SCHED_FIFO``, refused politely
where the user's ``rtprio`` limit does not allow it); :func:`set_fifo_priority` does
that for every thread of this process, those the middleware already started included.

Threads started later inherit the policy (``SCHED_RESET_ON_FORK`` is not used: Linux
applies it to new threads as well as to new processes).  Child processes would inherit
it too, so every child entry point of the node calls :func:`leave_fifo` first: the
engine's and the table's computing must never run real-time, or the consumers of the
library it computes would starve (measured: with the engine at FIFO too, a table miss
reached a normal-priority client 134 ms late at p95).

The engine's own CPU share is the other half (``engine_nice``, :func:`set_nice`): a
deadline run computes at a lower nice value than the robot's best-effort work, still
under the normal scheduler, so that a busy core delays a recovery less without ever
starving anyone (SCHED_OTHER weights: nice -5 is three times nice 0's share).
"""

import os
import resource
from typing import Optional

MAX_PRIORITY = 99


def _thread_ids():
    """Return the ids of this process's threads (Linux)."""
    return sorted(int(tid) for tid in os.listdir('/proc/self/task'))


def _refused(priority, exc):
    """Return the one-line reason a FIFO ``priority`` was refused, with the limit to raise."""
    try:
        limit = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
        hint = (f"this process's real-time priority limit (RLIMIT_RTPRIO) is {limit}; "
                f'raise it for the user, e.g. "@realtime - rtprio 98" in '
                f'/etc/security/limits.conf')
    except (AttributeError, ValueError, OSError):
        hint = 'this system has no real-time priority limit to raise'
    reason = getattr(exc, 'strerror', None) or str(exc)
    return (f'thread_priority: cannot use SCHED_FIFO priority {priority} ({reason}); '
            f'{hint}; running under the normal scheduler')


def set_fifo_priority(priority: int) -> Optional[str]:
    """
    Put every thread of this process under ``SCHED_FIFO`` at ``priority`` (0: no change).

    Threads started later inherit the policy, and so do child processes (which call
    :func:`leave_fifo`).  Return None when done, else the one-line reason it was
    refused; the threads changed before a refusal are put back, so the process is never
    half real-time.
    """
    if not 0 <= priority <= MAX_PRIORITY:
        raise ValueError(f'thread_priority: expected 0 .. {MAX_PRIORITY}, '
                         f'got {priority!r}')
    if priority == 0:
        return None
    changed = []
    try:
        policy = os.SCHED_FIFO
        for tid in _thread_ids():
            try:
                os.sched_setscheduler(tid, policy, os.sched_param(priority))
            except ProcessLookupError:
                continue                  # the thread ended meanwhile
            changed.append(tid)
    except (AttributeError, OSError) as exc:     # not Linux, or not permitted
        for tid in changed:
            try:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
            except OSError:
                pass
        return _refused(priority, exc)
    return None


def leave_fifo() -> None:
    """Put this (new) process's thread back under the normal scheduler; always allowed."""
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):
        pass


MIN_NICE, MAX_NICE = -20, 19


def set_nice(value: int, what: str = 'engine_nice') -> Optional[str]:
    """
    Set the calling thread's nice ``value`` (Linux: per thread); return None when done.

    Else return the one-line reason it was refused, with the limit to raise: a value
    below the thread's current one needs ``CAP_SYS_NICE`` or an ``RLIMIT_NICE`` allowance.
    ``what`` names the setting in that line.
    """
    if not MIN_NICE <= value <= MAX_NICE:
        raise ValueError(f'{what}: expected {MIN_NICE} .. {MAX_NICE}, got {value!r}')
    try:
        os.setpriority(os.PRIO_PROCESS, 0, value)
    except (AttributeError, OSError) as exc:
        try:
            limit = resource.getrlimit(resource.RLIMIT_NICE)[0]
            lowest = f', nice {20 - limit} at the lowest' if limit else ''
            hint = (f'the nice limit (RLIMIT_NICE) is {limit}{lowest}; raise it for the '
                    f'user, e.g. "@realtime - nice {value}" in /etc/security/limits.conf')
        except (AttributeError, ValueError, OSError):
            hint = 'this system has no nice limit to raise'
        reason = getattr(exc, 'strerror', None) or str(exc)
        return f'{what}: cannot compute at nice {value} ({reason}); {hint}'
    return None
