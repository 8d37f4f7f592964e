"""
Anytime refinement: keep improving a published library after the deadline result.

Free of ROS.  The deadline result is the best a 1 s search found; a fault set the node
did not precompute (a measured lock, a new combination) then deserves more search in
the background.  :func:`refinements` runs :func:`~.engine.recover` again with further
seeds, each try with its own budget derived from one caller-owned
:class:`~namo_fault_recovery.optimize.base.Clock` (its cancel flag ends it at once when
a new fault arrives), and yields every library better than the best so far by more than
``min_gain`` (relative), with ``origin='refined'``, the published result's deadline
and ``refined_after`` (seconds since the refinement started).  It ends when the seeds
or the clock run out, or after ``patience`` tries in a row without a gain (converged)::

    for better in refinements(robot, library, published, settings, clock=Clock(10.0)):
        publish(better)

The locks of the published library are kept (each try starts from the same lock
angles), except with the ``optimal`` strategy, where choosing the lock is part of the
search.
"""

from dataclasses import replace
import math
import time

from .engine import recover
from ..optimize.base import Clock

DEFAULT_TRY_SEC = None         # budget of one try (None: the optimiser's full run)
DEFAULT_MIN_GAIN = 1e-3        # a new version only for a gain above 0.1% of the total
# Tries in a row without a gain before it counts as converged.  A try costs about the
# engine's time without a deadline (50-100 ms for Namo's library), and a better basin
# may come up in only one seed of eight (measured: right joint 1 + left joint 3), so a
# short patience would stop long before the budget and miss it (0.88^4 = 60 %).
DEFAULT_PATIENCE = 32
DEFAULT_SEEDS = 1000           # tries at most (the budget usually ends it first)


def refinement_faults(published, settings):
    """Return the fault set each try solves: the published locks, unless they are searched."""
    if settings.lock_strategy == 'optimal':
        return dict(published.faults)
    return {j: float(a) for j, a in published.locks.items()}


def refinements(robot, library, published, settings, *, clock=None, seeds=None,
                try_sec=DEFAULT_TRY_SEC, min_gain=DEFAULT_MIN_GAIN,
                patience=DEFAULT_PATIENCE, quantisations=None):
    """
    Yield ever better libraries for ``published``'s fault set (see the module docstring).

    ``seeds`` is the sequence of seeds to try (default: ``DEFAULT_SEEDS`` seeds after the
    published one).  Each try runs at most ``try_sec`` seconds (None: until the optimiser
    ends), and every try ends with ``clock`` (None: no overall limit).
    """
    clock = clock or Clock(None)
    if seeds is None:
        first = 0 if published.seed is None else int(published.seed) + 1
        seeds = range(first, first + DEFAULT_SEEDS)
    faults = refinement_faults(published, settings)
    best = published.total_score
    if not math.isfinite(best):
        best = math.inf
    idle = 0
    for seed in seeds:
        if clock.expired() or idle >= patience:
            return
        now = time.monotonic()
        end = clock.end if try_sec is None else now + try_sec
        if clock.end is not None and end is not None:
            end = min(end, clock.end)
        step = Clock.until(end, clock.cancel)
        result = recover(robot, library, faults, settings, seed=seed, clock=step,
                         quantisations=quantisations)
        if result.cancelled or (clock.cancel is not None and clock.cancel()):
            return
        total = result.total_score
        if math.isfinite(total) and total < best - min_gain * max(abs(best), 1e-9):
            best = total
            idle = 0
            # A try cut short by its own budget is still a valid, better library.  Its
            # budget is the refinement's, not a deadline: the version keeps the deadline
            # of the result it refines, and says how long after it the refinement was.
            yield replace(result, origin='refined', faults=dict(published.faults),
                          success=not result.cancelled, deadline=published.deadline,
                          deadline_met=published.deadline_met,
                          refined_after=time.monotonic() - clock.start)
        else:
            idle += 1
