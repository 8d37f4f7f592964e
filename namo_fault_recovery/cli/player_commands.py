"""
``namo-recovery`` subcommands around the ``gesture_player`` node.

rclpy is imported only when one of them runs, so the rest of the command line works
without ROS.
"""

from pathlib import Path
import shutil
import sys
import time

EXIT_FAILURE = 1


def player_command():
    """Return the command that starts the ``gesture_player`` executable."""
    beside = Path(sys.executable).parent / 'gesture_player'
    if beside.is_file():
        return [str(beside)]
    found = shutil.which('gesture_player')
    if found:
        return [found]
    return [sys.executable, '-m', 'namo_fault_recovery.ros.player_node']


def call_play(node, gesture, timeout, player='/gesture_player', spin=None):
    """
    Call ``<player>/play/<gesture>`` from an rclpy node; return (success, message).

    ``spin(timeout_sec)`` spins the node's executor; None when another thread spins it.
    """
    from std_srvs.srv import Trigger
    client = node.create_client(Trigger, f'{player}/play/{gesture}')
    try:
        end = time.monotonic() + timeout
        if not client.wait_for_service(timeout_sec=min(timeout, 10.0)):
            return False, f'no service {player}/play/{gesture}; is gesture_player running?'
        future = client.call_async(Trigger.Request())
        while not future.done() and time.monotonic() < end:
            if spin is None:
                time.sleep(0.02)
            else:
                spin(0.05)
        if not future.done():
            return False, f'no answer within {timeout:g} s'
        return future.result().success, future.result().message
    finally:
        node.destroy_client(client)


def cmd_play(args, out):
    """Play one gesture on a running gesture_player; exit 1 when the play failed."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    context = Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    node = rclpy.create_node('namo_recovery_play', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        ok, message = call_play(node, args.gesture, args.timeout,
                                spin=lambda t: executor.spin_once(timeout_sec=t))
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    out.write(f"{'success' if ok else 'FAILURE'}: {message}\n")
    return 0 if ok else EXIT_FAILURE


def _common(parser, timeout):
    parser.add_argument('--timeout', type=float, default=timeout, metavar='SEC',
                        help=f'how long to wait (default {timeout:g} s)')
    parser.add_argument('--domain-id', type=int, default=None, metavar='N',
                        help='ROS domain id (default: $ROS_DOMAIN_ID, else 0)')


def register(subparsers, bench_subparsers):
    """Add ``play`` to the subcommands."""
    p = subparsers.add_parser('play', help='play a gesture on the running gesture_player')
    p.add_argument('gesture', help='gesture name, e.g. wai')
    _common(p, 60.0)
    p.set_defaults(func=cmd_play)
