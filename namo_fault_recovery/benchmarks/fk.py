"""
``bench fk``: the URDF-compiled chains' batched FK against the DH FK, on Namo.

Both run side by side in one run, from the same robot file: the DH model as the engine
loads it, the URDF one compiled from the URDF generated from that file
(``config/namo_profile.yaml`` over ``urdf_string``).  Each round times one batch of
``batch`` configurations through both arms of each model (the chains themselves, and
the engine's robot built from the profile through :mod:`..model.kinematics`, the path
the score and the search take), back to back in alternating order, so that a change
in machine load hits both; the figure is the median of the rounds' own URDF / DH
ratios (target: <= 1.1 for a batch of 1,000), printed beside the ratio of the best
times.  The Jacobians are timed the same way, and the largest
difference between the two models' landmarks is printed (they are the same kinematics).
"""

import time

import numpy as np

from . import common
from ..model.kinematics import batch_forward, batch_forward_jacobian
from ..model.profile_robot import robot_from_profile
from ..model.robot import ARMS
from ..model.robot_profile import load_profile
from ..model.urdf import urdf_string
from ..resources import config_path, NAMO_PROFILE_FILE

TARGET_RATIO = 1.1


def _time_pair(calls, rounds):
    """
    Return per-call times (s) of each callable, interleaved round by round.

    The order alternates from one round to the next, so that neither call always runs
    on the caches the other left.
    """
    times = [[] for _ in calls]
    for r in range(rounds):
        order = list(zip(calls, times))
        for call, acc in (order if r % 2 == 0 else order[::-1]):
            start = time.perf_counter()
            call()
            acc.append(time.perf_counter() - start)
    return [np.array(t) for t in times]


def _max_difference(robot, profile, q):
    worst = 0.0
    for side in ARMS:
        dh = batch_forward(robot, q, side)
        chain = profile.arms[side].chain.batch_forward(q)
        worst = max(worst, *(float(np.abs(a - b).max()) for a, b in zip(dh[:3], chain[:3])))
    return worst


def run_fk(out, robot, batch=1000, rounds=300, seed=0, out_dir=None):
    """Time DH and URDF FK (and Jacobians) on ``batch`` configurations; print and return."""
    profile = load_profile(config_path(NAMO_PROFILE_FILE), urdf=urdf_string(robot))
    q = np.random.default_rng(seed).uniform(-np.pi, np.pi, (batch, robot_joints(profile)))
    chains = {side: profile.arms[side].chain for side in ARMS}
    engine = robot_from_profile(profile, capsules=robot.capsules)
    pairs = {
        'fk': (lambda: [batch_forward(robot, q, s) for s in ARMS],
               lambda: [chains[s].batch_forward(q) for s in ARMS]),
        'jacobian': (lambda: [batch_forward_jacobian(robot, q, s) for s in ARMS],
                     lambda: [chains[s].jacobian(q) for s in ARMS]),
        # The engine's path: the robot built from the profile, through model.kinematics.
        'fk (engine robot)': (lambda: [batch_forward(robot, q, s) for s in ARMS],
                              lambda: [batch_forward(engine, q, s) for s in ARMS]),
        'jacobian (engine robot)': (
            lambda: [batch_forward_jacobian(robot, q, s) for s in ARMS],
            lambda: [batch_forward_jacobian(engine, q, s) for s in ARMS]),
    }
    doc = {'batch': batch, 'rounds': rounds, 'seed': seed, 'arms': list(ARMS),
           'machine': common.machine_info(), 'target_ratio': TARGET_RATIO,
           'max_difference_mm': _max_difference(robot, profile, q)}
    out.write(f'bench fk: Namo, both arms, batch {batch}, {rounds} interleaved rounds\n')
    out.write(common.format_machine(doc['machine']) + '\n')
    rows = []
    for name, (dh_call, urdf_call) in pairs.items():
        dh, urdf = _time_pair((dh_call, urdf_call), rounds)
        # The figure: the median over rounds of each round's own ratio (the two calls of a
        # round run back to back, under the same load); the best-of ratio beside it.
        ratio = float(np.median(urdf / dh))
        doc[name] = {'dh_median_us': float(np.median(dh) * 1e6),
                     'urdf_median_us': float(np.median(urdf) * 1e6),
                     'dh_min_us': float(dh.min() * 1e6), 'urdf_min_us': float(urdf.min() * 1e6),
                     'ratio': ratio, 'ratio_of_minima': float(urdf.min() / dh.min())}
        rows.append([name, f'{np.median(dh) * 1e6:.1f}', f'{np.median(urdf) * 1e6:.1f}',
                     f'{dh.min() * 1e6:.1f}', f'{urdf.min() * 1e6:.1f}', f'{ratio:.3f}',
                     f'{urdf.min() / dh.min():.3f}'])
    out.write(common.text_table(['what', 'DH median us', 'URDF median us', 'DH min us',
                                 'URDF min us', 'URDF / DH', 'of minima'], rows))
    for name in ('fk', 'fk (engine robot)'):
        verdict = 'met' if doc[name]['ratio'] <= TARGET_RATIO else 'MISSED'
        out.write(f'{name} ratio {doc[name]["ratio"]:.3f} (target <= {TARGET_RATIO}): '
                  f'{verdict}\n')
    out.write(f'largest landmark difference DH vs URDF: {doc["max_difference_mm"]:.2e} mm\n')
    if out_dir is not None:
        common.write_json(out_dir / 'fk.json', doc)
        out.write(f'written: {out_dir / "fk.json"}\n')
    return doc


def robot_joints(profile):
    """Return the number of chain joints per arm (the same for both of Namo's arms)."""
    return profile.arms['right'].chain.n_joints
