"""
The problem, the result and the deadline-aware driver shared by every optimiser.

Problems are *batched*: ``n_batch`` independent sub-problems with the same bounds are
solved in lock-step, so that one objective call evaluates every population member of
every sub-problem (e.g. all gestures of the library at once).
"""

from dataclasses import dataclass, field
import time
from typing import Callable, Optional
import warnings

import numpy as np

STATUS_DONE = 0
STATUS_DEADLINE = 1
STATUS_CANCELLED = 2
_MESSAGES = {
    STATUS_DONE: 'maximum number of iterations reached',
    STATUS_DEADLINE: 'deadline reached; best so far returned',
    STATUS_CANCELLED: 'cancelled; best so far returned',
}


class Problem:
    """
    Box-bounded minimisation of a batched objective.

    ``objective(X)`` takes X of shape (n_batch, N, D) and returns (n_batch, N). With
    ``n_batch = None`` the problem is a single one: results are squeezed to ``x`` (D,)
    and a scalar ``fun``.  ``value_and_grad`` optionally gives an analytic gradient for
    local polishing.  ``x0`` (n_batch, D) is an optional known-good start (for a
    gesture: the reference pose of the free joints), which an algorithm may use.
    """

    def __init__(self, lower, upper, objective: Callable[[np.ndarray], np.ndarray],
                 n_batch: Optional[int] = None, x0=None,
                 value_and_grad: Optional[Callable] = None):
        lower = np.asarray(lower, dtype=float).ravel()
        upper = np.asarray(upper, dtype=float).ravel()
        if lower.shape != upper.shape or lower.size == 0:
            raise ValueError(f'Problem: lower and upper bounds must be non-empty and of the '
                             f'same length, got {lower.shape} and {upper.shape}')
        if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
            raise ValueError('Problem: bounds must be finite')
        if np.any(lower > upper):
            i = int(np.argmax(lower > upper))
            raise ValueError(f'Problem: lower bound {lower[i]} > upper bound {upper[i]} '
                             f'in dimension {i}')
        if n_batch is not None and (not isinstance(n_batch, (int, np.integer)) or n_batch < 1):
            raise ValueError(f'Problem: n_batch must be a positive integer or None, '
                             f'got {n_batch!r}')
        self.lower = lower
        self.upper = upper
        self.objective = objective
        self.n_batch = n_batch
        self.nfev = 0
        # Optional analytic gradient: X (batch, N, D) -> (f (batch, N), g (batch, N, D)).
        self._value_and_grad = value_and_grad
        self.row_bounds = None   # (lower, upper) per sub-problem, (batch, D): see restrict
        # Optional known-good starting points, (batch, D); algorithms may use them.
        self.x0 = None if x0 is None else self.clip(
            np.asarray(x0, dtype=float).reshape(self.batch, self.dim))

    @property
    def dim(self) -> int:
        """Return the number of variables."""
        return self.lower.size

    @property
    def batch(self) -> int:
        """Return the number of sub-problems solved in lock-step (1 for a single one)."""
        return self.n_batch or 1

    def evaluate(self, x: np.ndarray) -> np.ndarray:
        """Evaluate X of shape (batch, N, D); counts function evaluations per sub-problem."""
        f = np.asarray(self.objective(x), dtype=float)
        self.nfev += x.shape[1]
        # A NaN must never win a comparison: treat it as the worst possible value.
        return np.where(np.isnan(f), np.inf, f)

    def value_and_grad(self, x: np.ndarray) -> tuple:
        """
        Return values (batch, N) and gradients (batch, N, D) at X (batch, N, D).

        Uses the problem's analytic gradient when it has one, else central differences
        (all 2 D + 1 points of every row in one batched objective call).
        """
        if self._value_and_grad is not None:
            f, g = self._value_and_grad(x)
            self.nfev += x.shape[1]
            return np.where(np.isnan(f), np.inf, f), g
        batch, n, dim = x.shape
        h = 1e-6
        pts = np.concatenate((x[:, :, None], x[:, :, None] + h * np.eye(dim),
                              x[:, :, None] - h * np.eye(dim)), axis=2)
        f = self.evaluate(pts.reshape(batch, n * (2 * dim + 1), dim))
        f = f.reshape(batch, n, 2 * dim + 1)
        return f[..., 0], (f[..., 1:dim + 1] - f[..., dim + 1:]) / (2 * h)

    def random(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Draw ``n`` uniform points per sub-problem, shape (batch, n, D)."""
        if self.row_bounds is not None:
            low, high = self.row_bounds
            return rng.uniform(low[:, None], high[:, None], size=(self.batch, n, self.dim))
        return rng.uniform(self.lower, self.upper, size=(self.batch, n, self.dim))

    def starts(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """
        Return ``n`` starting points per sub-problem (batch, n, D) for a population.

        Uniform draws (:meth:`random`) here; a problem that knows more of its structure
        (:class:`~namo_fault_recovery.recovery.keyframes.PoseProblem`) returns better ones.
        """
        return self.random(rng, n)

    def clip(self, x: np.ndarray) -> np.ndarray:
        """Clip into the bounds (each sub-problem's own, after :meth:`restrict`)."""
        if self.row_bounds is None:
            return np.clip(x, self.lower, self.upper)
        x = np.asarray(x, dtype=float)
        shape = (self.batch,) + (1,) * (x.ndim - 2) + (self.dim,)
        low, high = self.row_bounds
        return np.clip(x, low.reshape(shape), high.reshape(shape))

    def restrict(self, lower, upper):
        """
        Narrow each sub-problem's box to its own ``lower``/``upper`` (batch, D).

        A problem's constraints that are boxes per sub-problem (e.g. a motion's
        keyframes, each kept near its neighbours) are met by every point the
        algorithms draw or clip; ``lower``/``upper`` stay the boxes' union.  The
        boxes must lie within the bounds; ``x0`` is clipped into them.
        """
        low = np.broadcast_to(np.asarray(lower, dtype=float), (self.batch, self.dim))
        high = np.broadcast_to(np.asarray(upper, dtype=float), (self.batch, self.dim))
        if np.any(low > high) or np.any(low < self.lower) or np.any(high > self.upper):
            raise ValueError('Problem.restrict: expected lower <= upper within the bounds')
        self.row_bounds = (low.copy(), high.copy())
        if self.x0 is not None:
            self.x0 = self.clip(self.x0)


@dataclass
class OptimizeResult:
    """What an optimiser returns, in the shape of scipy's ``OptimizeResult``."""

    x: np.ndarray
    fun: object            # (batch,) array, or a float for a single problem
    nfev: int
    nit: int
    status: int
    message: str
    wall_time: float
    history: np.ndarray = field(repr=False)
    seed: Optional[int] = None
    algorithm: str = ''
    # The points the algorithm's own local search ended at, and their values (scipy's
    # shgo names; in the order of their starts, not sorted): (batch, k, D) and
    # (batch, k), (k, D) and (k,) for a single problem, or None for an algorithm that
    # does not end with one.  A caller that goes on locally may take the runners-up as
    # well as the best (the keyframe search does: recovery.keyframes).
    xl: Optional[np.ndarray] = field(default=None, repr=False)
    funl: Optional[np.ndarray] = field(default=None, repr=False)

    @property
    def success(self) -> bool:
        """Return True when the run ended on its own, not cut short."""
        return self.status == STATUS_DONE

    def __getitem__(self, key):
        return getattr(self, key)


class Clock:
    """
    The wall-clock budget of one run, on ``time.monotonic()``.

    ``expired()`` is cheap.  ``expired(next_cost)`` also refuses to start a step that
    is expected to end past the deadline, so the overrun stays near one step's jitter.
    """

    def __init__(self, deadline: Optional[float] = None,
                 cancel: Optional[Callable[[], bool]] = None, start: Optional[float] = None):
        if deadline is not None and (not np.isfinite(deadline) or deadline < 0):
            raise ValueError(f'deadline: expected a finite number of seconds >= 0 or None, '
                             f'got {deadline!r}')
        self.start = time.monotonic() if start is None else start
        self.end = None if deadline is None else self.start + deadline
        self.cancel = cancel
        self.reason = STATUS_DONE

    def expired(self, next_cost: float = 0.0) -> bool:
        """Return True (and remember why) if the run must stop now."""
        if self.cancel is not None and self.cancel():
            self.reason = STATUS_CANCELLED
            return True
        if self.end is not None and time.monotonic() + next_cost >= self.end:
            self.reason = STATUS_DEADLINE
            return True
        return False

    def remaining(self) -> float:
        """Return the seconds left (inf without a deadline)."""
        return np.inf if self.end is None else self.end - time.monotonic()

    def elapsed(self) -> float:
        """Return the seconds since the start."""
        return time.monotonic() - self.start

    @classmethod
    def until(cls, end: Optional[float],
              cancel: Optional[Callable[[], bool]] = None) -> 'Clock':
        """Return a clock that starts now and ends at ``end`` (monotonic s; None: never)."""
        clock = cls(None, cancel)
        if end is not None:
            clock.end = max(float(end), clock.start)
        return clock

    def child(self, share: float = 1.0, reserve: float = 0.0) -> 'Clock':
        """
        Return the clock of one stage of this run: same cancel, an earlier or equal end.

        The stage ends ``reserve`` seconds before this clock (the time kept for the work
        that follows it; at most half of what is left, so that a short deadline still
        leaves the stage something), after ``share`` of the rest.  Every stage of a run
        derives its budget this way from the one clock the caller owns, so that no
        stage can end past the caller's deadline.
        """
        if not 0.0 <= share <= 1.0 or not reserve >= 0.0:
            raise ValueError(f'Clock.child: expected 0 <= share <= 1 and reserve >= 0, '
                             f'got share={share!r}, reserve={reserve!r}')
        if self.end is None:
            return Clock(None, self.cancel)
        now = time.monotonic()
        left = max(self.end - now, 0.0)
        left -= min(reserve, 0.5 * left)
        return Clock.until(now + share * left, self.cancel)


class Algorithm:
    """
    Base class: subclasses implement :meth:`run` and validate their options.

    ``run(problem, rng, clock)`` returns ``(x_best (batch, D), f_best (batch,), nit,
    history list of (batch,) arrays)``, and an algorithm that ends with a local search
    of several starts may add a fifth item, ``(xl (batch, k, D), funl (batch, k))``,
    the points that search ended at (:attr:`OptimizeResult.xl`), or None.  It must call
    ``clock.expired(step_cost)`` between steps and return the best so far when it
    says so.
    """

    name = 'algorithm'

    def run(self, problem: Problem, rng: np.random.Generator, clock: Clock) -> tuple:
        """Run on ``problem`` until done or ``clock`` expires; see the class docstring."""
        raise NotImplementedError

    def options(self) -> dict:
        """Return the constructor's arguments as a plain dict (for reports)."""
        return {k: v for k, v in vars(self).items() if not k.startswith('_')}

    def settings(self) -> dict:
        """Return :meth:`options` (the name of version 0.1, deprecated)."""
        warnings.warn('Algorithm.settings() is deprecated; use Algorithm.options()',
                      DeprecationWarning, stacklevel=2)
        return self.options()


def best_of(points, values):
    """Return each sub-problem's best point (batch, D) and value (batch,) of a population."""
    k = np.argmin(values, axis=1)
    rows = np.arange(len(values))
    return points[rows, k].copy(), values[rows, k].copy()


def remember_best(points, values, best_x, best_f):
    """
    Keep, in place, each sub-problem's best so far against a population's best.

    ``points`` (batch, N, D) and ``values`` (batch, N); returns the rows that improved.
    """
    x, v = best_of(points, values)
    gain = v < best_f
    best_f[gain] = v[gain]
    best_x[gain] = x[gain]
    return gain


def check_int(name, value, minimum):
    """Return ``value`` as an int >= minimum, or raise a ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f'{name}: expected an integer >= {minimum}, got {value!r}')
    return int(value)


def check_float(name, value, low, high, low_open=False):
    """Return ``value`` as a float in [low, high] (or (low, high]), or raise naming it."""
    ok = (not isinstance(value, bool) and isinstance(value, (int, float, np.floating))
          and np.isfinite(value) and (value > low if low_open else value >= low)
          and value <= high)
    if not ok:
        interval = f'{"(" if low_open else "["}{low}, {high}]'
        raise ValueError(f'{name}: expected a number in {interval}, got {value!r}')
    return float(value)


class StepTimer:
    """Running estimate of one step's duration, for :meth:`Clock.expired`."""

    def __init__(self):
        self.last = time.monotonic()
        self.cost = 0.0

    def tick(self):
        """Record the end of a step; return the expected cost of the next one."""
        now = time.monotonic()
        self.cost = max(now - self.last, 0.5 * self.cost)
        self.last = now
        return self.cost


def minimize(problem: Problem, algorithm: Algorithm, clock: Optional[Clock] = None,
             seed: Optional[int] = None, **removed) -> OptimizeResult:
    """
    Minimise ``problem`` with ``algorithm`` until it is done or ``clock`` expires.

    ``clock`` (a :class:`Clock`; None: no deadline) owns the deadline and the cancel
    flag: the run ends at its end and honours its cancel (the caller's clock itself is
    left untouched).  ``seed`` makes the run reproducible (None draws one, reported in
    ``res.seed``).  The keywords ``deadline`` and ``cancel`` of version 0.1 are refused
    with a message that says what replaces them.
    """
    if removed:
        names = ', '.join(f'{k}=' for k in sorted(removed))
        hint = ('; pass clock=Clock(deadline_sec, cancel) instead'
                if set(removed) <= {'deadline', 'cancel'} else '')
        raise TypeError(f'minimize: unexpected keyword {names}{hint}')
    if not isinstance(problem, Problem):
        raise TypeError(f'problem: expected a Problem, got {type(problem).__name__}')
    if not isinstance(algorithm, Algorithm):
        raise TypeError(f'algorithm: expected an Algorithm, got {type(algorithm).__name__}')
    if clock is not None and not isinstance(clock, Clock):
        raise TypeError(f'clock: expected a Clock or None, got {type(clock).__name__}')
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 63))
    rng = np.random.default_rng(seed)
    clock = Clock(None) if clock is None else Clock.until(clock.end, clock.cancel)
    problem.nfev = 0
    x, f, nit, history, *local = algorithm.run(problem, rng, clock)
    wall = clock.elapsed()
    hist = np.array(history) if history else np.empty((0, problem.batch))
    xl, funl = local[0] if local and local[0] is not None else (None, None)
    if problem.n_batch is None:
        x, f = x[0], float(f[0])
        hist = hist[:, 0] if hist.size else hist.reshape(0)
        if xl is not None:
            xl, funl = xl[0], funl[0]
    return OptimizeResult(x=x, fun=f, nfev=problem.nfev, nit=nit, status=clock.reason,
                          message=_MESSAGES[clock.reason], wall_time=wall, history=hist,
                          seed=seed, algorithm=algorithm.name, xl=xl, funl=funl)
