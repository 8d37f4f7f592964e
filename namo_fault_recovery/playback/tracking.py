"""
What a joint's controller should have reached by now: a model of its tracking (no ROS).

A position-controlled joint does not follow its commanded trajectory ``r(t)`` exactly:
its controller lags behind.  :class:`TrackingModel` predicts the measured angle as the
command delayed by ``delay`` and passed through a first-order lag of
``time_constant``::

    tau * x'(t) + x(t) = r(t - delay)

one model per joint, the same two numbers for every joint (a robot whose joints differ
much gives the largest of each: a band, below, covers the rest).  The model is
integrated exactly for a command that is linear between steps of ``step`` seconds
(first-order hold), from the first measured pose, so that an arm which starts a little
off its command is not an error.

Why a calibrated model and not an estimate from the play itself: a joint that is
stuck from the start of a play looks, to an online estimator, like a joint with a very
long lag; the estimate would absorb the very fault it should expose.  The two numbers
are measured once on a healthy robot (or the simulator) with :func:`fit_tracking`
over whole plays, stored as parameters, and the detector compares with the model's
prediction.  What the model misses (a pose-dependent inertia, message latency and
scheduling jitter) the detector absorbs with a band: the range of the prediction over
the last ``window`` seconds (:meth:`TrackingModel.band`).
"""

from collections import deque
import math

import numpy as np
from scipy.signal import lfilter

DEFAULT_STEP = 0.005       # s: integration step of the model


def _coefficients(time_constant, step):
    """Return (b0, b1, a) of ``x1 = a x0 + b0 u1 + b1 u0`` (exact for a linear input)."""
    if time_constant <= 0.0:
        return 1.0, 0.0, 0.0
    a = math.exp(-step / time_constant)
    c = time_constant * (1.0 - a) / step
    return 1.0 - c, c - a, a


class TrackingModel:
    """The predicted angles of a set of joints, fed forward in time with the command."""

    def __init__(self, command, delay=0.0, time_constant=0.0, window=0.0,
                 step=DEFAULT_STEP):
        """
        Predict from ``command(t)`` ((J,) at a time, (n, J) at (n,) times).

        ``delay`` and ``time_constant`` (s) are the controller's, ``window`` (s) is how
        far back :meth:`band` looks, ``step`` (s) the integration step.
        """
        if not (delay >= 0.0 and time_constant >= 0.0 and window >= 0.0 and step > 0.0):
            raise ValueError(f'delay, time_constant and window must be >= 0 and step > 0, '
                             f'got {delay}, {time_constant}, {window}, {step}')
        self._command = command
        self.delay, self.time_constant = float(delay), float(time_constant)
        self.window, self.step = float(window), float(step)
        self._b0, self._b1, self._a = _coefficients(self.time_constant, self.step)
        self._grid = deque()         # (t, x) on the step grid, the last ``window`` s and one
        self._u = None
        self._now = None

    def _input(self, t):
        return np.atleast_2d(self._command(np.asarray(t, dtype=float) - self.delay))

    def reset(self, t, measured):
        """Start the model at time ``t`` from the ``measured`` pose."""
        self._grid.clear()
        self._grid.append((float(t), np.array(measured, dtype=float)))
        self._u = self._input([t])[0]
        self._now = float(t)

    def advance(self, t):
        """Integrate the model up to time ``t`` (s); return the predicted pose (J,)."""
        if self._now is None:
            raise RuntimeError('TrackingModel.advance before reset')
        last_t, x = self._grid[-1]
        n = int(math.ceil((t - last_t) / self.step - 1e-9))
        if n > 0:
            times = last_t + self.step * np.arange(1, n + 1)
            for tk, uk in zip(times, self._input(times)):
                x = self._a * x + self._b0 * uk + self._b1 * self._u
                self._u = uk
                self._grid.append((float(tk), x))
        self._now = max(self._now, float(t))
        while len(self._grid) > 2 and self._grid[1][0] <= self._now - self.window:
            self._grid.popleft()
        return self.at(self._now)

    def at(self, t):
        """Return the prediction at ``t`` within the integrated span (interpolated)."""
        for (t0, x0), (t1, x1) in zip(reversed(list(self._grid)[:-1]),
                                      reversed(list(self._grid)[1:])):
            if t0 <= t <= t1:
                return x0 + (x1 - x0) * ((t - t0) / (t1 - t0))
        return self._grid[-1][1].copy() if t > self._grid[-1][0] else self._grid[0][1].copy()

    def band(self):
        """Return (low, high): the range of the prediction over the last ``window`` s."""
        now = self._now
        points = [x for tk, x in self._grid if now - self.window <= tk <= now]
        points.append(self.at(now))
        points.append(self.at(max(self._grid[0][0], now - self.window)))
        stack = np.array(points)
        return stack.min(axis=0), stack.max(axis=0)


def predict(command, times, start, delay, time_constant, step=DEFAULT_STEP):
    """
    Return the model's prediction (n, J) at ``times`` (n,), from ``start`` at times[0].

    The batch form of :class:`TrackingModel` (the same recurrence, vectorised by
    ``scipy.signal.lfilter``), for calibration.
    """
    times = np.asarray(times, dtype=float)
    n = int(math.ceil((times[-1] - times[0]) / step - 1e-9)) + 1
    grid = times[0] + step * np.arange(n)
    u = np.atleast_2d(command(grid - delay))
    b0, b1, a = _coefficients(time_constant, step)
    start = np.asarray(start, dtype=float)
    dev = u - start                 # the model on deviations from the start: it starts at 0
    x = np.zeros_like(dev)
    if len(grid) > 1:
        zi = (b1 * dev[0])[None, :]   # direct form II transposed state before sample 1
        x[1:] = lfilter([b0, b1], [1.0, -a], dev[1:], axis=0, zi=zi)[0]
    x += start
    return np.stack([np.interp(times, grid, x[:, j]) for j in range(x.shape[1])], axis=1)


DELAYS = tuple(np.round(np.arange(0.0, 0.2001, 0.005), 3))           # s, the fit's grid
TIME_CONSTANTS = tuple(np.round(np.arange(0.0, 0.2001, 0.005), 3))   # s


def fit_tracking(plays, delays=DELAYS, time_constants=TIME_CONSTANTS, step=DEFAULT_STEP):
    """
    Fit (delay, time_constant) to healthy plays; return them and the worst error (rad).

    ``plays`` is a list of ``(command, times, measured)``: the command function of a
    play, the times (n,) of its measured poses (n, J) from the start of the play.  The
    fit is the grid point whose largest error over every joint and sample is the
    smallest (the detector's threshold must clear the largest, not the mean).
    """
    best = None
    for tau in time_constants:
        for delay in delays:
            worst = 0.0
            for command, times, measured in plays:
                measured = np.asarray(measured, dtype=float)
                guess = predict(command, times, measured[0], delay, tau, step)
                worst = max(worst, float(np.max(np.abs(measured - guess))))
                if best is not None and worst >= best[2]:
                    break
            if best is None or worst < best[2]:
                best = (float(delay), float(tau), worst)
    return best
