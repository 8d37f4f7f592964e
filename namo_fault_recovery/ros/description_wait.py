"""
The node's URDF from the ``robot_description`` topic, when neither a file nor a parameter gives it.

A recovery profile without a ``urdf`` key, and no ``robot_description`` parameter: the
URDF comes from the topic that ``robot_state_publisher`` publishes (``std_msgs/String``,
reliable, transient local, depth 1; ``robot_description`` in the node's namespace, so
``/robot_description`` at the root).  :func:`wait_for_description` runs while the node is
being built, before any of its parts exist: it spins the node alone in an executor of
its own, says on ``/diagnostics`` (a WARN status ``robot_description``, every
``diagnostics_period_sec``) and in the log what it waits for, and returns the document.
The subscription's callback only keeps the text; the URDF is parsed, the robot built and
the engine started afterwards by the node's constructor, as at any start-up.  A signal
(SIGINT, SIGTERM) while waiting ends it: a clean exit.
"""

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from .diagnostics import status, status_prefix
from .parameters import StartupError

TOPIC = 'robot_description'
STATUS = 'robot_description'          # the /diagnostics status name (after the node prefix)
# As robot_state_publisher publishes it: a late joiner still gets the last one.
QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                 reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
POLL = 0.1                            # s: the wait checks for a signal this often


def wait_for_description(node, profile, period):
    """
    Spin ``node`` alone until the ``robot_description`` topic delivers; return the text.

    ``profile`` (the robot_profile path) is named in the status; ``period`` (s) is how
    often the WARN status is published.  Raises StartupError if ROS shuts down first.
    """
    got = []
    group = MutuallyExclusiveCallbackGroup()
    sub = node.create_subscription(String, TOPIC, lambda msg: got.append(msg.data), QOS,
                                   callback_group=group)
    pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
    prefix = status_prefix(node.get_fully_qualified_name())
    topic = sub.topic_name                      # resolved in the node's namespace
    text = (f'waiting for the URDF on {topic} (std_msgs/String, transient local, '
            f'as robot_state_publisher publishes it): robot_profile {profile} names none')

    def say():
        msg = DiagnosticArray(status=[status(prefix, STATUS, 'WARN', text, profile, [
            ('topic', topic), ('robot_profile', profile)])])
        msg.header.stamp = node.get_clock().now().to_msg()
        pub.publish(msg)

    timer = node.create_timer(period, say, callback_group=group,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
    node.get_logger().info(text)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        say()
        while not got and node.context.ok():
            executor.spin_once(timeout_sec=POLL)
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_timer(timer)
        node.destroy_subscription(sub)
        node.destroy_publisher(pub)
    if not got:
        raise StartupError(f'start-up ended while waiting for {topic}')
    node.get_logger().info(f'robot_description received on {topic} '
                           f'({len(got[-1])} characters)')
    return got[-1]
