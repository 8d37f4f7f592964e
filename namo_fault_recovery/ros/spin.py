"""
Spin an executor until ROS is shut down, even when the shutdown's wake-up is lost.

rclpy's ``Executor.spin()`` waits without a timeout and relies on the context's
shutdown to trigger a guard condition that wakes it.  When SIGTERM shuts the context
down while the executor is rebuilding its wait set, that guard's handle is already
invalid, rclpy leaves it out of the wait set, and the wait never returns unless a
message happens to arrive (measured: ``namo_sim`` hung on SIGTERM about one stop in
ten once the other nodes had gone quiet).  :func:`spin_until_shutdown` waits in bounded
slices instead, so a lost wake-up costs at most ``period`` seconds.
"""

from rclpy.executors import ExternalShutdownException, ShutdownException

DEFAULT_PERIOD = 0.5      # s: the longest a lost shutdown wake-up can delay the exit


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
