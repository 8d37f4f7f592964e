"""
Ordinary Kriging with a spherical variogram (the second source paper, eqs. 2-6).

The paper interpolates the correction vectors r = theta'' - theta found at a few typical
points to every point of a motion.  The variogram is fitted by least squares to the
experimental variogram cloud of the samples; the Kriging weights come from the Lagrange
system of the sum-to-one constraint, which also gives the estimation variance.
Values may be vectors: one variogram serves all their components (the semivariance
is the mean over components), so every component gets the same weights.
"""

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize_scalar, nnls

# Range search, in units of the largest lag of the cloud.
_MIN_RANGE = 1e-3
_MAX_RANGE = 1e3


@dataclass(frozen=True)
class SphericalVariogram:
    """
    gamma(h) = nugget + sill (1.5 h/range - 0.5 (h/range)^3) for 0 < h < range.

    It is nugget + sill beyond the range, and 0 at h = 0: the paper's a0, a1 and a2.
    """

    nugget: float
    sill: float
    range: float  # noqa: A003 - the geostatistics name (the paper's a2)

    def __post_init__(self):
        if not (self.nugget >= 0 and self.sill >= 0 and self.range > 0
                and np.isfinite([self.nugget, self.sill, self.range]).all()):
            raise ValueError(f'spherical variogram: expected nugget >= 0, sill >= 0 and '
                             f'range > 0 (finite), got nugget={self.nugget!r}, '
                             f'sill={self.sill!r}, range={self.range!r}')

    def __call__(self, h):
        """Return the semivariance at lag distances ``h`` (any shape)."""
        h = np.asarray(h, dtype=float)
        s = np.minimum(h / self.range, 1.0)
        gamma = self.nugget + self.sill * (1.5 * s - 0.5 * s ** 3)
        return np.where(h > 0, gamma, 0.0)


def variogram_cloud(points, values):
    """
    Return the experimental variogram cloud ``(h, gamma*)`` over all sample pairs.

    ``points`` (K, D) are the sample locations and ``values`` (K,) or (K, M) the samples;
    ``gamma* = 0.5 |r_i - r_j|^2 / M`` (paper eq. 4, averaged over the M components).
    """
    x, r = _as_samples(points, values)
    i, j = np.triu_indices(len(x), k=1)
    h = np.linalg.norm(x[i] - x[j], axis=1)
    gamma = 0.5 * np.mean((r[i] - r[j]) ** 2, axis=1)
    return h, gamma


def fit_spherical(h, gamma):
    """
    Fit a spherical variogram to a variogram cloud by least squares (scipy).

    For a fixed range the model is linear in the nugget and the sill, so they come from
    a non-negative linear least-squares solve (``scipy.optimize.nnls``); the range,
    where the model has a kink, is found by a grid over the cloud's extent refined with
    ``scipy.optimize.minimize_scalar``.  (A general bounded ``least_squares`` from
    several starts found the same fits about 30 times slower, which mattered inside
    the node's deadline.)  A flat cloud (all zero: every sample equal) gives a zero
    sill, for which Kriging returns that common value everywhere.
    """
    h = np.asarray(h, dtype=float).ravel()
    gamma = np.asarray(gamma, dtype=float).ravel()
    if h.shape != gamma.shape:
        raise ValueError(f'fit_spherical: h and gamma must have the same length, got '
                         f'{h.size} and {gamma.size}')
    if not (np.isfinite(h).all() and np.isfinite(gamma).all()):
        raise ValueError('fit_spherical: h and gamma must be finite')
    h_max = float(h.max()) if h.size else 0.0
    g_max = float(gamma.max()) if gamma.size else 0.0
    if h.size == 0 or h_max <= 0 or g_max <= 0:
        return SphericalVariogram(0.0, 0.0, max(h_max, 1.0))
    # Work in units of the cloud's extent so that the tolerances mean the same thing
    # whatever the units of the joint space and of the values.
    hs, gs = h / h_max, gamma / g_max
    positive = hs > 0

    def linear_part(range_):
        s = np.minimum(hs / range_, 1.0)
        design = np.stack((positive.astype(float),
                           np.where(positive, 1.5 * s - 0.5 * s ** 3, 0.0)), axis=1)
        return nnls(design, gs)

    def cost(log_range):
        return linear_part(np.exp(log_range))[1]

    grid = np.log(np.geomspace(_MIN_RANGE, _MAX_RANGE, 41))
    costs = [cost(r) for r in grid]
    k = int(np.argmin(costs))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    best = minimize_scalar(cost, bounds=(lo, hi), method='bounded',
                           options={'xatol': 1e-6})
    log_range = best.x if best.fun <= costs[k] else grid[k]
    (a0, a1), _ = linear_part(np.exp(log_range))
    return SphericalVariogram(float(a0 * g_max), float(a1 * g_max),
                              float(np.exp(log_range) * h_max))


class KrigingEstimate(NamedTuple):
    """Kriging at query points: estimates, estimation variances and weights."""

    values: np.ndarray     # (Q, M)
    variance: np.ndarray   # (Q,), paper eq. 6
    weights: np.ndarray    # (Q, K), each row sums to 1


class OrdinaryKriging:
    """
    Ordinary Kriging of vector samples; fits a spherical variogram unless given one.

    Build it once from the K samples, then :meth:`predict` at any number of points.
    It reproduces the samples exactly at their own locations.
    """

    def __init__(self, points, values, variogram=None):
        self.points, self.values = _as_samples(points, values)
        k = len(self.points)
        if variogram is None:
            variogram = fit_spherical(*variogram_cloud(self.points, self.values))
        self.variogram = variogram
        lags = np.linalg.norm(self.points[:, None] - self.points[None], axis=-1)
        system = np.ones((k + 1, k + 1))
        system[:k, :k] = variogram(lags)
        system[k, k] = 0.0
        self._system = system

    def predict(self, query):
        """Return the KrigingEstimate at query points (Q, D) (or one point (D,))."""
        q = np.asarray(query, dtype=float)
        if q.ndim == 1:
            q = q[None]
        if q.ndim != 2 or q.shape[1] != self.points.shape[1]:
            raise ValueError(f'Kriging query: expected points of dimension '
                             f'{self.points.shape[1]}, got shape {np.shape(query)}')
        k = len(self.points)
        rhs = np.ones((k + 1, len(q)))
        rhs[:k] = self.variogram(np.linalg.norm(self.points[:, None] - q[None], axis=-1))
        try:
            sol = np.linalg.solve(self._system, rhs)
        except np.linalg.LinAlgError:
            # Coincident samples or a flat variogram: the least-norm solution still
            # satisfies the constraint and gives the common value.
            sol = np.linalg.lstsq(self._system, rhs, rcond=None)[0]
        weights, mu = sol[:k].T, sol[k]
        variance = np.maximum(np.sum(weights * rhs[:k].T, axis=1) + mu, 0.0)
        return KrigingEstimate(weights @ self.values, variance, weights)


def _as_samples(points, values):
    x = np.asarray(points, dtype=float)
    r = np.asarray(values, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if r.ndim == 1:
        r = r[:, None]
    if x.ndim != 2 or r.ndim != 2 or len(x) != len(r) or len(x) == 0:
        raise ValueError(f'Kriging samples: expected points (K, D) and values (K,) or '
                         f'(K, M) with the same K >= 1, got shapes {np.shape(points)} and '
                         f'{np.shape(values)}')
    if not (np.isfinite(x).all() and np.isfinite(r).all()):
        raise ValueError('Kriging samples: points and values must be finite')
    return x, r
