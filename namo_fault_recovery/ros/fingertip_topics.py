"""
The fingertip tracker's topics (``msg_docs/fingertip_tracker.md``), both ends of them.

``<prefix>/<side>`` (default ``/fingertip_tracker/right`` and ``/left``) carry
``geometry_msgs/PointStamped``: the measured fingertip in the robot's base frame
(``header.frame_id``, the URDF's root link), in metres, ``header.stamp`` = the capture
time; best-effort sensor QoS, as a camera driver publishes.  ``namo_sim`` publishes
them; ``gesture_player`` reads them; a real tracker (AprilTag, mocap) can stand in.
"""

from geometry_msgs.msg import PointStamped
from rclpy.qos import qos_profile_sensor_data

TRACKER_TOPIC = '/fingertip_tracker'
GROUND_TRUTH_TOPIC = '~/ground_truth'      # namo_sim's, for benchmarks only
TRACKER_QOS = qos_profile_sensor_data
_MM = 1e-3


def topic(prefix: str, side: str) -> str:
    """Return the topic of one hand's tracker under ``prefix``."""
    return f'{prefix.rstrip("/")}/{side}'


def point_message(point_mm, stamp: float, frame: str) -> PointStamped:
    """Return a PointStamped in metres of a point in mm, stamped ``stamp`` (s)."""
    msg = PointStamped()
    msg.header.frame_id = frame
    sec = int(stamp // 1)
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = min(int(round((stamp - sec) * 1e9)), 999_999_999)
    msg.point.x, msg.point.y, msg.point.z = (float(v) * _MM for v in point_mm)
    return msg


def measurement(msg: PointStamped) -> tuple:
    """Return (capture stamp in s, (x, y, z) in mm) of a tracker message."""
    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    return stamp, (msg.point.x / _MM, msg.point.y / _MM, msg.point.z / _MM)
