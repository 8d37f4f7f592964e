"""
Artificial Bee Colony (Karaboga), vectorised across the colony and the batch.

Employed bees each take a neighbour step on one random dimension against a random
partner (``v_ij = x_ij + phi (x_ij - x_kj)``, phi ~ U(-1, 1)) with greedy selection;
onlookers pick sources by roulette on fitness 1 / (1 + f); a source that fails to
improve ``limit`` times is abandoned to a scout.  Every phase is one batched objective
call.  Optionally, the best sources are polished with a batched L-BFGS-B at the end
(the colony finds the basin; the polish walks to its floor); the polished points are
the result's local minima (``xl``, ``funl``).
"""

import numpy as np

from .base import Algorithm, best_of, check_float, check_int, remember_best, StepTimer
from .polish import polish

DISTINCT_RAD = 0.2   # rad: a source this close to the best (every angle) is the same start


class ABC(Algorithm):
    """
    Artificial Bee Colony options.

    ``n_sources`` food sources (as many employed and onlooker bees), ``max_cycles``
    cycles, abandonment ``limit``; ``stall_cycles`` ends the run early after that many
    cycles without improvement of any sub-problem's best (None: never); ``polish`` is the
    number of best distinct sources per sub-problem refined locally at the end (0: none),
    with steepest-descent restarts if ``polish_restart`` (see :func:`~.polish.polish`);
    ``use_x0`` places the problem's known-good start (if any) among the first sources.
    The first sources are uniform draws, as in the paper; with ``informed_starts`` they
    are the problem's :meth:`~.base.Problem.starts` (the same, unless the problem knows
    better: the keyframe search's kinematic starts), so that the paper's preset stays the
    paper's colony in its comparison with GA and BFOA.
    """

    name = 'abc'

    def __init__(self, n_sources=5, max_cycles=500, limit=150, stall_cycles=None, polish=0,
                 polish_maxiter=100, polish_ftol=1e-10, use_x0=False, polish_restart=False,
                 informed_starts=False):
        self.n_sources = check_int('ABC n_sources', n_sources, 2)
        self.max_cycles = check_int('ABC max_cycles', max_cycles, 1)
        self.limit = check_int('ABC limit', limit, 1)
        self.stall_cycles = (None if stall_cycles is None
                             else check_int('ABC stall_cycles', stall_cycles, 1))
        self.polish = check_int('ABC polish', polish, 0)
        self.polish_maxiter = check_int('ABC polish_maxiter', polish_maxiter, 1)
        self.polish_ftol = check_float('ABC polish_ftol', polish_ftol, 0.0, 1.0)
        if not isinstance(use_x0, bool):
            raise ValueError(f'ABC use_x0: expected true or false, got {use_x0!r}')
        self.use_x0 = use_x0
        if not isinstance(polish_restart, bool):
            raise ValueError(f'ABC polish_restart: expected true or false, got '
                             f'{polish_restart!r}')
        self.polish_restart = polish_restart
        if not isinstance(informed_starts, bool):
            raise ValueError(f'ABC informed_starts: expected true or false, got '
                             f'{informed_starts!r}')
        self.informed_starts = informed_starts

    @classmethod
    def paper(cls):
        """Return the paper's tuned preset (Table 3): 5 sources, 500 cycles, limit 150."""
        return cls(n_sources=5, max_cycles=500, limit=150)

    def _neighbours(self, problem, rng, x, src):
        """Return neighbour candidates of sources ``src`` (batch, m) of colony ``x``."""
        batch, sn, dim = x.shape
        m = src.shape[1]
        rows = np.arange(batch)[:, None]
        partner = (src + rng.integers(1, sn, size=(batch, m))) % sn
        j = rng.integers(0, dim, size=(batch, m))
        phi = rng.uniform(-1.0, 1.0, size=(batch, m))
        cand = x[rows, src].copy()
        xij = cand[rows, np.arange(m)[None, :], j]
        xkj = x[rows, partner, j]
        cand[rows, np.arange(m)[None, :], j] = xij + phi * (xij - xkj)
        return problem.clip(cand)

    def run(self, problem, rng, clock):
        """Run the colony on ``problem`` within ``clock``; see :class:`~.base.Algorithm`."""
        batch, sn = problem.batch, self.n_sources
        x = problem.starts(rng, sn) if self.informed_starts else problem.random(rng, sn)
        if self.use_x0 and problem.x0 is not None:
            # In place of the last start: informed starts come best first, and the first
            # is the one to keep (overwriting it lost TIAGo++'s salute through its wrist
            # flip, 6x above the best, whenever the flipped design was the best start).
            x[:, -1] = problem.x0
        f = problem.evaluate(x)
        trials = np.zeros((batch, sn), dtype=int)
        best_x, best_f = best_of(x, f)
        history = [best_f.copy()]
        timer = StepTimer()
        stall = 0
        nit = 0
        all_src = np.broadcast_to(np.arange(sn), (batch, sn))
        while nit < self.max_cycles and not clock.expired(timer.cost):
            nit += 1
            # Employed bees: one neighbour per source, greedy selection.
            cand = self._neighbours(problem, rng, x, all_src)
            fc = problem.evaluate(cand)
            better = fc < f
            x[better], f[better] = cand[better], fc[better]
            trials = np.where(better, 0, trials + 1)
            trials = self._onlookers(problem, rng, x, f, trials)
            # Memorise the best, then send a scout to the most exhausted source.
            if np.any(remember_best(x, f, best_x, best_f)):
                stall = 0
            else:
                stall += 1
            self._scout(problem, rng, x, f, trials)
            history.append(best_f.copy())
            timer.tick()
            if self.stall_cycles is not None and stall >= self.stall_cycles:
                break
        local = None
        if self.polish and not clock.expired():
            starts = _distinct_best(x, f, best_x, self.polish)
            if self.use_x0 and problem.x0 is not None:
                # The known-good start is always refined too, whatever became of it.
                starts[:, -1] = problem.x0
            local = polish(problem, starts, clock, maxiter=self.polish_maxiter,
                           ftol=self.polish_ftol, restart=self.polish_restart)
            remember_best(*local, best_x, best_f)
            history.append(best_f.copy())
        return best_x, best_f, nit, history, local

    def _onlookers(self, problem, rng, x, f, trials):
        """
        Run the onlooker phase on the colony ``x``/``f`` in place; return the new trials.

        Onlookers pick sources by roulette on fitness 1 / (1 + f) (f >= 0 for a score);
        several onlookers may pick one source, which keeps the best of their candidates.
        """
        batch, sn = x.shape[:2]
        rows = np.arange(batch)[:, None]
        fit = 1.0 / (1.0 + np.maximum(f, 0.0))
        cum = np.cumsum(fit / fit.sum(axis=1, keepdims=True), axis=1)
        u = rng.uniform(size=(batch, sn))
        chosen = np.minimum((u[:, :, None] > cum[:, None, :]).sum(axis=2), sn - 1)
        cand = self._neighbours(problem, rng, x, chosen)
        fc = problem.evaluate(cand)
        order = np.argsort(fc, axis=1, kind='stable')
        first = np.full((batch, sn), -1)
        for pos in range(sn - 1, -1, -1):   # a loop over bees, not configurations
            first[rows[:, 0], chosen[rows[:, 0], order[:, pos]]] = order[:, pos]
        counts = np.zeros((batch, sn), dtype=int)
        np.add.at(counts, (np.repeat(np.arange(batch), sn), chosen.ravel()), 1)
        has = first >= 0
        pick = np.where(has, first, 0)
        fbest = fc[rows, pick]
        improved = has & (fbest < f)
        x[improved] = cand[rows, pick][improved]
        f[improved] = fbest[improved]
        return np.where(improved, 0, trials + counts)

    def _scout(self, problem, rng, x, f, trials):
        """Send a scout to each sub-problem's most exhausted source, if over ``limit``."""
        batch = x.shape[0]
        worn = np.argmax(trials, axis=1)
        scout = trials[np.arange(batch), worn] > self.limit
        if np.any(scout):
            # One batched call evaluates a fresh point for every sub-problem; only
            # those with an exhausted source take theirs.
            b = np.nonzero(scout)[0]
            fresh = problem.random(rng, 1)
            f_fresh = problem.evaluate(fresh)
            x[b, worn[b]] = fresh[b, 0]
            f[b, worn[b]] = f_fresh[b, 0]
            trials[b, worn[b]] = 0


def _distinct_best(x, f, best_x, k):
    """
    Return the best memorised point plus the k - 1 best current sources, (batch, k, D).

    A source within ``DISTINCT_RAD`` (every angle) of the best memorised point is the
    same start polished twice: the other sources are taken first.
    """
    near = np.all(np.abs(x - best_x[:, None, :]) <= DISTINCT_RAD, axis=-1)
    order = np.lexsort((f, near), axis=1)[:, :max(k - 1, 0)]
    rows = np.arange(x.shape[0])[:, None]
    return np.concatenate((best_x[:, None, :], x[rows, order]), axis=1)
