"""
One subscription taken in a thread of its own, on a wait set of its own, without an executor.

rclpy's executor builds its wait set from every entity of the nodes it spins on each
wake-up, then takes one message per wake-up, and runs its callback as a task.  For a
node with about twenty entities (``recovery_node``: its services, the parameter
services, timers, guard conditions) that is 0.6-0.8 ms of Python per message.  Three
inputs cannot wait for that:

- ``/joint_states`` at 100-500 Hz (the node): each sample cost the node's executor
  about 0.8 ms, 16 % of a core at 200 Hz, which the engine's process then lacked on a
  busy robot;
- ``/actuator_fault`` (the node): a fault waited behind the executor's other work
  before the table hit that answers it could start;
- ``/gesture_library`` (every client): a library is one message per gesture, and the
  executor took them one wake-up each.  Measured from outside with ``bench latency``
  (Namo's table hits, 2026-12-08, a host three times slower than usual): from the
  middleware's reception of the last gesture to the client's callback, p50 3.1-4.4 ms
  through the client node's executor against 1.1-1.5 ms here.

:class:`TopicListener` subscribes on a helper node that has nothing else (no parameter
services, no ``/rosout``, never spun by an executor), as ``tf2_ros.TransformListener``
takes ``/tf`` on a node of its own.  Its thread waits on a wait set holding that one
subscription and a guard condition (rclpy's own ``wait_for_message`` waits the same
way), and at each wake-up takes every message the subscription holds, in order.
:meth:`TopicListener.stop`, or the context's shutdown, triggers the guard condition:
the thread never polls, so an idle listener costs no CPU.

With a ``period`` the thread takes messages at most once per period: after a wake-up
it waits one period (the steady clock, ended at once by :meth:`~TopicListener.stop`),
and a subscription of depth one (keep last) lets the middleware keep only the newest
sample meanwhile.  The node reads the latest joint state on a 10 Hz tick and at a
fault, so a 500 Hz stream needs no more than that.
"""

import threading
from typing import Callable, Optional

import rclpy
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile

from ..errors import shorten

WAIT_FOREVER = -1       # ns: the wait set's timeout (the guard condition ends a wait)


def _helper_node(parent: Node, topic: str) -> Node:
    """
    Create the helper node of ``parent`` for ``topic``: one subscription and nothing else.

    No parameter, type-description or ``/rosout`` entities, and none of the process's
    ``--ros-args``: a launch file's ``__node:=`` rename is ``parent``'s, and would name
    the helper as ``parent``.
    """
    return rclpy.create_node(
        f'{parent.get_name()}_{topic.strip("/").replace("/", "_")}',
        namespace=parent.get_namespace(), context=parent.context,
        start_parameter_services=False, enable_rosout=False, use_global_arguments=False,
        parameter_overrides=[Parameter('start_type_description_service', value=False)])


class TopicListener:
    """A subscription of ``parent``'s, taken in a thread of its own (see the module)."""

    def __init__(self, parent: Node, msg_type, topic: str, callback: Callable,
                 qos: QoSProfile, raw: bool = False, period: Optional[float] = None,
                 info: bool = False):
        """
        Subscribe ``callback`` to ``topic`` as ``parent`` resolves it (its remappings).

        ``callback(msg)`` runs in the listener's thread, so it must not block; with
        ``info`` it is ``callback(msg, info)``, ``info`` the middleware's MessageInfo
        (``received_timestamp``, ``source_timestamp``, ...).  ``raw`` hands it the
        serialized bytes.  ``period`` (s, None: every message at once) spaces the
        wake-ups (see the module).  An exception of ``callback`` is logged on
        ``parent``'s logger, and the next message is taken.
        """
        self._callback, self._info, self._period = callback, info, period
        self._logger = parent.get_logger()
        self.topic = parent.resolve_topic_name(topic)
        self.node = _helper_node(parent, topic)
        self._sub = self.node.create_subscription(msg_type, self.topic, callback, qos, raw=raw)
        self._guard = GuardCondition(None, None, context=parent.context)
        self._stop = threading.Event()
        parent.context.on_shutdown(self._wake)
        self._thread = threading.Thread(target=self._run, name=f'take {self.node.get_name()}',
                                        daemon=True)
        self._thread.start()

    def _wake(self):
        """End the thread's wait (a call from any thread, or the context's shutdown)."""
        try:
            self._guard.trigger()
        except Exception:  # noqa: B902 - the context is already down: the wait has ended
            pass

    def _run(self):
        """Wait on the subscription alone; take every message it holds; until stop()."""
        context, sub, guard = self.node.context, self._sub.handle, self._guard.handle
        try:
            with context.handle, sub, guard:
                wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, context.handle)
                while not self._stop.is_set() and context.ok():
                    wait_set.clear_entities()
                    wait_set.add_subscription(sub)
                    wait_set.add_guard_condition(guard)
                    wait_set.wait(WAIT_FOREVER)
                    if self._stop.is_set():
                        break
                    self._take_all(sub)
                    if self._period:
                        self._stop.wait(self._period)
        except Exception:  # noqa: B902 - the context or the handles went down under it
            pass

    def _take_all(self, sub):
        """Take and hand on every message the subscription holds, oldest first."""
        while not self._stop.is_set():
            taken = sub.take_message(self._sub.msg_type, self._sub.raw)
            if taken is None:
                return
            try:
                self._callback(*taken) if self._info else self._callback(taken[0])
            except Exception as exc:  # noqa: B902 - one bad message must not end the input
                self._logger.error(f'{self.topic}: {type(exc).__name__}: {shorten(exc)}; '
                                   f'message dropped')

    @property
    def running(self) -> bool:
        """Return True while the listener's thread takes messages."""
        return self._thread.is_alive()

    def stop(self) -> None:
        """Stop the thread (woken from its wait), then destroy the helper node."""
        self._stop.set()
        self._wake()
        self._thread.join(timeout=2.0)
        self.node.destroy_node()
        self._guard.destroy()
