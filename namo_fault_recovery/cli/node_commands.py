"""
``namo-recovery fault | clear | reconfigure | library``: calls to a running node.

For machines without the ``ros2`` tool; each command is a few calls of
:class:`~namo_fault_recovery.ros.client.RecoveryClient` in the node's namespace and
domain, and prints what came back.
"""

import json
import math
import re
import time

from .ros_common import (add_connection_arguments, add_global_arguments, describe_fault,
                         EXIT_FAILURE, fault_angles, open_client, report_library, wrap)


def cmd_fault(args, out):
    """Report failed joints to the node and print the reconfigured library's scores."""
    angles = fault_angles(args)
    with open_client(args) as client:
        outcome = client.report_fault(args.joints, angles, args.timeout)
        out.write(describe_fault(client.fault_topic, args.joints, angles))
    report_library(outcome, out)
    return 0


def cmd_clear(args, out):
    """Call clear_faults and print its answer."""
    with open_client(args) as client:
        answer = client.clear_faults(args.timeout)
    out.write(answer.message + '\n')
    return 0 if answer.success else EXIT_FAILURE


def cmd_reconfigure(args, out):
    """Call reconfigure_gestures (what the gesture player does) and print its answer."""
    with open_client(args) as client:
        t0 = time.monotonic()
        answer = client.reconfigure(args.timeout)
        elapsed = time.monotonic() - t0
    out.write(f"{'success' if answer.success else 'FAILURE'} ({elapsed:.3f} s): "
              f'{answer.message}\n')
    return 0 if answer.success else EXIT_FAILURE


def _library_header(library):
    stamp = library.stamp
    when = time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(stamp / 1e9))
    text = (f'library of {when}.{stamp % 1_000_000_000 // 1_000_000:03d} '
            f'({len(library.names)} gestures); angles in degrees')
    locks = library.result.locks
    if not library.described:
        return text + '; locked joints unknown (no /diagnostics received)\n'
    if locks:
        return text + '; * = locked joint: ' + ', '.join(
            f'{j} at {math.degrees(a):.2f}' for j, a in locks.items()) + '\n'
    return text + '; no locked joint (reference library)\n'


def arm_of(joint):
    """
    Return the arm ('right', 'left') a joint name says, else None (a torso joint).

    Namo's ``right_arm_joint2`` as Talos's ``arm_right_2_joint``: the side must be a word
    of the name (``_``, ``/`` or its ends around it), as the profile template guesses.
    """
    for side in ('right', 'left'):
        if re.search(rf'(^|[_/]){side}([_/]|$)', joint):
            return side
    return None


def format_library(library, out):
    """Print a PublishedLibrary in degrees, one row per arm and keyframe, locks starred."""
    out.write(_library_header(library))
    locks = library.result.locks
    joints = library.joint_names
    for gesture in library.result.gestures:
        out.write(f'\n{gesture.name}\n')
        for t, positions in zip(gesture.times, gesture.positions):
            out.write(f'  t = {t:.3f} s\n')
            for side in ('right', 'left'):
                cells = ' '.join(f"{math.degrees(a):8.2f}{'*' if j in locks else ' '}"
                                 for j, a in zip(joints, positions) if arm_of(j) == side)
                if cells:
                    out.write(f'    {side:<5} {cells}\n')
        others = [j for j in joints if arm_of(j) is None]
        if others and gesture.positions:
            out.write(f"    other joints: {', '.join(others)}\n")


def library_document(library):
    """Return the JSON document of ``library --json`` (radians)."""
    return {'stamp_ns': library.stamp,
            'library_version': library.library_version,
            'locked_joints': dict(library.result.locks) if library.described else None,
            'gestures': {g.name: [{'time_from_start': t,
                                   'positions_rad': dict(zip(library.joint_names, q))}
                                  for t, q in zip(g.times, g.positions)]
                         for g in library.result.gestures}}


def cmd_library(args, out):
    """Print the current library received from gesture_library."""
    with open_client(args) as client:
        library = client.current_library(args.timeout,
                                         diagnostics_timeout=min(args.timeout, 3.0))
    if args.json:
        out.write(json.dumps(library_document(library), indent=2) + '\n')
    else:
        format_library(library, out)
    return 0


def register(subparsers, parser=None):
    """Add fault, clear, reconfigure and library (and, given ``parser``, its ROS options)."""
    if parser is not None:
        add_global_arguments(parser)
    p = subparsers.add_parser('fault', help='report failed joints to the running node')
    p.add_argument('joints', nargs='+', metavar='JOINT',
                   help='failed joint, e.g. right_arm_joint2')
    p.add_argument('--angle', type=float, nargs='+', metavar='DEG',
                   help="lock angle(s) in degrees, one per joint (default: the node's lock "
                        'strategy chooses)')
    add_connection_arguments(p)
    p.set_defaults(func=wrap(cmd_fault))

    p = subparsers.add_parser('clear', help='forget every fault (clear_faults)')
    add_connection_arguments(p)
    p.set_defaults(func=wrap(cmd_clear))

    p = subparsers.add_parser('reconfigure',
                              help='call reconfigure_gestures and print its summary')
    add_connection_arguments(p)
    p.set_defaults(func=wrap(cmd_reconfigure))

    p = subparsers.add_parser('library', help='print the library received from '
                              'gesture_library (degrees, locked joints marked)')
    p.add_argument('--json', action='store_true', help='print one JSON document (radians)')
    add_connection_arguments(p)
    p.set_defaults(func=wrap(cmd_library))
