"""
Genetic algorithm as the paper describes it, vectorised across population and batch.

A chromosome is the real vector of free joints.  The initial population is uniform in
the bounds; parents are paired at random; one-point crossover happens with
``crossover_rate``; each gene mutates with ``mutation_rate`` by a uniform step of at most
``mutation_step`` times that gene's range (upper - lower); generation rollover lets
offspring that are better replace the worst individuals.
"""

import numpy as np

from .base import Algorithm, best_of, check_float, check_int, StepTimer


class GA(Algorithm):
    """Genetic algorithm options (paper Table 3: 80 / 50 / 0.8 / 0.25 / 0.15)."""

    name = 'ga'

    def __init__(self, population=80, generations=50, crossover_rate=0.8, mutation_rate=0.25,
                 mutation_step=0.15):
        self.population = check_int('GA population', population, 2)
        self.generations = check_int('GA generations', generations, 1)
        self.crossover_rate = check_float('GA crossover_rate', crossover_rate, 0.0, 1.0)
        self.mutation_rate = check_float('GA mutation_rate', mutation_rate, 0.0, 1.0)
        self.mutation_step = check_float('GA mutation_step', mutation_step, 0.0, 1.0,
                                         low_open=True)

    @classmethod
    def paper(cls):
        """Return the paper's tuned preset."""
        return cls()

    def run(self, problem, rng, clock):
        """Run on ``problem`` within ``clock``; see :class:`~.base.Algorithm`."""
        batch, n, dim = problem.batch, self.population, problem.dim
        rows = np.arange(batch)[:, None]
        pop = problem.random(rng, n)
        fit = problem.evaluate(pop)
        span = problem.upper - problem.lower
        history = [fit.min(axis=1)]
        timer = StepTimer()
        nit = 0
        half = n // 2
        while nit < self.generations and not clock.expired(timer.cost):
            nit += 1
            perm = rng.permuted(np.broadcast_to(np.arange(n), (batch, n)), axis=1)
            pa, pb = pop[rows, perm[:, :half]], pop[rows, perm[:, half:2 * half]]
            # One-point crossover: genes after the cut point are swapped.
            cut = rng.integers(1, max(dim, 2), size=(batch, half, 1))
            swap = (np.arange(dim) >= cut) & (rng.uniform(size=(batch, half, 1))
                                              < self.crossover_rate)
            ca = np.where(swap, pb, pa)
            cb = np.where(swap, pa, pb)
            kids = np.concatenate((ca, cb), axis=1)
            mutate = rng.uniform(size=kids.shape) < self.mutation_rate
            step = rng.uniform(-1.0, 1.0, size=kids.shape) * self.mutation_step * span
            kids = problem.clip(np.where(mutate, kids + step, kids))
            kfit = problem.evaluate(kids)
            # Generation rollover: the best n of parents + offspring survive.
            allx = np.concatenate((pop, kids), axis=1)
            allf = np.concatenate((fit, kfit), axis=1)
            keep = np.argsort(allf, axis=1, kind='stable')[:, :n]
            pop, fit = allx[rows, keep], allf[rows, keep]
            history.append(fit[:, 0].copy())
            timer.tick()
        best_x, best_f = best_of(pop, fit)
        return best_x, best_f, nit, history
