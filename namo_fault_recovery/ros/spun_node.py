"""
An rclpy node in a ROS context of its own, spun by one background thread.

The typed client, the benchmarks and the demos each talk to a running node from a
process that has other work to do: they need their own context (their own domain id,
shut down without touching anyone else's), one ``SingleThreadedExecutor`` spun in a
daemon thread, and a :meth:`SpunNode.close` that ends all three in the right order.
One definition here, instead of one per caller::

    spun = SpunNode('my_probe', domain_id=7)
    spun.node.create_subscription(...)       # create the entities first,
    spun.start()                             # then spin
    ...
    spun.close()

The node is rclpy's full node, parameter services included.  Made lean (as the
helper of :mod:`.topic_listener` is), the player-on-simulator test's carry-on failed 4
times in 25 runs (the reconfigured library came 0.95 s late, and the blend then met the
torso), against 0 in 28 with full nodes; the cause was not found.
"""

import threading
import time


class SpunNode:
    """An rclpy node, its own context and the thread that spins it."""

    def __init__(self, name, domain_id=None, namespace=None):
        """Create the context and the node (not spinning yet: see :meth:`start`)."""
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self._rclpy = rclpy
        self.context = Context()
        # args=[]: the caller's command line is its own (e.g. namo-recovery's
        # '--node-param x:=y' would otherwise be read as a ROS remap rule).
        rclpy.init(args=[], context=self.context, domain_id=domain_id)
        try:
            self.node = rclpy.create_node(name, namespace=namespace, context=self.context)
        except Exception:
            rclpy.try_shutdown(context=self.context)
            raise
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = None

    def start(self):
        """Start spinning in a daemon thread (once the node's entities exist)."""
        self._thread = threading.Thread(target=self._spin, name=f'spin {self.node.get_name()}',
                                        daemon=True)
        self._thread.start()

    def _spin(self):
        try:
            self.executor.spin()
        except Exception:  # noqa: B902 - the context is shut down by close()
            pass

    def close(self):
        """Stop spinning, destroy the node and shut the context down."""
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)
        if self._thread is not None:
            self._thread.join(timeout=5.0)


class SpunClient:
    """
    A client that owns a :class:`SpunNode` (``self._spun``): ``close()`` and ``with``.

    The base of :class:`.client.RecoveryClient` and :class:`.player_client.PlayerClient`.
    """

    def close(self) -> None:
        """Stop spinning and shut the client's context down."""
        self._spun.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def wait_until(predicate, timeout, period=0.02, lock=None):
    """
    Return ``predicate()`` once truthy (called under ``lock`` if given), or None.

    How a caller of a spun node waits for what the node's callbacks record: polled every
    ``period`` s for at most ``timeout`` s.
    """
    end = time.monotonic() + timeout
    while True:
        if lock is None:
            value = predicate()
        else:
            with lock:
                value = predicate()
        if value:
            return value
        if time.monotonic() >= end:
            return None
        time.sleep(period)


def wait_on(condition, predicate, timeout, period=0.05):
    """
    Return ``predicate()`` once truthy, or None after ``timeout`` s.

    ``predicate`` is called holding ``condition`` (a ``threading.Condition`` that the
    callbacks notify), woken by each notification or every ``period`` s.
    """
    end = time.monotonic() + timeout
    with condition:
        while True:
            value = predicate()
            if value:
                return value
            remaining = end - time.monotonic()
            if remaining <= 0:
                return None
            condition.wait(min(remaining, period))


def call_service(client, request, timeout):
    """
    Call an rclpy service ``client`` whose node another thread spins; return the response.

    Returns None when no answer came within ``timeout`` s (the request is dropped).
    """
    done = threading.Event()
    future = client.call_async(request)
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        client.remove_pending_request(future)
        return None
    return future.result()
