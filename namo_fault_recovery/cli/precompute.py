"""
The ``precompute`` command of ``namo-recovery``: build the contingency table offline.

One entry per fault set (each joint failing on top of ``--active`` faults, all joints
by default or those of ``--joint``), each the best library of ``--seeds`` runs without a
deadline (:mod:`~namo_fault_recovery.recovery.contingency`).  The settings options are
``solve``'s, named like the node's parameters: a table is used only by a node whose
robot, library and settings (but the deadline) are the same.  ``--robot-profile`` builds
the table for another robot (its recovery profile, as the node's ``robot_profile``) with
its library (``--gesture-file``).
"""

import argparse
import math
import time

from .common import (add_setting_options, engine_settings, option_models, parse_faults,
                     UsageError, writing_out)


def cmd_precompute(args, out):
    """Build the table, print one line per entry and a summary, and write the file."""
    from ..recovery import contingency
    if args.jobs < 1:
        raise UsageError(f'--jobs: expected a number of processes >= 1, got {args.jobs}')
    if args.seeds < 1:
        raise UsageError(f'--seeds: expected a number of seeds >= 1, got {args.seeds}')
    budget = args.budget
    if budget is not None and (not math.isfinite(budget) or budget < 0):
        raise UsageError(f'--budget: expected a number of seconds >= 0 (0: none), got {budget}')
    budget = budget or None
    settings = engine_settings(args)
    robot, library = option_models(args)
    active = parse_faults(robot, args.active or [])
    joints = None
    if args.joint:
        for joint in args.joint:
            try:
                robot.locate_joint(joint)
            except KeyError as exc:
                raise UsageError(f'--joint: {exc.args[0]}') from None
        joints = tuple(dict.fromkeys(args.joint))
    try:
        sets = contingency.fault_sets(robot, library, settings, active, joints)
    except ValueError as exc:
        raise UsageError(f'--active: {exc}') from None
    if not sets:
        raise UsageError('no fault set to precompute (every --joint is already --active)')
    out.write(f'precomputing {len(sets)} fault sets, seeds 0..{args.seeds - 1}, '
              f"{'no deadline' if budget is None else f'{budget:g} s per seed'}, "
              f'{args.jobs} process(es), lock strategy {settings.lock_strategy}\n')
    out.flush()

    def show(built):
        locks = ', '.join(f'{j} = {math.degrees(a):.2f} deg' for j, a in built.locks.items())
        spread = max(built.seed_scores) - min(built.seed_scores)
        out.write(f'{locks}: total score {built.result.total_score:.4f} (seed '
                  f'{built.result.seed}; seeds spread {spread:.4f}) in {built.wall_sec:.2f} s '
                  f'({built.cpu_sec:.2f} s CPU)\n')
        out.flush()
    began = time.monotonic()
    table = contingency.build_table(robot, library, settings, sets, jobs=args.jobs,
                                    progress=show, seeds=range(args.seeds), budget_sec=budget)
    with writing_out(args.out):
        table.save(args.out)
    scores = [result.total_score for _, result in table.entries.values()]
    out.write(f'wrote {len(table)} entries to {contingency.expand(args.out)} in '
              f'{time.monotonic() - began:.1f} s (total scores {min(scores):.4f} .. '
              f'{max(scores):.4f}; fingerprint {table.fingerprint[:12]})\n')
    return 0


def register(sub):
    """Add the ``precompute`` subcommand to the main parser's subcommands."""
    from ..recovery.contingency import DEFAULT_SEEDS, DEFAULT_TABLE_PATH
    p = sub.add_parser('precompute',
                       help='build the contingency table: the best library of each likely '
                            'fault set, offline')
    p.add_argument('--out', default=DEFAULT_TABLE_PATH, metavar='FILE',
                   help=f'table file to write (default {DEFAULT_TABLE_PATH})')
    p.add_argument('--jobs', type=int, default=1, metavar='N',
                   help='worker processes (default 1)')
    p.add_argument('--seeds', type=int, default=len(DEFAULT_SEEDS), metavar='K',
                   help=f'seeds 0..K-1 per entry, the best kept (default {len(DEFAULT_SEEDS)})')
    p.add_argument('--budget', type=float, default=None, metavar='SEC',
                   help="seconds per seed (default: no deadline, the preset's full "
                        'iterations; 0: the same)')
    p.add_argument('--joint', action='append', metavar='JOINT',
                   help='only this joint failing (repeatable; default: all of the robot)')
    p.add_argument('--active', action='append', metavar='JOINT[=DEG]',
                   help='a fault already in force, that every entry adds to (repeatable; '
                        'without DEG the lock strategy chooses the angle)')
    # SUPPRESS: given after the command it wins; absent, the global option stands.
    p.add_argument('--robot-profile', default=argparse.SUPPRESS, metavar='FILE',
                   help="another robot's recovery profile (as the node's robot_profile; "
                        'default: the global --robot-profile, else the robot file)')
    p.add_argument('--gesture-file', default=argparse.SUPPRESS, metavar='FILE',
                   help="the robot's gesture library (as the node's gesture_file)")
    add_setting_options(p)
    p.set_defaults(func=cmd_precompute)
    return p
