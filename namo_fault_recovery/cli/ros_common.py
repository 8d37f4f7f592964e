"""
What the ROS commands of ``namo-recovery`` share: connection options, errors, tables.

Every ROS command (``fault``, ``clear``, ``reconfigure``, ``library``, ``demo``,
``export``, ``play``, ``demo-play``, ``bench latency | stream | product``) is a thin
caller of :class:`~namo_fault_recovery.ros.client.RecoveryClient` (the player's
services: :class:`~namo_fault_recovery.ros.player_client.PlayerClient`).  Those of
the node take ``--namespace NS`` (the node's namespace, default the root) and
``--domain-id N`` (default ``$ROS_DOMAIN_ID``, else 0), either before the command name
or after it.  Nothing here imports rclpy: the client module is imported when a
command runs, so the offline commands work without ROS.

Exit codes: 0 on success, 1 when the node is unreachable, rejects the input or reports
a failure, 2 for bad arguments.
"""

import argparse
import math
import sys

from ..errors import EXIT_FAILURE, EXIT_USAGE, ReportedError


class CommandError(ReportedError):
    """A failure of a ROS command reported on one line; ``code`` is the exit code."""


def add_global_arguments(parser):
    """Add ``--namespace`` and ``--domain-id`` before the command name (all ROS commands)."""
    parser.add_argument('--namespace', default='/', metavar='NS',
                        help='namespace of the recovery_node the ROS commands talk to, '
                             'e.g. /robot1 (default: the root namespace)')
    parser.add_argument('--domain-id', type=int, default=None, metavar='N',
                        help='ROS domain id of the ROS commands (default: $ROS_DOMAIN_ID, '
                             'else 0)')


def add_connection_arguments(parser, timeout=15.0):
    """Add ``--timeout``, ``--namespace`` and ``--domain-id`` to one ROS command."""
    parser.add_argument('--timeout', type=float, default=timeout, metavar='SEC',
                        help=f'how long to wait for the node (default {timeout:g} s)')
    # SUPPRESS: given after the command it wins; absent, the global option stands.
    parser.add_argument('--namespace', default=argparse.SUPPRESS, metavar='NS',
                        help="the node's namespace, e.g. /robot1 (default: the root)")
    parser.add_argument('--domain-id', type=int, default=argparse.SUPPRESS, metavar='N',
                        help='ROS domain id (default: $ROS_DOMAIN_ID, else 0)')


def namespace(args):
    """Return the command's namespace, checked and absolute ('/' if none was given)."""
    from ..ros.client import normalise_namespace
    return normalise_namespace(getattr(args, 'namespace', None))


def domain_id(args):
    """Return the domain id the command was given (None: ``$ROS_DOMAIN_ID``)."""
    return getattr(args, 'domain_id', None)


def open_client(args, domain=None):
    """Return a RecoveryClient for the node in the command's namespace and domain."""
    from ..ros.client import RecoveryClient
    return RecoveryClient(namespace(args), domain if domain is not None else domain_id(args))


def wrap(func):
    """Return ``func(args, out)`` turned into a command: one-line errors, exit codes."""
    def run(args, out):
        from ..ros.client import BadNamespace, ClientError
        try:
            return func(args, out)
        except BadNamespace as exc:
            return _fail(exc, EXIT_USAGE)
        except ReportedError as exc:      # CommandError, a benchmark's BenchError
            return _fail(exc, exc.code)
        except ClientError as exc:
            return _fail(exc, EXIT_FAILURE)
        except KeyboardInterrupt:
            sys.stderr.write('namo-recovery: interrupted\n')
            return 130
    run.__doc__ = func.__doc__
    return run


def _fail(exc, code):
    sys.stderr.write(f'namo-recovery: error: {exc}\n')
    return code


def fault_angles(args):
    """Return the ``--angle`` degrees of a fault command in radians (None if absent)."""
    if args.angle is None:
        return None
    if len(args.angle) != len(args.joints):
        raise CommandError(f'--angle: expected one angle (deg) per joint ({len(args.joints)}), '
                           f'got {len(args.angle)}', EXIT_USAGE)
    if not all(math.isfinite(a) for a in args.angle):
        raise CommandError('--angle: angles must be finite', EXIT_USAGE)
    return [math.radians(a) for a in args.angle]


def describe_fault(topic, joints, angles):
    """Return the line that says which fault was reported where."""
    if angles:
        what = ', '.join(f'{j} at {math.degrees(a):.2f} deg' for j, a in zip(joints, angles))
    else:
        what = ', '.join(joints) + " (lock angle chosen by the node's lock strategy)"
    return f'fault reported on {topic}: {what}\n'


def gesture_table(result):
    """Return the score table of a LibraryResult, with its timing and frozen arms."""
    lines = [f"{'gesture':<14}{'before':>10}{'after':>10}{'time (s)':>10}  status"]
    for g in result.gestures:
        lines.append(f'{g.name:<14}{g.score_before:>10.2f}{g.score_after:>10.2f}'
                     f'{g.wall_time:>10.3f}  {g.status}')
    lines.append(f'library time {result.wall_time:.4f} s, deadline {result.deadline:g} s '
                 f"{'met' if result.deadline_met else 'MISSED'}"
                 + (f' by the deadline result; refined {result.refined_after:.3f} s after it'
                    if result.origin == 'refined' and result.refined_after is not None
                    else ''))
    if result.frozen_arms:
        lines.append(f"frozen arm(s): {' '.join(result.frozen_arms)}")
    return '\n'.join(lines) + '\n'


def lock_lines(result):
    """Return one 'locked: JOINT at X deg' line per lock of a LibraryResult."""
    return ''.join(f'locked: {joint} at {math.degrees(lock):.2f} deg\n'
                   for joint, lock in result.locks.items())


def report_library(outcome, out, what='new library'):
    """Print a fault's outcome; raise CommandError if the node rejected the fault."""
    if outcome.rejected is not None:
        raise CommandError(f'the node rejected the fault report: {outcome.rejected}')
    library = outcome.library
    out.write(f'{what} received {outcome.elapsed:.3f} s after the report '
              f'({len(library.names)} gestures)\n')
    if not library.described:
        out.write('no /diagnostics describing it arrived: scores and locks unknown\n')
        return
    out.write(gesture_table(library.result))
    out.write(lock_lines(library.result))
