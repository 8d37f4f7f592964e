"""
A client of a running ``gesture_player``: its play services and what the arms did.

:class:`PlayerClient` is to ``gesture_player`` what :class:`.client.RecoveryClient` is
to ``recovery_node``: an rclpy node in a context of its own (:class:`.spun_node.
SpunNode`), spun in a background thread, with plain method calls.  ``play`` calls
``<player>/play/<gesture>``; given the arm controllers, it also records the commands
sent to them, ``/joint_states`` and ``/actuator_fault`` (``demo-play``).
"""

import itertools
import os
import threading
import time

from .spun_node import call_service, SpunClient, SpunNode

DEFAULT_PLAYER = '/gesture_player'
_COUNTER = itertools.count()


def _seconds(duration):
    return duration.sec + duration.nanosec * 1e-9


class PlayerClient(SpunClient):
    """A client of the ``gesture_player`` in ``domain_id``; a context manager."""

    def __init__(self, domain_id: int = None, player: str = DEFAULT_PLAYER,
                 controllers: tuple = ()):
        """Start the client; with ``controllers``, record the commands sent to them."""
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory
        self.player = player
        self._spun = SpunNode(f'namo_player_client_{os.getpid()}_{next(_COUNTER)}',
                              domain_id)
        self.node = self._spun.node
        self.lock = threading.Lock()
        self.commands, self.states, self.faults = [], [], []   # (monotonic time, msg)
        for controller in controllers:
            self.node.create_subscription(
                JointTrajectory, f'/{controller}/joint_trajectory',
                lambda msg, c=controller: self._add(self.commands, (c, msg)), 100)
        if controllers:
            self.node.create_subscription(JointState, '/joint_states',
                                          lambda m: self._add(self.states, m), 100)
            self.node.create_subscription(JointState, '/actuator_fault',
                                          lambda m: self._add(self.faults, m), 10)
        self._spun.start()

    def _add(self, where, item):
        with self.lock:
            where.append((time.monotonic(), item))

    def play(self, gesture: str, timeout: float) -> tuple:
        """Call ``<player>/play/<gesture>``; return ``(success, message)``."""
        from std_srvs.srv import Trigger
        service = f'{self.player}/play/{gesture}'
        client = self.node.create_client(Trigger, service)
        try:
            if not client.wait_for_service(timeout_sec=min(timeout, 10.0)):
                return False, f'no service {service}; is gesture_player running?'
            response = call_service(client, Trigger.Request(), timeout)
            if response is None:
                return False, f'no answer within {timeout:g} s'
            return response.success, response.message
        finally:
            self.node.destroy_client(client)

    def latest_state(self) -> dict:
        """Return ``{joint: angle}`` of the newest ``/joint_states`` (empty if none)."""
        with self.lock:
            if not self.states:
                return {}
            msg = self.states[-1][1]
        return dict(zip(msg.name, msg.position))

    def reported_locks(self) -> dict:
        """Return ``{joint: angle}`` of every ``/actuator_fault`` report received."""
        with self.lock:
            faults = list(self.faults)
        return {j: a for _, m in faults for j, a in zip(m.name, m.position)}

    def play_trace(self, since: float) -> tuple:
        """
        Return (commands, measured) as lists of (t, {joint: angle}) after ``since``.

        A controller follows its latest trajectory: the points of one that a newer one
        replaced (the hold after a failed play) end where the newer one arrived.
        """
        commands, measured = [], []
        with self.lock:
            sent = [(t, c, m) for t, (c, m) in self.commands if t >= since]
            states = [(t, m) for t, m in self.states if t >= since]
        for i, (t, controller, msg) in enumerate(sent):
            ends = [t2 for t2, c2, _ in sent[i + 1:] if c2 == controller]
            end = (ends[0] if ends else float('inf')) - since
            for p in msg.points:
                tp = t - since + _seconds(p.time_from_start)
                if tp <= end:
                    commands.append((tp, dict(zip(msg.joint_names, p.positions))))
        for t, msg in states:
            measured.append((t - since, dict(zip(msg.name, msg.position))))
        return sorted(commands, key=lambda c: c[0]), measured
