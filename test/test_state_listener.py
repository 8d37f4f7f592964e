"""
``/joint_states`` on the node's helper node: named after the node, remapped as the node.

The helper ignores the process's ``--ros-args`` (a launch file's ``__node:=`` rename
would name it as the node itself) and subscribes to the topic as the node resolves it,
so a remapping meant for the node (``recovery_node:joint_states:=...``) holds.
"""

from namo_fault_recovery.ros.spun_node import SpunNode, wait_until
from node_harness import NodeProcess, session_domain
import pytest

pytestmark = pytest.mark.slow

DOMAIN = session_domain(1)       # the lifecycle tests': never at the same time


def test_helper_named_after_the_renamed_node_and_remapped_with_it(tmp_path):
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state', args=[
        '-r', '__node:=my_recovery', '-r', '__ns:=/robot1',
        '-r', 'my_recovery:joint_states:=/measured', '-p', 'contingency_table:=false'])
    probe = SpunNode('namo_test_probe', DOMAIN)
    try:
        node.wait_output('engine process started', timeout=120)
        # The graph fills in over discovery: the subscription's DDS endpoint can arrive
        # before the node names (ROS's own discovery topic), which name it when they do:
        # wait for the whole expected picture.
        expected = {('my_recovery', '/robot1'), ('my_recovery_joint_states', '/robot1')}
        seen = {}

        def whole_graph():
            seen['names'] = set(probe.node.get_node_names_and_namespaces())
            seen['subs'] = [i.node_name for i in probe.node.get_subscriptions_info_by_topic(
                '/measured')]
            return expected <= seen['names'] and seen['subs'] == ['my_recovery_joint_states']

        wait_until(whole_graph, 30.0, period=0.2)
        names, subs = seen['names'], seen['subs']
        assert expected <= names, (subs, names)
        assert subs == ['my_recovery_joint_states'], (subs, names)
        assert not probe.node.get_subscriptions_info_by_topic('/robot1/joint_states')
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

    from namo_fault_recovery.ros.state_listener import StateListener
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Int32

    qos = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.BEST_EFFORT)
    parent = SpunNode('namo_test_period_parent', DOMAIN)
    taken = []
    listener = StateListener(parent.node, Int32, 'namo_test_period', taken.append, qos,
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
