"""
``namo-recovery demo``: start a private node, inject a fault, show the result, stop.

Everything goes through :class:`~namo_fault_recovery.ros.client.RecoveryClient`; the
stick figures are drawn from the library received over ROS (needs matplotlib).
"""

import importlib.util
from pathlib import Path
import time

from .ros_common import (add_connection_arguments, CommandError, describe_fault,
                         domain_id, EXIT_FAILURE, fault_angles, namespace, open_client,
                         report_library, wrap)
from ..runtime.private_node import private_domain, PrivateNode

DEFAULT_FAULT = 'right_arm_joint2'


def save_figures(args, result, out_dir, out):
    """Save one stick figure per gesture of a received LibraryResult; return the paths."""
    if importlib.util.find_spec('matplotlib') is None:
        out.write('stick-figure PNG skipped: matplotlib is not installed '
                  "(pip install -e '.[plot]')\n")
        return []
    from ..benchmarks import plotting
    from ..model.gestures import load_library
    from ..model.robot import load_robot
    robot = load_robot(getattr(args, 'robot_file', None))
    library = load_library(robot, getattr(args, 'gesture_file', None))
    paths = []
    for name in library.names:
        path = Path(out_dir) / f'{name}.png'
        plotting.plot_reconfiguration(robot, library, result, name, path)
        out.write(f'stick figure saved: {path}\n')
        paths.append(path)
    return paths


def _run(args, client, out):
    from ..ros.client import RECONFIGURE_SERVICE
    reference = client.current_library(args.timeout, diagnostics_timeout=0.0)
    out.write(f'reference library received on {client.library_topic}: '
              f"{', '.join(reference.names)}\n")
    angles = fault_angles(args)
    outcome = client.report_fault(args.joints, angles, args.timeout)
    out.write(describe_fault(client.fault_topic, args.joints, angles))
    report_library(outcome, out)
    if not outcome.library.described:
        raise CommandError('no /diagnostics describing the new library')
    out.write(f'\ncalling {client.resolve_service(RECONFIGURE_SERVICE)}, '
              'as the gesture player does...\n')
    t0 = time.monotonic()
    answer = client.reconfigure(args.timeout)
    out.write(f"{'success' if answer.success else 'FAILURE'} "
              f'({time.monotonic() - t0:.3f} s): {answer.message}\n')
    after = None
    if answer.library_stamp is not None:
        after = client.next_library(answer.library_stamp - 1, args.timeout)
    if after is None or not after.described:
        after = outcome.library
    try:
        save_figures(args, after.result, args.out_dir, out)
    except Exception as exc:  # noqa: B902 - the figure is a bonus; report it
        out.write(f'stick-figure PNG not saved: {type(exc).__name__}: {exc}\n')


def cmd_demo(args, out):
    """Start the node, inject a fault, print scores before/after, save a PNG, shut down."""
    fault_angles(args)                      # bad arguments fail before a node starts
    ns = namespace(args)
    domain = domain_id(args)
    domain = private_domain() if domain is None else domain
    failed = True
    node = PrivateNode.for_args(args, domain, ns, out)
    try:
        with open_client(args, domain) as client:
            _run(args, client, out)
        failed = False
    finally:
        rc = node.stop()
        if rc != 0 or failed:
            out.write(f'node exited with code {rc}; its log:\n{node.log}')
        else:
            out.write(f'node stopped cleanly (exit code {rc})\n')
    return 0 if rc == 0 else EXIT_FAILURE


def register(subparsers):
    """Add ``demo``."""
    p = subparsers.add_parser('demo', help='start the node, inject a fault, show the '
                              'result, shut down')
    p.add_argument('joints', nargs='*', metavar='JOINT', default=[DEFAULT_FAULT],
                   help=f'failed joint(s) (default {DEFAULT_FAULT})')
    p.add_argument('--angle', type=float, nargs='+', metavar='DEG',
                   help='lock angle(s) in degrees (default: the lock strategy chooses)')
    p.add_argument('--out-dir', metavar='DIR', default='namo_demo',
                   help='where the stick figures go, one <gesture>.png each '
                        '(default ./namo_demo)')
    add_connection_arguments(p, timeout=30.0)
    p.set_defaults(func=wrap(cmd_demo))
