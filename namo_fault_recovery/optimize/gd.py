"""
Gradient descent with momentum: the paper's baseline (decay 0.9, learning rate 0.1/0.05).

The gradient is taken by central differences with respect to the joint angles in
**degrees** (the paper's Table 2 units), which is what makes its learning rates of 0.1
and 0.05 sensible step sizes.  Each sub-problem starts from one uniform random point.
"""

import numpy as np

from .base import Algorithm, check_float, check_int, StepTimer

_DEG = np.pi / 180.0
_H = 1e-4   # finite-difference step, degrees


class GradientDescent(Algorithm):
    """Momentum gradient descent options."""

    name = 'gd'

    def __init__(self, learning_rate=0.1, decay=0.9, iterations=1000):
        self.learning_rate = check_float('GD learning_rate', learning_rate, 0.0, 1e3,
                                         low_open=True)
        self.decay = check_float('GD decay', decay, 0.0, 1.0)
        self.iterations = check_int('GD iterations', iterations, 1)

    @classmethod
    def paper(cls, learning_rate=0.1):
        """Return the paper's baseline (learning rate 0.1 or 0.05)."""
        return cls(learning_rate=learning_rate)

    def run(self, problem, rng, clock):
        """Run on ``problem`` within ``clock``; see :class:`~.base.Algorithm`."""
        batch, dim = problem.batch, problem.dim
        x = problem.random(rng, 1)[:, 0]
        v = np.zeros_like(x)
        eye = np.eye(dim) * _H * _DEG
        best_x = x.copy()
        best_f = np.full(batch, np.inf)
        history = []
        timer = StepTimer()
        nit = 0
        while nit < self.iterations and not clock.expired(timer.cost):
            nit += 1
            pts = np.concatenate((x[:, None], x[:, None] + eye, x[:, None] - eye), axis=1)
            f = problem.evaluate(pts)
            gain = f[:, 0] < best_f
            best_f[gain], best_x[gain] = f[gain, 0], x[gain]
            grad_deg = (f[:, 1:dim + 1] - f[:, dim + 1:]) / (2 * _H)
            v = self.decay * v - self.learning_rate * grad_deg
            x = problem.clip(x + v * _DEG)
            history.append(best_f.copy())
            timer.tick()
        return best_x, best_f, nit, history
