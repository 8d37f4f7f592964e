"""
Conversions between the ROS messages of the contract and the numerical core.

Library versions <-> ``trajectory_msgs/JointTrajectory`` (one per gesture), the RViz
skeleton markers, and the ``diagnostic_msgs`` statuses.  Only the node and the ROS
command line import this module; the numerical core stays free of ROS.
"""

from collections import OrderedDict
import math
import struct
import threading

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point
import numpy as np
from rclpy.serialization import serialize_message
from std_msgs.msg import ColorRGBA
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker

from ..model.kinematics import forward_kinematics, shoulder_position, split_arms
from ..model.robot import ARMS
from ..recovery.result import reference_result, summary  # noqa: F401 - re-exported

DIAG_PREFIX = 'recovery_node: '
# A serialized JointTrajectory: the CDR encapsulation (little-endian), then its header's
# stamp (int32 sec, uint32 nanosec) at once.
CDR_LITTLE_ENDIAN = b'\x00\x01\x00\x00'
STAMP_OFFSET = len(CDR_LITTLE_ENDIAN)
_MM = 1e-3


def duration_msg(seconds):
    """Return a builtin_interfaces/Duration for a non-negative time in seconds."""
    sec = int(math.floor(seconds))
    nanosec = int(round((seconds - sec) * 1e9))
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return Duration(sec=sec, nanosec=nanosec)


def duration_seconds(msg):
    """Return a Duration message as float seconds."""
    return msg.sec + msg.nanosec * 1e-9


def library_to_msgs(joint_names, result, stamp):
    """
    Return one JointTrajectory per gesture, all with the same header stamp.

    ``joint_names`` are the arms' joints, then any joints shared by both arms (a torso,
    ``RobotJoints.played_joints``): a shared joint holds the gesture's lean
    (``GestureResult.shared``) at every point, 0 (upright) when it does not lean.
    """
    msgs = []
    for gesture in result.gestures:
        msg = JointTrajectory()
        msg.header.stamp = stamp
        msg.header.frame_id = gesture.name
        names = list(joint_names) + [n for n in gesture.shared if n not in joint_names]
        msg.joint_names = names
        arms = len(gesture.positions[0]) if gesture.positions else len(joint_names)
        lean = [float(gesture.shared.get(n, 0.0)) for n in names[arms:]]
        for t, q in zip(gesture.times, gesture.positions):
            msg.points.append(JointTrajectoryPoint(positions=[float(a) for a in q] + lean,
                                                   time_from_start=duration_msg(t)))
        msgs.append(msg)
    return msgs


class PreparedMessages:
    """
    The messages of library versions serialized in advance: a table hit only publishes.

    :meth:`prepare` (the contingency table's entries, as they join it, in the table's
    own threads) converts and serializes a result's gestures once; :meth:`messages`
    returns them with the header stamp of this publication written into their bytes
    (the stamp leads a JointTrajectory's CDR payload, :data:`STAMP_OFFSET`), matched by
    the very ``gestures`` tuple (a hit is the entry's result with other fields
    replaced), else converts at once (message objects).  Either kind is what
    ``Publisher.publish`` takes.  At most ``limit`` versions are kept, the oldest
    prepared dropped first.
    """

    def __init__(self, joint_names, limit=1024):
        self._joint_names = tuple(joint_names)
        self._limit = limit
        self._lock = threading.Lock()
        self._prepared = OrderedDict()     # id(gestures) -> (gestures, [bytes])

    def prepare(self, result):
        """Serialize ``result``'s gestures now, for a later :meth:`messages` (thread-safe)."""
        raws = [serialize_message(m) for m in library_to_msgs(self._joint_names, result, Time())]
        if any(raw[:STAMP_OFFSET] != CDR_LITTLE_ENDIAN for raw in raws):
            return                         # another encoding: converted when published
        with self._lock:
            self._prepared[id(result.gestures)] = (result.gestures, raws)
            self._prepared.move_to_end(id(result.gestures))
            while len(self._prepared) > self._limit:
                self._prepared.popitem(last=False)

    def messages(self, result, stamp):
        """Return one JointTrajectory (or its serialized bytes) per gesture, stamped."""
        with self._lock:
            found = self._prepared.get(id(result.gestures))
        if found is None or found[0] is not result.gestures:
            return library_to_msgs(self._joint_names, result, stamp)
        out = []
        for raw in found[1]:
            data = bytearray(raw)
            struct.pack_into('<iI', data, STAMP_OFFSET, stamp.sec, stamp.nanosec)
            out.append(bytes(data))
        return out


