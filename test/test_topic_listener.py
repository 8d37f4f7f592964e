"""
The node's ``/joint_states`` and ``/actuator_fault``, and a client's library, on listeners.

Each :class:`~namo_fault_recovery.ros.topic_listener.TopicListener` subscribes on a
helper node that ignores the process's ``--ros-args`` (a launch file's ``__node:=``
rename would name it as the node itself) and subscribes to the topic as the node
resolves it, so a remapping meant for the node (``recovery_node:joint_states:=...``)
holds.  Its thread takes every message in order, survives a callback's exception, and
ends on ``stop()`` or on the context's shutdown.
"""

from namo_fault_recovery.ros.spun_node import SpunNode, wait_until
from node_harness import NodeProcess, session_domain
import pytest

pytestmark = pytest.mark.slow

DOMAIN = session_domain(1)       # the lifecycle tests': never at the same time


def test_helper_named_after_the_renamed_node_and_remapped_with_it(tmp_path):
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state', args=[
        '-r', '__node:=my_recovery', '-r', '__ns:=/robot1',
        '-r', 'my_recovery:joint_states:=/measured', '-r', 'my_recovery:actuator_fault:=/faults',
        '-p', 'contingency_table:=false'])
    probe = SpunNode('namo_test_probe', DOMAIN)
    try:
        node.wait_output('engine process started', timeout=120)
        # The graph fills in over discovery: the subscription's DDS endpoint can arrive
        # before the node names (ROS's own discovery topic), which name it when they do:
        # wait for the whole expected picture.
        expected = {('my_recovery', '/robot1'), ('my_recovery_joint_states', '/robot1'),
                    ('my_recovery_actuator_fault', '/robot1')}
        seen = {}

        def whole_graph():
            seen['names'] = set(probe.node.get_node_names_and_namespaces())
            seen['subs'] = [i.node_name for topic in ('/measured', '/faults')
                            for i in probe.node.get_subscriptions_info_by_topic(topic)]
            return expected <= seen['names'] and seen['subs'] == [
                'my_recovery_joint_states', 'my_recovery_actuator_fault']

        wait_until(whole_graph, 30.0, period=0.2)
        names, subs = seen['names'], seen['subs']
        assert expected <= names, (subs, names)
        assert subs == ['my_recovery_joint_states', 'my_recovery_actuator_fault'], (subs, names)
        assert not probe.node.get_subscriptions_info_by_topic('/robot1/joint_states')
        assert not probe.node.get_subscriptions_info_by_topic('/robot1/actuator_fault')
    finally:
        probe.close()
        assert node.stop() == 0, node.describe()


def test_a_period_spaces_the_samples_taken_and_keeps_the_newest():
    """
    With a period, the helper takes at most one sample per period, the newest then.

    A 500 Hz stream cost the node's process 29-34 % of a core taken sample by sample,
    5-8 % at the node's 0.02 s (2026-12-07, 10 s, the bench's stream process).
    """
    import time

    from namo_fault_recovery.ros.topic_listener import TopicListener
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Int32

    qos = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.BEST_EFFORT)
    parent = SpunNode('namo_test_period_parent', DOMAIN)
    taken = []
    listener = TopicListener(parent.node, Int32, 'namo_test_period', taken.append, qos,
                             period=0.05)
    publisher = parent.node.create_publisher(Int32, 'namo_test_period', qos)
    try:
        wait_until(lambda: publisher.get_subscription_count() > 0, 10.0)
        began, sent = time.monotonic(), 0
        while time.monotonic() - began < 1.0:
            sent += 1
            publisher.publish(Int32(data=sent))
            time.sleep(0.002)
        time.sleep(0.2)
    finally:
        listener.stop()
        parent.close()
    assert sent > 200
    assert 5 <= len(taken) <= 1.0 / 0.05 + 3, len(taken)
    assert taken[-1].data >= sent - 0.05 / 0.002 - 5, (taken[-1].data, sent)


def _reliable(depth):
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)


def test_a_burst_is_taken_whole_in_order_with_its_info_in_the_listener_thread():
    """Every message of a burst, oldest first, with the middleware's reception time."""
    import threading

    from namo_fault_recovery.ros.topic_listener import TopicListener
    from std_msgs.msg import Int32

    parent = SpunNode('namo_test_burst_parent', DOMAIN)
    taken = []

    def keep(msg, info):
        taken.append((msg.data, info.get('received_timestamp'),
                      threading.current_thread().name))

    listener = TopicListener(parent.node, Int32, 'namo_test_burst', keep, _reliable(100),
                             info=True)
    publisher = parent.node.create_publisher(Int32, 'namo_test_burst', _reliable(100))
    try:
        wait_until(lambda: publisher.get_subscription_count() > 0, 10.0)
        for k in range(1, 51):
            publisher.publish(Int32(data=k))
        wait_until(lambda: len(taken) >= 50, 10.0)
    finally:
        listener.stop()
        parent.close()
    assert [d for d, _, _ in taken] == list(range(1, 51))
    assert all(stamp and stamp > 0 for _, stamp, _ in taken), taken[:3]
    assert {name for _, _, name in taken} == {'take namo_test_burst_parent_namo_test_burst'}


def test_a_callback_that_raises_drops_that_message_only():
    """A bad message is logged and dropped; the listener takes the next ones."""
    from namo_fault_recovery.ros.topic_listener import TopicListener
    from std_msgs.msg import Int32

    parent = SpunNode('namo_test_raise_parent', DOMAIN)
    taken = []

    def keep(msg):
        if msg.data == 3:
            raise ValueError('three')
        taken.append(msg.data)

    listener = TopicListener(parent.node, Int32, 'namo_test_raise', keep, _reliable(10))
    publisher = parent.node.create_publisher(Int32, 'namo_test_raise', _reliable(10))
    try:
        wait_until(lambda: publisher.get_subscription_count() > 0, 10.0)
        for k in range(1, 6):
            publisher.publish(Int32(data=k))
        wait_until(lambda: len(taken) >= 4, 10.0)
        assert listener.running
    finally:
        listener.stop()
        parent.close()
    assert taken == [1, 2, 4, 5]


def test_stop_and_the_contexts_shutdown_end_the_thread():
    """stop() ends an idle listener's wait at once; so does its context's shutdown."""
    import time

    from namo_fault_recovery.ros.topic_listener import TopicListener
    from std_msgs.msg import Int32

    parent = SpunNode('namo_test_stop_parent', DOMAIN)
    stopped = TopicListener(parent.node, Int32, 'namo_test_stop_a', print, _reliable(1))
    orphan = TopicListener(parent.node, Int32, 'namo_test_stop_b', print, _reliable(1))
    try:
        time.sleep(0.2)
        assert stopped.running and orphan.running
        began = time.monotonic()
        stopped.stop()
        assert not stopped.running
        assert time.monotonic() - began < 1.0
    finally:
        parent.close()          # orphan is never stopped: the shutdown wakes it
    assert wait_until(lambda: not orphan.running, 2.0)
