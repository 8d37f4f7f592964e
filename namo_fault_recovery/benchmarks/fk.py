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

Each round draws its batch from a pool of ``POOL`` different ones, as the search hands
the FK a new population every iteration.  One batch timed over and over is not what
the robot runs: the CPU's branch predictor learns the cosine's branches for those exact
angles, and the DH model, whose two arms turn the same angles (the left one is mirrored
afterwards), gains from it where the URDF chains, whose arms have their own offsets, do
not.  That figure (the row ``fk, one batch repeated``) is printed beside, for comparison.
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
POOL = 64
SAME_BATCH_ROW = 'fk, one batch repeated'


def _time_pair(calls, rounds, batches):
    """
    Return per-call times (s) of each callable on round r's batch, interleaved.

    Round r hands ``batches[r % len(batches)]`` to every call.  The order alternates
    from one round to the next, so that neither call always runs on the caches the
    other left.
    """
    times = [[] for _ in calls]
    for r in range(rounds):
        q = batches[r % len(batches)]
        order = list(zip(calls, times))
        for call, acc in (order if r % 2 == 0 else order[::-1]):
            start = time.perf_counter()
            call(q)
            acc.append(time.perf_counter() - start)
    return [np.array(t) for t in times]


def _max_difference(robot, profile, q):
    worst = 0.0
    for side in ARMS:
        dh = batch_forward(robot, q, side)
        chain = profile.arms[side].chain.batch_forward(q)
        worst = max(worst, *(float(np.abs(a - b).max()) for a, b in zip(dh[:3], chain[:3])))
    return worst


def _pairs(robot, profile):
    """Return {row: (DH call, URDF call)}, each call taking one batch of angles."""
    chains = {side: profile.arms[side].chain for side in ARMS}
    engine = robot_from_profile(profile, capsules=robot.capsules)
    return {
        'fk': (lambda q: [batch_forward(robot, q, s) for s in ARMS],
               lambda q: [chains[s].batch_forward(q) for s in ARMS]),
        'jacobian': (lambda q: [batch_forward_jacobian(robot, q, s) for s in ARMS],
                     lambda q: [chains[s].jacobian(q) for s in ARMS]),
        # The engine's path: the robot built from the profile, through model.kinematics.
        'fk (engine robot)': (lambda q: [batch_forward(robot, q, s) for s in ARMS],
                              lambda q: [batch_forward(engine, q, s) for s in ARMS]),
        'jacobian (engine robot)': (
            lambda q: [batch_forward_jacobian(robot, q, s) for s in ARMS],
            lambda q: [batch_forward_jacobian(engine, q, s) for s in ARMS]),
    }


def _row(dh, urdf):
    """Return the figures of one timed pair (the median of the rounds' own ratios)."""
    return {'dh_median_us': float(np.median(dh) * 1e6),
            'urdf_median_us': float(np.median(urdf) * 1e6),
            'dh_min_us': float(dh.min() * 1e6), 'urdf_min_us': float(urdf.min() * 1e6),
            'ratio': float(np.median(urdf / dh)),
            'ratio_of_minima': float(urdf.min() / dh.min())}


def run_fk(out, robot, batch=1000, rounds=300, seed=0, out_dir=None):
    """Time DH and URDF FK (and Jacobians) on ``batch`` configurations; print and return."""
    profile = load_profile(config_path(NAMO_PROFILE_FILE), urdf=urdf_string(robot))
    rng = np.random.default_rng(seed)
    pool = [rng.uniform(-np.pi, np.pi, (batch, robot_joints(profile)))
            for _ in range(min(POOL, rounds))]
    pairs = _pairs(robot, profile)
    doc = {'batch': batch, 'rounds': rounds, 'seed': seed, 'arms': list(ARMS),
           'batches': len(pool), 'machine': common.machine_info(),
           'target_ratio': TARGET_RATIO,
           'max_difference_mm': _max_difference(robot, profile, pool[0])}
    out.write(f'bench fk: Namo, both arms, batch {batch}, {rounds} interleaved rounds over '
              f'{len(pool)} different batches\n')
    out.write(common.format_machine(doc['machine']) + '\n')
    timed = [(name, calls, pool) for name, calls in pairs.items()]
    # For comparison only: one batch over and over (see the module docstring).
    timed.append((SAME_BATCH_ROW, pairs['fk'], pool[:1]))
    rows = []
    for name, calls, batches in timed:
        doc[name] = _row(*_time_pair(calls, rounds, batches))
        rows.append([name] + [f'{doc[name][k]:.1f}' for k in (
            'dh_median_us', 'urdf_median_us', 'dh_min_us', 'urdf_min_us')] +
            [f'{doc[name][k]:.3f}' for k in ('ratio', 'ratio_of_minima')])
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