def stamp_key(stamp):
    """Return a header stamp as an integer number of nanoseconds (a version key)."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def trajectory_angles(msg, joint_names=None):
    """
    Return a JointTrajectory's positions as an array (keyframes, joints) and times.

    With ``joint_names`` the columns are reordered to that order (KeyError if missing).
    """
    q = np.array([list(p.positions) for p in msg.points], dtype=float)
    times = [duration_seconds(p.time_from_start) for p in msg.points]
    if joint_names is not None:
        index = [list(msg.joint_names).index(j) for j in joint_names]
        q = q[:, index]
    return q, times


# --- summaries -----------------------------------------------------------------------


def fmt_angle(rad):
    """Return an angle as 'X.XXXX rad (Y.YY deg)'."""
    return f'{rad:.4f} rad ({math.degrees(rad):.2f} deg)'


# --- markers -------------------------------------------------------------------------

_REF_COLOR = ColorRGBA(r=0.6, g=0.6, b=0.6, a=0.8)
_NEW_COLOR = {'right': ColorRGBA(r=1.0, g=0.45, b=0.0, a=1.0),
              'left': ColorRGBA(r=0.1, g=0.6, b=1.0, a=1.0)}
_AXIS_COLORS = (ColorRGBA(r=1.0, a=1.0), ColorRGBA(g=1.0, a=1.0), ColorRGBA(b=1.0, a=1.0))


def _point(p_mm, offset):
    return Point(x=float(p_mm[0] * _MM + offset[0]), y=float(p_mm[1] * _MM + offset[1]),
                 z=float(p_mm[2] * _MM + offset[2]))


_MAX_FIGURES = 6      # stick figures per gesture; a dense motion shows its path instead
_AXIS_LENGTH = 60.0   # mm


def _figure_frames(n):
    """Return the keyframes drawn as stick figures: all of a short motion, else spread."""
    if n <= _MAX_FIGURES:
        return list(range(n))
    return sorted({int(round(k)) for k in np.linspace(0, n - 1, _MAX_FIGURES)})


def _landmarks(robot, positions, side):
    """Batched forward kinematics of one arm over every keyframe of a gesture."""
    q = split_arms(robot, np.asarray(positions, dtype=float))[ARMS.index(side)]
    return forward_kinematics(robot, q, side)


def _line_strip(base, ident, color, width, label, points_mm, offset):
    """Return one labelled LINE_STRIP marker through ``points_mm`` (mm, robot frame)."""
    strip = Marker(header=base.header, ns=base.ns, id=ident, type=Marker.LINE_STRIP,
                   action=Marker.ADD)
    strip.pose.orientation.w = 1.0
    strip.scale.x = width
    strip.color = color
    strip.text = label
    strip.points = [_point(p, offset) for p in points_mm]
    return strip


def _arm_markers(robot, lm, k, side, offset, base, ident, color, width, label):
    """Return the skeleton line strip and palm-axes line list of one arm at keyframe k."""
    skeleton = _line_strip(base, ident, color, width, label,
                           (shoulder_position(robot, side), lm.elbow[k], lm.wrist[k],
                            lm.tip[k]), offset)
    axes = Marker(header=base.header, ns=base.ns, id=ident + 1, type=Marker.LINE_LIST,
                  action=Marker.ADD)
    axes.pose.orientation.w = 1.0
    axes.scale.x = width * 0.6
    axes.color = color
    for a in range(3):
        axes.points.append(_point(lm.tip[k], offset))
        axes.points.append(_point(lm.tip[k] + _AXIS_LENGTH * lm.palm[k][:, a], offset))
        axes.colors.extend([_AXIS_COLORS[a], _AXIS_COLORS[a]])
    return [skeleton, axes]


def library_markers(robot, reference, current, stamp, frame_id='base_link', spacing=0.8):
    """
    Return the RViz markers comparing the reference and the current library.

    The first marker deletes everything previously shown.  Each gesture has its own
    namespace and sits ``spacing`` metres further along -y than the previous one.  At up
    to six keyframes spread over the motion, each arm gets a grey reference skeleton
    and a coloured reconfigured one (shoulder-elbow-wrist-fingertip, with palm axes at
    the fingertip); a motion of several keyframes also gets the fingertip paths (the
    second paper's Fig. 5-7 view), and each gesture a text label.
    """
    clear = Marker(action=Marker.DELETEALL)
    clear.header.stamp = stamp
    clear.header.frame_id = frame_id
    markers = [clear]
    ref_by_name = {g.name: g for g in reference.gestures}
    # The reconfigured arms are drawn as they are: with the tool, if one is held.
    model = robot.with_tool(current.tool_mm, current.tool_arm)
    for gi, gesture in enumerate(current.gestures):
        ref = ref_by_name.get(gesture.name)
        if ref is not None and len(ref.positions) != len(gesture.positions):
            ref = None
        offset = (0.0, -gi * spacing, 0.0)
        base = Marker()
        base.header.stamp = stamp
        base.header.frame_id = frame_id
        base.ns = gesture.name
        n = len(gesture.positions)
        for ai, side in enumerate(ARMS):
            new = _landmarks(model, gesture.positions, side)
            old = None if ref is None else _landmarks(robot, ref.positions, side)
            for k in _figure_frames(n):
                ident = k * 100 + ai * 10
                if old is not None:
                    markers += _arm_markers(robot, old, k, side, offset, base, ident,
                                            _REF_COLOR, 0.008, 'reference')
                markers += _arm_markers(model, new, k, side, offset, base, ident + 2,
                                        _NEW_COLOR[side], 0.015, 'reconfigured')
            if n > 1:
                ident = 1_000_000 + ai * 10
                if old is not None:
                    markers.append(_line_strip(base, ident, _REF_COLOR, 0.004,
                                               'reference path', old.tip, offset))
                markers.append(_line_strip(base, ident + 1, _NEW_COLOR[side], 0.008,
                                           'reconfigured path', new.tip, offset))
        text = Marker(header=base.header, ns=base.ns, id=99999, type=Marker.TEXT_VIEW_FACING,
                      action=Marker.ADD)
        text.pose.position.y = offset[1]
        text.pose.position.z = 0.35
        text.pose.orientation.w = 1.0
        text.scale.z = 0.06
        text.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
        text.text = (f'{gesture.name}: {gesture.score_before:.1f} -> '
                     f'{gesture.score_after:.1f}' if current.locks else gesture.name)
        markers.append(text)
    return markers


# --- diagnostics ---------------------------------------------------------------------


def key_values(pairs):
    """Return a list of diagnostic KeyValue from (key, value) pairs."""
    return [KeyValue(key=str(k), value=str(v)) for k, v in pairs]


def status(name, level, message, hardware_id, pairs=()):
    """Return one DiagnosticStatus (level is one of OK, WARN, ERROR, STALE)."""
    return DiagnosticStatus(level=getattr(DiagnosticStatus, level), name=DIAG_PREFIX + name,
                            message=message, hardware_id=hardware_id,
                            values=key_values(pairs))


def status_values(status_msg):
    """Return a DiagnosticStatus' key-values as a dict."""
    return {kv.key: kv.value for kv in status_msg.values}
