"""
The gesture player's watch for a structure change (:mod:`..playback.deviation` on ROS).

It declares the player's ``structure_*`` and ``on_structure_change`` parameters, reads
the fingertip tracker (``<tracker_topic>/<side>``, ``msg_docs/fingertip_tracker.md``)
and the stamped ``/joint_states``, and during each play feeds them to a
:class:`~..playback.deviation.DeviationWatch`.  A suspicion is published:

- on ``/diagnostics``: ``gesture_player: structure change`` (WARN), message
  ``structure change suspected: right arm 49.8 mm off its designed path``, values
  ``arm``, ``error_mm``, ``unexplained_mm``, ``gesture``, ``play_time_sec``,
  ``on_structure_change``;
- on ``/structure_change`` (diagnostic_msgs/DiagnosticStatus, reliable, transient local,
  depth 10), the same status, with ``adapt`` = ``true`` when ``on_structure_change`` is
  ``adapt``: the player's exploration (:mod:`.exploration`, told through ``on_notice``)
  then adapts that arm on its own once the play has ended; with ``report``
  (``adapt`` = ``false``) it waits for ``~/explore``.
"""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from .fingertip_topics import measurement, topic, TRACKER_QOS, TRACKER_TOPIC
from ..playback.deviation import DeviationThresholds, DeviationWatch

STATUS_NAME = 'gesture_player: structure change'
MODES = ('report', 'adapt')


def _declare(node, name, default, text):
    return node.declare_parameter(name, default, ParameterDescriptor(
        description=text, read_only=True)).value


class StructureWatch:
    """Attached to the player node: ``start`` a play's watch, ``stop`` it at its end."""

    def __init__(self, node, robot, callback_group=None):
        self.node, self.robot = node, robot
        self.mode = _declare(node, 'on_structure_change', 'report', "'report': say it and "
                             "wait to be asked to adapt; 'adapt': ask for an adaptation")
        if self.mode not in MODES:
            raise ValueError(f'on_structure_change: {self.mode!r}; expected one of '
                             f'{", ".join(MODES)}')
        self.thresholds = DeviationThresholds(
            threshold_mm=_declare(node, 'structure_threshold_mm', 10.0, 'fingertip '
                                  'deviation (mm) beyond which a sample deviates'),
            sustain_s=_declare(node, 'structure_sustain_sec', 0.5, 'capture time (s) over '
                               'which most samples must deviate'),
            lag_s=_declare(node, 'structure_lag_sec', 0.1, 'designed path (s) a fingertip '
                           'may lag behind'))
        prefix = _declare(node, 'tracker_topic', TRACKER_TOPIC, 'prefix of the fingertip '
                          'tracker topics <prefix>/<side> (empty: no watch)')
        self.watch, self.gesture = None, None
        self.suspicions = []
        self.on_notice = None          # on_notice(gesture, side, adapt): the exploration's
        if not prefix:
            return
        for side in robot.arms:
            node.create_subscription(
                PointStamped, topic(prefix, side),
                lambda msg, s=side: self._on_fingertip(s, msg), TRACKER_QOS,
                callback_group=callback_group)
        states = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        node.create_subscription(JointState, '/joint_states', self._on_joint_states, states,
                                 callback_group=callback_group)
        latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._diag_pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._change_pub = node.create_publisher(DiagnosticStatus, '/structure_change',
                                                 latched)

    def _now(self):
        return self.node.get_clock().now().nanoseconds * 1e-9

    def start(self, gesture, plan, keyframe_span=None, played=None):
        """
        Watch a play whose motion starts now.

        ``keyframe_span`` (s, the gesture's keyframes from first to last): only its end of
        the plan is watched, not the approach before it (None: all of it).  An explored
        version is watched against the designed path so: its approach, from wherever the
        last trial left the arm, has no designed counterpart.  ``played``: the motion sent
        to the controllers, if not ``plan`` (an explored version, timed as ``plan``).
        """
        if hasattr(self, '_diag_pub'):
            begin = 0.0 if keyframe_span is None else max(plan.duration - keyframe_span, 0.0)
            self.watch = DeviationWatch(self.robot, plan, self._now(), self.thresholds, begin,
                                        played)
            self.gesture = gesture

    def stop(self):
        """End the watch of the current play (a sample after it is ignored)."""
        self.watch = None

    def _on_joint_states(self, msg):
        if self.watch is not None:
            stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            self.watch.joint_state(stamp or self._now(), msg.name, msg.position)

    def _on_fingertip(self, side, msg):
        if self.watch is None:
            return
        stamp, point = measurement(msg)
        found = self.watch.fingertip(side, stamp, point)
        if found is not None:
            self._publish(found)

    def _publish(self, found):
        adapt = self.mode == 'adapt'
        values = {'arm': found.side, 'error_mm': f'{found.error_mm:.1f}',
                  'unexplained_mm': f'{found.unexplained_mm:.1f}', 'gesture': self.gesture,
                  'play_time_sec': f'{found.play_time:.2f}', 'on_structure_change': self.mode,
                  'adapt': str(adapt).lower()}
        status = DiagnosticStatus(level=DiagnosticStatus.WARN, name=STATUS_NAME,
                                  message=f'structure change suspected: {found.describe()}',
                                  hardware_id=self.robot.name,
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        self.suspicions.append(found)
        if self.on_notice is not None:
            self.on_notice(self.gesture, found.side, adapt)
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self._diag_pub.publish(msg)
        self._change_pub.publish(status)
        self.node.get_logger().warning(
            f'{self.gesture}: {status.message} (unexplained by the model: '
            f'{found.unexplained_mm:.1f} mm); '
            + ('adaptation requested on /structure_change' if adapt else
               'waiting to be asked to adapt'))
