"""
The self-collision clearance a :class:`~.trial.SafetyCheck` asks of the model.

The capsule model of :mod:`namo_fault_recovery.model.self_contact` (the one the
objective and the simulator share): the clearance of a pose is the smallest distance
between the surfaces of every checked pair that involves the moving arm, with the other
arm held where it is.  The model is the nominal one, so an unknown tool is not in it:
the margin covers that.
"""

import numpy as np

from ..model.kinematics import forward_kinematics, split_arms
from ..model.robot import ARMS
from ..model.self_contact import pair_distances, PAIRS, radius_sums


def capsule_clearance(robot, side, held):
    """
    Return ``clearance(q)``: (N, n) poses of ``side`` -> (N,) smallest clearance (mm).

    ``held`` (J,) rad is the whole robot's pose; the other arm stays at its part of it.
    """
    other = [s for s in ARMS if s != side][0]
    rest = split_arms(robot, held)[ARMS.index(other)]
    mine = np.array([side in (a, b) for a, _, b, _ in PAIRS])
    sums = radius_sums(robot.capsules)[mine]

    def clearance(q):
        q = np.atleast_2d(np.asarray(q, dtype=float))
        lm = {side: forward_kinematics(robot, q, side),
              other: forward_kinematics(robot, np.repeat(rest[None], len(q), axis=0), other)}
        d = pair_distances(robot, lm['right'], lm['left'])[0]
        return np.min(d[:, mine] - sums[None], axis=1)
    return clearance
