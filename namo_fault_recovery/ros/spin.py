"""
The nodes' ``main()``: start ROS, build the node, spin until shutdown, shut down cleanly.

:func:`run_node` is the one body of ``recovery_node``, ``gesture_player`` and
``namo_sim``: exit code 0 on SIGINT or SIGTERM (at any moment), 1 with one line on
stderr for a bad configuration, and every thread, executor and context shut down.  A
node that declares ``thread_priority`` has its threads put under ``SCHED_FIFO`` once
it is built (:func:`use_priority`).

It spins an executor until ROS is shut down, even when the shutdown's wake-up is lost.

As we read rclpy 7.1, its signal handler wakes the executor (its signal guard
condition) and shuts the contexts down from a thread of its own, without running the
context's ``on_shutdown`` callbacks (the executor's own wake-up).  An executor woken
before the shutdown finds the context still up, waits again, and nothing wakes it
unless a message happens to arrive (measured: ``namo_sim`` hung on SIGTERM about one
stop in ten once the other nodes had gone quiet).  A Python-level signal handler
cannot help: it runs in the main thread, the one blocked in that wait.
:func:`spin_until_shutdown` therefore spins without a timeout, as ``spin()`` does, and
a watcher thread checks the context every ``WATCH_PERIOD`` s; once it is down, the
watcher wakes the executor, which then ends.

It replaces waiting in 0.5 s slices (``spin_once(timeout_sec=0.5)``), for which rclpy
builds a new timeout timer each time a wait yields work.  Measured with
``namo-recovery bench idle`` (table off): 1.47 % of a core with the slices, 1.37 %
without them; the rest was the node's 10 Hz tick (see :mod:`.node`), 0.35 % with both
gone.  The watcher costs one thread wake-up per period.
"""

import sys
import threading

import rclpy
from rclpy.executors import ExternalShutdownException, ShutdownException, SingleThreadedExecutor

from ..errors import EXIT_CONFIG
from ..runtime.realtime import set_fifo_priority

WATCH_PERIOD = 0.25       # s: the longest a lost shutdown wake-up can delay the exit


def _watch(executor, context, done, period):
    """Wake ``executor`` every ``period`` s once ``context`` is down, until ``done``."""
    while not done.wait(period):
        try:
            if not context.ok():
                executor.wake()     # the wait returns and rclpy sees the shutdown
        except Exception:  # noqa: B902 - e.g. the executor already shut down: nothing to wake
            return


def spin_until_shutdown(executor, context, period=WATCH_PERIOD):
    """
    Run ``executor`` until ``context`` is shut down (e.g. by SIGINT or SIGTERM).

    Raises ``ExternalShutdownException`` when it ends that way, as ``spin()`` does, so
    that a node's ``main()`` handles both alike.  The executor waits without a timeout;
    a watcher thread wakes it within ``period`` s of the shutdown (module docstring).
    """
    done = threading.Event()
    watcher = threading.Thread(target=_watch, args=(executor, context, done, period),
                               name='shutdown-watch', daemon=True)
    watcher.start()
    try:
        while context.ok():
            try:
                executor.spin_once()
            except ShutdownException:
                break
            except ExternalShutdownException:
                raise
            except Exception:  # noqa: B902 - e.g. a timer created on a context going down
                if context.ok():
                    raise
                break
    finally:
        done.set()
        watcher.join(timeout=2.0)
    raise ExternalShutdownException()


def use_priority(node):
    """
    Run ``node``'s process threads real-time if its ``thread_priority`` parameter asks.

    Called once the node is built, before it spins: its own threads and the
    middleware's exist by then (and the ones started later inherit the policy), while
    its loading and start-up ran under the normal scheduler.  A refusal (no ``rtprio``
    allowance) is logged and the node runs on under the normal scheduler.
    """
    if not node.has_parameter('thread_priority'):
        return
    priority = node.get_parameter('thread_priority').value
    refused = set_fifo_priority(priority)
    if refused:
        node.get_logger().warning(refused)
    elif priority:
        node.get_logger().info(f'threads under SCHED_FIFO, priority {priority}')


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
        use_priority(node)
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
