"""
Lock strategies compared: the library total of ``average`` and ``optimal`` per fault.

For each of the 14 single faults (right and left arm, joints 1-7) the packaged library
is adapted with :func:`~namo_fault_recovery.recovery.engine.recover` and the node's
settings (:class:`~namo_fault_recovery.recovery.engine.RecoverySettings` defaults),
once with ``lock_strategy='average'`` and once with ``'optimal'``, with the same seed,
without a deadline and with the node's 1 s deadline.  The library total is the sum of
the gestures' ``score_after`` (each motion's worst point).  ``optimal`` must never be
above ``average``; without a deadline that holds exactly (the average run is part of
the optimal one), with a deadline the figures say how close the two come.

Run: ``python -m namo_fault_recovery.benchmarks.lock_compare [--seed 0] [--json F]``.
"""

import argparse
import json
import sys
import time

from ..model.gestures import load_library
from ..model.robot import ARMS, load_robot, N_JOINTS
from ..optimize.base import Clock
from ..recovery.engine import recover, RecoverySettings

DEADLINES = (None, 1.0)


def library_total(result):
    """Return a LibraryResult's total: the sum of its gestures' ``score_after``."""
    return float(sum(g.score_after for g in result.gestures))


def run_lock_compare(seed=0, deadlines=DEADLINES, faults=None, robot=None, library=None,
                     settings=None, out=sys.stdout):
    """
    Compare ``average`` and ``optimal`` on every single fault; print and return figures.

    ``faults`` is a list of joint names (default: every joint of both arms).  Returns
    ``{'seed', 'rows': [{joint, deadline, average, optimal, lock_average, lock_optimal,
    wall_average, wall_optimal, deadline_met_optimal}]}``, totals as defined above.
    """
    robot = robot or load_robot()
    library = library or load_library(robot)
    settings = settings or RecoverySettings()
    joints = faults or [robot.arms[side].joint_names[j] for side in ARMS
                        for j in range(N_JOINTS)]
    rows = []
    print(f"library totals (sum of score_after), seed {seed}; settings: the node's "
          f'defaults', file=out)
    print(f'{"joint":<18} {"deadline":>8} {"average":>9} {"optimal":>9} {"diff":>8} '
          f'{"lock avg":>9} {"lock opt":>9} {"t avg":>6} {"t opt":>6}', file=out)
    for deadline in deadlines:
        for joint in joints:
            row = {'joint': joint, 'deadline': deadline}
            for strategy in ('average', 'optimal'):
                began = time.monotonic()
                res = recover(robot, library, {joint: None},
                              settings.with_changes(lock_strategy=strategy,
                                                    deadline_sec=deadline or 1.0),
                              seed=seed, clock=Clock(deadline))
                row[strategy] = library_total(res)
                row[f'lock_{strategy}'] = float(res.locks[joint])
                row[f'wall_{strategy}'] = time.monotonic() - began
                row[f'deadline_met_{strategy}'] = bool(res.deadline_met)
            rows.append(row)
            dl = 'none' if deadline is None else f'{deadline:g} s'
            print(f'{joint:<18} {dl:>8} {row["average"]:9.3f} {row["optimal"]:9.3f} '
                  f'{row["optimal"] - row["average"]:8.3f} '
                  f'{_deg(row["lock_average"]):9.2f} {_deg(row["lock_optimal"]):9.2f} '
                  f'{row["wall_average"]:6.2f} {row["wall_optimal"]:6.2f}', file=out,
                  flush=True)
    for deadline in deadlines:
        sub = [r for r in rows if r['deadline'] == deadline]
        worse = [r['joint'] for r in sub if r['optimal'] > r['average'] + 1e-9]
        dl = 'no deadline' if deadline is None else f'deadline {deadline:g} s'
        print(f'{dl}: average {sum(r["average"] for r in sub):.3f}, optimal '
              f'{sum(r["optimal"] for r in sub):.3f} over {len(sub)} faults; optimal '
              f'worse on: {", ".join(worse) or "none"}', file=out)
    return {'seed': seed, 'rows': rows}


def _deg(rad):
    return rad * 180.0 / 3.141592653589793


def main(argv=None):
    """Command line: print the comparison, optionally write it as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--joint', action='append', help='only these joints (repeatable)')
    parser.add_argument('--no-deadline-only', action='store_true',
                        help='skip the runs at the 1 s deadline')
    parser.add_argument('--json', help='write the figures to this file')
    args = parser.parse_args(argv)
    deadlines = (None,) if args.no_deadline_only else DEADLINES
    data = run_lock_compare(args.seed, deadlines, args.joint)
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(data, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
