"""
The node's side of the exploration on the robot: adopt what the gesture player measured.

The gesture player explores a motion with real trials and the fingertip tracker and
publishes, latched, the explored motion (``explored_topic``,
``/gesture_player/explored_motions``: a ``JointTrajectory`` as ``/gesture_library``
carries a gesture, stamped with the library version it was explored from) and the
structural correction it fitted for that arm (``structure_correction``, a
``diagnostic_msgs/DiagnosticStatus``: ``arm``, ``gesture``, ``library_stamp``,
``groups``, ``params``, ``measured_errors_mm``, ``unadapted_errors_mm``, ``trials``,
``method``, ``profile``).
When the two of one exploration are in, :class:`ExploredIntake` adopts them in a worker
thread of its own (compiling the corrected chain reads the profile's URDF: never in a
callback):

- the correction is compiled on ``profile_file``'s nominal chain (the node's own
  profile when it runs on ``robot_profile`` and ``profile_file`` is empty), checked to be the
  robot's own arm, and handed to the run book: every later run (a fault on that arm
  included) searches on the corrected model;
- the explored motion becomes a library version, origin ``explored``, scored by the
  measured error (:mod:`..runtime.explored_version`), published on ``/gesture_library``
  when it still adapts the current version (else a run on the corrected model is
  requested);
- both are persisted in the state file: a restarted node restores the correction and
  republishes the explored version.
"""

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from trajectory_msgs.msg import JointTrajectory

from .messages import stamp_key, trajectory_angles
from ..errors import ConfigError, shorten
from ..model.structure import ArmCorrection, check_matches, learned_arms
from ..resources import config_path, NAMO_PROFILE_FILE
from ..runtime.explored_version import explored_library
from ..runtime.latest_worker import LatestWorker
from ..runtime.restore import check_result

CORRECTION_TOPIC = 'structure_correction'
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def parse_correction(status: DiagnosticStatus) -> ArmCorrection:
    """Return the ArmCorrection of a ``structure_correction`` status (ValueError if bad)."""
    values = {kv.key: kv.value for kv in status.values}
    try:
        groups = tuple(values.get('groups', '').split())
        params = tuple(tuple(float(v) for v in part.split())
                       for part in values.get('params', '').split(';') if part.strip())
        return ArmCorrection(
            values['arm'], groups, params, values.get('gesture', ''),
            int(values.get('library_stamp', '0') or 0),
            tuple(float(e) for e in values.get('measured_errors_mm', '').split()),
            int(values.get('trials', '0') or 0), values.get('method', ''),
            values.get('profile', ''),
            tuple(float(e) for e in values.get('unadapted_errors_mm', '').split()))
    except KeyError as exc:
        raise ValueError(f'structure_correction: missing key {exc.args[0]!r}') from None


class ExploredIntake:
    """Pairs the player's corrections with its explored motions; adopts them off callbacks."""

    def __init__(self, node, models, book, state, publish, log, profile_file, topic):
        self._robot, self._library = models              # the node's robot and library
        self._book, self._state = book, state
        self._publish, self._log = publish, log          # log(level, text)
        # profile_file: a path, or the robot's own RobotProfile (a node on robot_profile).
        self._profile = None if isinstance(profile_file, str) else profile_file
        self._profile_file = (getattr(self._profile, 'source', None) or profile_file
                              or str(config_path(NAMO_PROFILE_FILE)))
        self._motions = {}               # (gesture, stamp ns) -> JointTrajectory
        self._corrections = {}           # side -> ArmCorrection, newest received
        self._adopted = set()            # (side, gesture, stamp) already taken
        self._worker = LatestWorker(self._adopt, 0.0, name='explored-intake')
        if topic:
            group = MutuallyExclusiveCallbackGroup()
            node.create_subscription(DiagnosticStatus, CORRECTION_TOPIC, self._on_correction,
                                     LATCHED, callback_group=group)
            node.create_subscription(JointTrajectory, topic, self._on_motion,
                                     QoSProfile(depth=100, reliability=LATCHED.reliability,
                                                durability=LATCHED.durability),
                                     callback_group=group)

    def start(self):
        """Start the worker thread."""
        self._worker.start()

    def stop(self):
        """Stop the worker thread."""
        self._worker.stop()

    def learned(self, corrections):
        """Return the LearnedArm of each ArmCorrection, checked against the robot."""
        profile = self._load_profile()
        for correction in corrections:
            check_matches(self._robot, profile, correction.side)
        return learned_arms(profile, corrections)

    def _load_profile(self):
        if self._profile is None:
            from ..model.robot_profile import load_profile
            try:
                self._profile = load_profile(self._profile_file)
            except (ConfigError, FileNotFoundError) as exc:
                raise ValueError(f'profile_file: {" ".join(str(exc).split())}') from None
        return self._profile

    # --- callbacks (never wait) ---------------------------------------------------

    def _on_correction(self, msg):
        try:
            correction = parse_correction(msg)
        except ValueError as exc:
            self._log('warning', f'structure_correction refused: {shorten(exc)}')
            return
        self._corrections[correction.side] = correction
        self._pair()

    def _on_motion(self, msg):
        self._motions[(msg.header.frame_id, stamp_key(msg.header.stamp))] = msg
        self._pair()

    def _pair(self):
        for side, correction in self._corrections.items():
            key = (correction.gesture, correction.library_stamp)
            if key in self._motions and (side,) + key not in self._adopted:
                self._adopted.add((side,) + key)
                self._worker.submit(correction, self._motions[key])

    # --- the worker ---------------------------------------------------------------

    def _adopt(self, correction, msg):
        """Compile, check, persist and publish one exploration's outcome (worker thread)."""
        try:
            current = {a.correction.side: a for a in self._book.learned}
            current[correction.side] = self.learned([correction])[0]
            learned = tuple(current.values())
            result = self._explored(correction, msg)
        except (ValueError, KeyError) as exc:
            self._log('warning', f'explored {correction.gesture} ({correction.side} arm) '
                                 f'not adopted: {shorten(exc)}')
            return
        published = self._state.adopt(learned, result, self._publish)
        self._log('info', f'adopted the {correction.side} arm as measured on '
                          f'{correction.gesture}: {correction.describe()} (measured '
                          f'{correction.measured_mean_mm:.2f} mm mean, {correction.trials} '
                          'trials); ' + ('published the explored version' if published else
                                         'reconfiguring the library on the corrected model'))

    def _explored(self, correction, msg):
        """Return the explored library version, or None if it no longer adapts the current."""
        current = self._book.current
        if current is None or self._book.stamp_ns != correction.library_stamp:
            return None
        q, times = trajectory_angles(msg, self._robot.joint_names)
        result = explored_library(self._robot, current, correction.gesture, times, q,
                                  correction)
        problem = check_result(self._robot, self._library, result, self._book.faults)
        if problem:
            raise ValueError(problem)
        return result
