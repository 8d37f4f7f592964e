"""
``/joint_states`` taken on a node and executor of their own, in a thread of their own.

A robot streams ``/joint_states`` at 100-500 Hz.  rclpy's executor builds its wait set
from every entity of the nodes it spins on each wake-up, and ``recovery_node`` has about
twenty (its services, the parameter services, timers, guard conditions): each sample
cost the node's executor about 0.8 ms of Python, 16 % of a core at 200 Hz, which the
engine's process then lacked on a busy robot, and a fault report arriving meanwhile
waited for it.  :class:`StateListener` takes the stream on a helper node that has
nothing else (no parameter services, no ``/rosout``), spun by its own executor, as
``tf2_ros.TransformListener`` takes ``/tf``; the callback is the same O(1) keep-the-latest.

With a ``period``, the thread takes at most one sample per period: after a sample it
waits one period, and the subscription's depth of one (keep last) lets the middleware
keep only the newest sample meanwhile.  The node reads the latest sample on a 10 Hz
tick and at a fault, so a 500 Hz stream needs no more than that; each sample taken
still costs the process's interpreter about half a millisecond.
"""

import threading
from typing import Callable, Optional

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile


def _helper_node(parent: Node, topic: str) -> Node:
    """
    Create the helper node of ``parent`` for ``topic``: one subscription and nothing else.

    No parameter, type-description or ``/rosout`` entities (its executor waits on its
    subscription alone), and none of the process's ``--ros-args``: a launch file's
    ``__node:=`` rename is ``parent``'s, and would name the helper as ``parent``.
    """
    return rclpy.create_node(
        f'{parent.get_name()}_{topic.strip("/").replace("/", "_")}',
        namespace=parent.get_namespace(), context=parent.context,
        start_parameter_services=False, enable_rosout=False, use_global_arguments=False,
        parameter_overrides=[Parameter('start_type_description_service', value=False)])


class StateListener:
    """A subscription of ``parent``'s, spun apart from ``parent``'s executor."""

    def __init__(self, parent: Node, msg_type, topic: str, callback: Callable,
                 qos: QoSProfile, raw: bool = False, period: Optional[float] = None):
        """
        Subscribe ``callback`` to ``topic`` as ``parent`` resolves it (its remappings).

        The helper ignores the process's own arguments: a launch file's ``__node:=``
        rename would otherwise name it as ``parent``, and the topic comes resolved.
        ``period`` (s, None: every sample) spaces the samples taken (see the module).
        """
        self._period = period
        self.topic = parent.resolve_topic_name(topic)
        self.node = _helper_node(parent, topic)
        self.node.create_subscription(msg_type, self.topic, callback, qos, raw=raw)
        self._executor = SingleThreadedExecutor(context=parent.context)
        self._executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name=f'spin {self.node.get_name()}',
                                        daemon=True)
        self._thread.start()

    def _spin(self):
        """Spin until :meth:`stop` (its shutdown wakes the wait) or the context goes down."""
        try:
            while not self._stop.is_set() and self.node.context.ok():
                self._executor.spin_once()
                if self._period:
                    # A wait on the steady clock (use_sim_time does not apply), ended
                    # at once by stop().
                    self._stop.wait(self._period)
        except Exception:  # noqa: B902 - the executor or context shut down under it
            pass

    def stop(self) -> None:
        """Stop the thread (woken from its wait), then the executor and the helper node."""
        self._stop.set()
        try:
            self._executor.wake()
        except Exception:  # noqa: B902 - the context is already down: the wait has ended
            pass
        self._thread.join(timeout=2.0)
        self._executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
