"""
Vector quantisation of a motion into typical points (the second source paper, step 1).

The designed joint vectors are clustered by k-means (scipy's ``kmeans2``), and each
codeword is replaced by the designed point nearest to it, so that every typical point
is a point of the motion whose reference is known exactly.  K is the smallest number
of codewords whose quantisation distortion stays within a threshold, as in the paper
(which asked for less than 60 mm in its world coordinates and got 8 typical points
on a circle of radius 150 mm).
"""

from dataclasses import dataclass, replace
import warnings

import numpy as np
from scipy.cluster.vq import kmeans2


@dataclass(frozen=True)
class Quantisation:
    """The typical points of a motion, and which typical point stands for each point."""

    typical: np.ndarray    # (K,) indices of the typical points, increasing
    labels: np.ndarray     # (T,) index into ``typical`` of each point's typical point
    distortion: float      # the largest distance of a point from its typical point
    threshold: float
    note: str = ''         # why the search for the fewest typical points stopped early

    @property
    def k(self):
        """Return the number of typical points."""
        return len(self.typical)


def quantise(vectors, threshold, features=None, seed=0, restarts=3, clock=None):
    """
    Return the Quantisation of ``vectors`` (T, D) with distortion <= ``threshold``.

    The clustering runs on ``vectors`` (joint angles); the distortion is measured on
    ``features`` (T, F), by default the vectors themselves, e.g. fingertip positions in
    mm for the paper's world-coordinate threshold.  K grows from 1 until the threshold
    holds (at K = T it always does); ``restarts`` k-means runs per K, seeded.

    With a ``clock`` (:class:`~namo_fault_recovery.optimize.base.Clock`) that expires
    before the threshold holds (a tight threshold on a long motion tries nearly every
    K), the search stops and every distinct point becomes a typical point: the
    threshold still holds (the distortion is 0), only the saving of exploring fewer
    points is lost, and ``note`` says so.
    """
    x = np.asarray(vectors, dtype=float)
    if x.ndim != 2 or len(x) == 0 or not np.isfinite(x).all():
        raise ValueError(f'quantise: expected finite vectors of shape (T, D) with T >= 1, '
                         f'got shape {x.shape}')
    feats = x if features is None else np.asarray(features, dtype=float)
    if feats.ndim != 2 or len(feats) != len(x):
        raise ValueError(f'quantise: features must have shape (T, F) with T = {len(x)}, '
                         f'got {feats.shape}')
    if not (np.isfinite(threshold) and threshold >= 0):
        raise ValueError(f'quantise: threshold must be a finite number >= 0, '
                         f'got {threshold!r}')
    rng = np.random.default_rng(seed)
    unique = len(np.unique(x, axis=0))
    best = None
    for k in range(1, len(x) + 1):
        if best is not None and clock is not None and clock.expired():
            every = _codebook(x, feats, unique, unique, rng, threshold)
            return replace(every, note=(
                f'the search for typical points stopped at K = {k - 1} (distortion '
                f'{best.distortion:.3g} > {threshold:.3g} mm) to stay within the deadline; '
                f'all {every.k} distinct points are explored'))
        best = None
        for _ in range(restarts if 1 < k < unique else 1):
            q = _codebook(x, feats, k, unique, rng, threshold)
            if best is None or q.distortion < best.distortion:
                best = q
        if best.distortion <= threshold:
            return best
    raise AssertionError('unreachable: K = T has zero distortion')


def _codebook(x, feats, k, unique, rng, threshold):
    if k >= unique:
        typical = np.unique(np.unique(x, axis=0, return_index=True)[1])
    else:
        with warnings.catch_warnings():   # an empty cluster is fine: its codeword drops
            warnings.simplefilter('ignore')
            centroids, _ = kmeans2(x, k, minit='++', seed=rng)
        nearest = np.argmin(np.linalg.norm(x[None] - centroids[:, None], axis=-1), axis=1)
        typical = np.unique(nearest)
    dist = np.linalg.norm(x[:, None] - x[typical][None], axis=-1)
    labels = np.argmin(dist, axis=1)
    distortion = float(np.max(np.linalg.norm(feats - feats[typical][labels], axis=-1)))
    return Quantisation(typical, labels, distortion, float(threshold))
