"""
Bacterial Foraging Optimisation (Passino), vectorised across bacteria and batch.

Chemotaxis: each bacterium tumbles to a random unit direction and takes a step of
``step_size`` (radians, in the joint space), then keeps swimming along it for up to
``swim_length`` steps while its cost improves.  The cost includes the cell-to-cell
signal ``J_cc(x) = sum_i -d_attract exp(-w_attract |x - x_i|^2)
+ h_repel exp(-w_repel |x - x_i|^2)``.  After ``chemotactic_steps`` the healthier half
reproduces (``reproduction_steps`` times), then each bacterium is dispersed to a random
point with probability ``p_eliminate`` (``elimination_events`` times).

Note: with the paper's values (attract depth = repel height = 0.4 and equal widths 0.3)
the attraction and repulsion cancel exactly, so J_cc is identically zero.  It is still
computed, so other options behave as Passino describes.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .base import Algorithm, best_of, check_float, check_int, remember_best, StepTimer


@dataclass(frozen=True)
class CellSignal:
    """
    The cell-to-cell signal's attraction depth and width and repulsion height and width.

    Passino's swarming term; the paper's values (0.4, 0.3, 0.4, 0.3) cancel exactly.
    """

    d_attract: float = 0.4
    w_attract: float = 0.3
    h_repel: float = 0.4
    w_repel: float = 0.3

    def __post_init__(self):
        for name in ('d_attract', 'w_attract', 'h_repel', 'w_repel'):
            object.__setattr__(self, name,
                               check_float(f'BFOA {name}', getattr(self, name), 0.0, 1e6))


class BFOA(Algorithm):
    """BFOA options; the defaults are the paper's Table 3 preset (``signal``: a CellSignal)."""

    name = 'bfoa'

    def __init__(self, population=10, step_size=0.5, elimination_events=2,
                 reproduction_steps=6, chemotactic_steps=10, swim_length=15,
                 p_eliminate=0.3, signal: Optional[CellSignal] = None):
        self.population = check_int('BFOA population', population, 2)
        self.step_size = check_float('BFOA step_size', step_size, 0.0, 10.0, low_open=True)
        self.elimination_events = check_int('BFOA elimination_events', elimination_events, 1)
        self.reproduction_steps = check_int('BFOA reproduction_steps', reproduction_steps, 1)
        self.chemotactic_steps = check_int('BFOA chemotactic_steps', chemotactic_steps, 1)
        self.swim_length = check_int('BFOA swim_length', swim_length, 0)
        self.p_eliminate = check_float('BFOA p_eliminate', p_eliminate, 0.0, 1.0)
        signal = CellSignal() if signal is None else signal
        # Kept flat, so that options() reports the same names as before.
        self.d_attract, self.w_attract = signal.d_attract, signal.w_attract
        self.h_repel, self.w_repel = signal.h_repel, signal.w_repel

    @classmethod
    def paper(cls):
        """Return the paper's tuned preset."""
        return cls()

    def _jcc(self, x, colony):
        """Cell-to-cell signal at points x (b, n, D) from the colony (b, s, D)."""
        d2 = np.sum((x[:, :, None, :] - colony[:, None, :, :]) ** 2, axis=-1)
        return np.sum(-self.d_attract * np.exp(-self.w_attract * d2)
                      + self.h_repel * np.exp(-self.w_repel * d2), axis=-1)

    def run(self, problem, rng, clock):
        """Run on ``problem`` within ``clock``; see :class:`~.base.Algorithm`."""
        batch, s, dim = problem.batch, self.population, problem.dim
        rows = np.arange(batch)[:, None]
        x = problem.random(rng, s)
        j = problem.evaluate(x)
        best_x, best_f = best_of(x, j)
        history = [best_f.copy()]
        timer = StepTimer()
        nit = 0

        for _ in range(self.elimination_events):
            for _ in range(self.reproduction_steps):
                health = np.zeros((batch, s))
                for _ in range(self.chemotactic_steps):
                    if clock.expired(timer.cost):
                        return best_x, best_f, nit, history
                    nit += 1
                    cost = j + self._jcc(x, x)
                    delta = rng.uniform(-1.0, 1.0, size=(batch, s, dim))
                    direction = delta / np.linalg.norm(delta, axis=-1, keepdims=True)
                    x = problem.clip(x + self.step_size * direction)
                    j = problem.evaluate(x)
                    remember_best(x, j, best_x, best_f)
                    new_cost = j + self._jcc(x, x)
                    swimming = new_cost < cost
                    cost = np.where(swimming, new_cost, cost)
                    for _ in range(self.swim_length):
                        if not np.any(swimming) or clock.expired(timer.cost):
                            break
                        trial = problem.clip(x + self.step_size * direction)
                        jt = problem.evaluate(trial)
                        ct = jt + self._jcc(trial, x)
                        moved = swimming & (ct < cost)
                        x = np.where(moved[..., None], trial, x)
                        j = np.where(moved, jt, j)
                        cost = np.where(moved, ct, cost)
                        swimming = moved
                        remember_best(trial, np.where(moved, jt, np.inf), best_x, best_f)
                    health += cost
                    history.append(best_f.copy())
                    timer.tick()
                # Reproduction: the healthier half (lowest accumulated cost) splits.
                order = np.argsort(health, axis=1, kind='stable')[:, :(s + 1) // 2]
                idx = np.concatenate((order, order), axis=1)[:, :s]
                x, j = x[rows, idx], j[rows, idx]
            # Elimination-dispersal.
            gone = rng.uniform(size=(batch, s)) < self.p_eliminate
            if np.any(gone):
                x = np.where(gone[..., None], problem.random(rng, s), x)
                j = problem.evaluate(x)
                remember_best(x, j, best_x, best_f)
        return best_x, best_f, nit, history
