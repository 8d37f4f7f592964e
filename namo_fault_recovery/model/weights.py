"""
The score weights of a gesture: which similarity components count, and how much.

Part of a gesture's description (``config/gestures.yaml`` may give a gesture its own) and
of the node's settings; :mod:`~namo_fault_recovery.objective.score` applies them.
"""

from collections.abc import Mapping
from dataclasses import dataclass, fields
import math

import numpy as np

COMPONENTS = ('elbow', 'wrist', 'tip', 'palm', 'wrist_lr', 'tip_lr')
ARM_COMPONENTS = 4         # the first four are per arm; the last two only two-handed


@dataclass(frozen=True)
class ScoreWeights:
    """
    Relative component weights; by default equal and normalised to sum to 1.

    With ``normalise`` the weights of the components a gesture uses are scaled to sum
    to 1: 1/4 each for a one-arm gesture and 1/6 each for a two-handed one (the paper's
    "equal weight values for all components").
    """

    elbow: float = 1.0
    wrist: float = 1.0
    tip: float = 1.0
    palm: float = 1.0
    wrist_lr: float = 1.0
    tip_lr: float = 1.0
    normalise: bool = True

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == 'normalise':
                continue
            value = getattr(self, f.name)
            if (isinstance(value, bool) or not isinstance(value, (int, float))
                    or not math.isfinite(value) or value < 0):
                raise ValueError(f'score weight {f.name}: expected a finite number >= 0, '
                                 f'got {value!r}')
        if sum(getattr(self, c) for c in COMPONENTS[:ARM_COMPONENTS]) <= 0:
            raise ValueError('score weights: at least one of elbow, wrist, tip, palm '
                             'must be > 0')

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, float]) -> 'ScoreWeights':
        """Build weights from a dict, naming any unknown key."""
        unknown = set(mapping) - set(COMPONENTS) - {'normalise'}
        if unknown:
            raise ValueError(f'score weights: unknown component {sorted(unknown)[0]!r}; '
                             f'expected some of {", ".join(COMPONENTS)}')
        return cls(**mapping)

    def vector(self, two_handed: bool) -> np.ndarray:
        """Return the 6 weights of a gesture (the left-right ones are 0 if one-handed)."""
        w = np.array([getattr(self, c) for c in COMPONENTS], dtype=float)
        if not two_handed:
            w[ARM_COMPONENTS:] = 0.0
        if self.normalise:
            w /= w.sum()
        return w
