"""
What the node knows of its inputs: the latest joint state, the measured angles, rejections.

Joint states arrive at 100-500 Hz.  :meth:`InputMonitor.joint_state` only keeps the latest
serialized sample (O(1), no parsing on the executor); :meth:`InputMonitor.measured`
deserializes and validates it when the angles are needed (a fault report, the 10 Hz
tick).  Rejected inputs are counted and the last few kept, each reason truncated, so that
memory and ``/diagnostics`` stay bounded under any stream of bad input; the log gets at
most one line per kind of input (its topic) and second, which counts the ones held back
(:class:`~..runtime.log_throttle.LogThrottle`), while ``rejected_total`` counts them all.
"""

from collections import deque
import threading
import time

from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from ..errors import shorten
from ..runtime.inputs import BadInput, parse_joint_state
from ..runtime.log_throttle import DEFAULT_PERIOD, LogThrottle

MAX_REJECTIONS_SHOWN = 10
MAX_REASON = 300


class InputMonitor:
    """Latest joint state, measured angles and rejected inputs (thread-safe)."""

    def __init__(self, robot, on_reject, on_sample=lambda: None, log_period=DEFAULT_PERIOD):
        self._robot = robot
        # on_reject(line): log ``line``, the rate-limited text (None: held back, counted)
        self._on_reject = on_reject
        self._on_sample = on_sample        # on_sample(): a sample waits to be parsed
        self._log = LogThrottle(log_period)
        self._lock = threading.Lock()
        self._raw = None
        self._measured = {}
        self.rejections = deque(maxlen=MAX_REJECTIONS_SHOWN)
        self.rejected_total = 0
        self.states_received = 0
        self.last_accepted = 0.0

    def joint_state(self, raw):
        """Keep the latest serialized ``/joint_states`` sample (the subscription's callback)."""
        self._raw = raw
        self.states_received += 1
        self._on_sample()

    def pending_state(self):
        """Return True if a joint state arrived since the last :meth:`measured`."""
        return self._raw is not None

    def measured(self):
        """Parse the latest joint state (if new); return the measured angles (joint -> rad)."""
        raw, self._raw = self._raw, None
        if raw is not None:
            try:
                msg = deserialize_message(raw, JointState)
                angles = parse_joint_state(self._robot, msg.name, msg.position)
            except BadInput as exc:
                self.reject('/joint_states', str(exc))
            except Exception as exc:  # noqa: B902 - a malformed sample is just rejected
                self.reject('/joint_states', f'cannot deserialize it: {exc}')
            else:
                with self._lock:
                    self._measured.update(angles)
        with self._lock:
            return dict(self._measured)

    def measured_joints(self):
        """Return the joints with a measured angle, sorted."""
        with self._lock:
            return tuple(sorted(self._measured))

    def reject(self, source, reason):
        """Count and keep a rejected input (its reason truncated), and report it."""
        reason = shorten(reason, MAX_REASON)
        with self._lock:
            self.rejected_total += 1
            self.rejections.append((time.time(), source, reason))
        self._on_reject(self._log.admit(source, f'rejected {source}: {reason}; previous '
                                                f'state kept'))

    def log_pending(self):
        """Return True while rejections are held back, for a later line to report."""
        return self._log.pending() > 0

    def flush_log(self):
        """Report the rejections held back whose period is over (call it periodically)."""
        for line in self._log.flush():
            self._on_reject(line)

    def accepted(self):
        """Record that an input was accepted: older rejections are no longer recent."""
        self.last_accepted = time.time()
