"""
The nodes' ``main()``: start ROS, build the node, spin until shutdown, shut down cleanly.

:func:`run_node` is the one body of ``recovery_node``, ``gesture_player`` and
``namo_sim``: exit code 0 on SIGINT or SIGTERM (at any moment), 1 with one line on
stderr for a bad configuration, and every thread, executor and context shut down.

It spins an executor until ROS is shut down, even when the shutdown's wake-up is lost.

rclpy's ``Executor.spin()`` waits without a timeout and relies on the context's
shutdown to trigger a guard condition that wakes it.  When SIGTERM shuts the context
down while the executor is rebuilding its wait set, that guard's handle is already
invalid, rclpy leaves it out of the wait set, and the wait never returns unless a
message happens to arrive (measured: ``namo_sim`` hung on SIGTERM about one stop in
ten once the other nodes had gone quiet).  :func:`spin_until_shutdown` waits in bounded
slices instead, so a lost wake-up costs at most ``period`` seconds.
"""

import sys

import rclpy
from rclpy.executors import ExternalShutdownException, ShutdownException, SingleThreadedExecutor

DEFAULT_PERIOD = 0.5      # s: the longest a lost shutdown wake-up can delay the exit
EXIT_CONFIG = 1           # the exit code of a bad configuration


def spin_until_shutdown(executor, context, period=DEFAULT_PERIOD):
    """
    Run ``executor`` until ``context`` is shut down (e.g. by SIGINT or SIGTERM).

    Raises ``ExternalShutdownException`` when it ends that way, as ``spin()`` does, so
    that a node's ``main()`` handles both alike.
    """
    while context.ok():
        try:
            executor.spin_once(timeout_sec=period)
        except ShutdownException:
            break
        except ExternalShutdownException:
            raise
        except Exception:  # noqa: B902 - e.g. a timer created on a context going down
            if context.ok():
                raise
            break
    raise ExternalShutdownException()


def _config_error(name, exc):
    """Write a bad configuration's one line, ``NAME: error: what``, to stderr."""
    text = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
    sys.stderr.write(f'{name}: error: {" ".join(str(text).split())}\n')


def run_node(name, build, args=None, config_errors=(), interrupted=lambda: False):
    """
    Run the node ``build()`` makes until Ctrl-C or SIGTERM; return the exit code.

    ``name`` prefixes the error line; ``config_errors`` are the exception types of a bad
    parameter or file (one line, exit code 1); ``interrupted()`` says whether a signal
    already arrived during start-up (``recovery_node`` handles its own before rclpy's),
    in which case nothing more is built and the exit is a clean 0.  One executor thread:
    every callback of the nodes is short and non-blocking (the work runs in the nodes'
    own threads), and with a thread pool the executor's threads, woken by each
    ``/joint_states`` sample and resuming the pending ``async`` callbacks, fought those
    threads for the interpreter lock (measured: a fault's report took p95 27 ms to reach
    its callback, and the player's ``/joint_states`` stalled for seconds).
    """
    try:
        rclpy.init(args=args)      # rclpy's handlers turn SIGINT and SIGTERM into a shutdown
    except Exception as exc:  # noqa: B902 - e.g. malformed --ros-args
        if interrupted():
            return 0
        _config_error(name, RuntimeError(f'cannot initialise ROS: {exc}'))
        return EXIT_CONFIG
    node = executor = None
    try:
        executor = SingleThreadedExecutor()
        if interrupted():
            raise ExternalShutdownException()
        try:
            node = build()
        except config_errors as exc:   # only while building: a callback's error is not one
            if interrupted():          # a start-up cut short by Ctrl-C or SIGTERM
                return 0
            _config_error(name, exc)
            return EXIT_CONFIG
        executor.add_node(node)
        if not interrupted():
            spin_until_shutdown(executor, node.context)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # noqa: B902
        if rclpy.ok() and not interrupted():
            raise          # a genuine error: let it be seen
        # Otherwise a signal shut ROS down during start-up or while a thread waited.
    finally:
        _shut_down(node, executor)
    return 0


def _shut_down(node, executor):
    """Stop the node's own threads (if it has any), then the executor, node and context."""
    if node is not None and hasattr(node, 'stop'):
        node.stop()
    if executor is not None:
        executor.shutdown(timeout_sec=2.0)
    if node is not None:
        node.destroy_node()
    rclpy.try_shutdown()
