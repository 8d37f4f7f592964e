"""
What one exploration is asked, and what it found (shared by both explorers).

An :class:`ExploreTask` is one arm's typical points: the poses to start from (the
design with any locks applied), the fingertip targets (mm, base frame), the nominal
chain (the prior; the SA explorer does not use it), the joint limits and the staged
free-joint layouts (the designed DOF first, then each expansion stage).  A
:class:`PointOutcome` is the poses each typical point ended on, as measured.
"""

from dataclasses import dataclass, field

import numpy as np

DEFAULT_EXPANSION_MM = 5.0     # a typical point missing its target by more expands the DOF


@dataclass(frozen=True)
class ExploreTask:
    """One arm's typical points to explore, and what the explorer may move."""

    chain: object               # nominal KinematicChain (mm), the prior
    start: np.ndarray           # (K, n) rad: the designed poses, locks applied
    targets: np.ndarray         # (K, 3) mm: where the fingertip should be
    lower: np.ndarray           # (n,) rad
    upper: np.ndarray           # (n,) rad
    layouts: tuple              # ((stage, free joint indices), ...), designed DOF first
    sigma_mm: float = 1.0       # the tracker's noise (its declared standard deviation)
    expansion_mm: float = DEFAULT_EXPANSION_MM
    point_ids: tuple = ()       # the typical points' indices in their motion (for logs)

    def __post_init__(self):
        start = np.asarray(self.start, dtype=float)
        targets = np.asarray(self.targets, dtype=float)
        if start.ndim != 2 or targets.shape != (len(start), 3) or not len(self.layouts):
            raise ValueError(f'explore task: expected start (K, n), targets (K, 3) and at '
                             f'least one layout, got {start.shape}, {targets.shape} and '
                             f'{len(self.layouts)} layouts')
        if not (np.isfinite(self.sigma_mm) and self.sigma_mm > 0):
            raise ValueError(f'explore task: sigma_mm must be > 0, got {self.sigma_mm!r}')


@dataclass
class PointOutcome:
    """What an explorer found at the typical points, by measurement."""

    q: np.ndarray                 # (K, n) rad: each point's final commanded pose
    measured: np.ndarray          # (K, 3) mm: the tracker's tip at that pose
    trials: np.ndarray            # (K,) trials commanded per typical point
    stage: int = 0                # DOF expansion stage reached
    free: tuple = ()              # free joint indices of that stage
    correction: str = ''          # what the shared model fit found (ours)
    model: object = None          # that fit (a :class:`.corrections.Correction`), ours only
    status: str = 'converged'     # converged | budget | stopped | refused
    notes: list = field(default_factory=list)

    def measured_error(self, targets):
        """Return the measured fingertip error (K,) mm at the final poses."""
        return np.linalg.norm(self.measured - targets, axis=1)
