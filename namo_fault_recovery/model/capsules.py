"""The capsule dimensions of the arms and torso (config data, no geometry code)."""

from dataclasses import dataclass, field
import math

import numpy as np


@dataclass(frozen=True)
class CapsuleModel:
    """
    Radii (mm) of the arm capsules and the torso capsule's axis and radius.

    Defaults are plausible for Namo's size: a 182 mm shoulder half-width, 206 mm upper
    arm and forearm and a 130 mm hand; the torso is a 120 mm radius column below the
    shoulders, so an arm hanging at rest clears it by 22 mm.
    """

    upper_arm: float = 40.0
    forearm: float = 35.0
    hand: float = 25.0
    torso_radius: float = 120.0
    torso_top: tuple = (0.0, 0.0, -40.0)
    torso_bottom: tuple = (0.0, 0.0, -500.0)
    weight: float = 1.0
    # The torso's own shape, which the forearms and hands must clear too (a
    # model.torso_field.TorsoField fitted to a URDF's torso; None on Namo).
    torso_field: object = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        for name in ('upper_arm', 'forearm', 'hand', 'torso_radius', 'weight'):
            value = getattr(self, name)
            if (isinstance(value, bool) or not isinstance(value, (int, float))
                    or not math.isfinite(value) or value < 0):
                raise ValueError(f'capsules.{name}: expected a finite number >= 0, '
                                 f'got {value!r}')
        for name in ('torso_top', 'torso_bottom'):
            value = getattr(self, name)
            if (not isinstance(value, (tuple, list)) or len(value) != 3
                    or not all(isinstance(v, (int, float)) and math.isfinite(v)
                               for v in value)):
                raise ValueError(f'capsules.{name}: expected 3 finite numbers (mm), '
                                 f'got {value!r}')

    @property
    def radii(self):
        """Radii of the three arm segments, in SEGMENTS order."""
        return np.array([self.upper_arm, self.forearm, self.hand])
