"""
The words of ``/diagnostics`` and of the Trigger answers, shared by writer and readers.

The node writes its statuses with these names and keys; the client,
:mod:`~namo_fault_recovery.ros.client` (and so every ``namo-recovery`` ROS command),
reads them back.  One definition for both sides means a
renamed key breaks loudly in one place instead of silently in a parser.

Every status name starts with :func:`status_prefix` of the node's fully qualified name,
so that several robots (``__ns:=/robot1``, ``__ns:=/robot2``) can share one domain and
the one global ``/diagnostics`` topic and still be told apart.  Plain Python: no ROS
import, so the numerical core and its tests can use it too.
"""

import re

NODE_NAME = 'recovery_node'

# --- status names (after the prefix) -------------------------------------------------

FAULTS = 'faults'
JOINT_STATUS = 'joint '             # + joint name: one status per failed joint
ARM_STATUS = 'arm '                 # + side: one status per frozen arm
RECONFIGURATION = 'reconfiguration'
INPUTS = 'inputs'
STATE = 'state'
CONTINGENCY_TABLE = 'contingency_table'

# --- keys of 'faults' ----------------------------------------------------------------

FAULT_VERSION = 'fault_version'
FAILED_JOINTS = 'failed_joints'     # space-separated joint names
LOCK_STRATEGY = 'lock_strategy'

# --- keys of 'joint <j>' and 'arm <side>' ----------------------------------------------

JOINT = 'joint'
ARM = 'arm'
INDEX = 'index'                     # 1-based joint number within its arm
LOCK_ANGLE_RAD = 'lock_angle_rad'   # repr() of the float; '' while pending without angle
LOCK_ANGLE_DEG = 'lock_angle_deg'
LOCK_SOURCE = 'lock_source'         # 'fault report', '<strategy> strategy' or 'pending'
LOCK_SOURCE_REPORT = 'fault report'
LOCK_SOURCE_PENDING = 'pending'
FROZEN = 'frozen'

# --- keys of 'reconfiguration' ---------------------------------------------------------

LIBRARY_VERSION = 'library_version'
LIBRARY_STAMP = 'library_stamp'     # format_stamp() of the published header stamp
LIBRARY_ORIGIN = 'library_origin'   # LibraryResult.origin: reference, deadline, table, ...
GESTURES = 'gestures'               # the version's gesture names, space-separated, in order
CORRECTIONS = 'corrections'         # arms searched on their measured model (corrections)
UP_TO_DATE = 'up_to_date'
RUNNING = 'running'
OPTIMIZER = 'optimizer'
OPTIMIZER_PRESET = 'optimizer_preset'
DEADLINE_SEC = 'deadline_sec'
WALL_TIME_SEC = 'wall_time_sec'
REQUEST_TO_PUBLISH_SEC = 'request_to_publish_sec'   # the span the deadline covers
# The node's own share, last library: result in hand (engine answer received, table hit)
# -> last gesture message published; it includes waiting for a fault set still syncing.
PUBLISH_PATH_SEC = 'publish_path_sec'
# Last fault batch: first report received -> run requested (the engine may start).
FAULT_TO_REQUEST_SEC = 'fault_to_request_sec'
# Last fault batch: the synced write of the fault set (overlaps the engine run).
FAULT_SYNC_SEC = 'fault_sync_sec'
# Last fault batch: first report received -> last gesture of its library published (the
# node's whole share of a table hit; an outside client adds the transport both ways).
FAULT_TO_PUBLISH_SEC = 'fault_to_publish_sec'
DEADLINE_MET = 'deadline_met'
# A refined library: s from the refinement's start (its deadline result) to this version.
REFINED_AFTER_SEC = 'refined_after_sec'
SUCCESS = 'success'
FROZEN_ARMS = 'frozen_arms'         # space-separated sides
SHARED_JOINTS = 'shared_joints'      # the trailing joint_names both arms hang from (a torso)
SEED = 'seed'
TOOL_LENGTH_MM = 'tool_length_mm'
TOOL_ARM = 'tool_arm'

# Per gesture: '<gesture>.<field>' (see gesture_key).
SCORE_BEFORE = 'score_before'
SCORE_AFTER = 'score_after'
TIME_SEC = 'time_sec'
STATUS = 'status'
STAGE = 'stage'
METHOD = 'method'
TYPICAL_POINTS = 'typical_points'
TIP_ERROR_MM = 'tip_error_mm'
MAX_JUMP_DEG = 'max_jump_deg'
COLLIDES = 'collides'
COLLIDING_PAIRS = 'colliding_pairs'  # space-separated
RIGHT_JOINTS = 'right_joints'        # the right arm's columns in the gesture's joint_names
GESTURE_FIELDS = (SCORE_BEFORE, SCORE_AFTER, TIME_SEC, STATUS, STAGE, METHOD,
                  TYPICAL_POINTS, TIP_ERROR_MM, MAX_JUMP_DEG, COLLIDES, COLLIDING_PAIRS,
                  RIGHT_JOINTS)

# --- keys of 'inputs' and 'state' -------------------------------------------------------

REJECTED_TOTAL = 'rejected_total'
JOINT_STATES_RECEIVED = 'joint_states_received'
MEASURED_JOINTS = 'measured_joints'
LAST_REJECTED_SOURCE = 'last_rejected_source'
LAST_REJECTED_REASON = 'last_rejected_reason'
STATE_FILE = 'state_file'
ENGINE_RESTARTS = 'engine_restarts'
WAITING_CALLERS = 'waiting_callers'

# --- keys of 'contingency_table' -------------------------------------------------------

TABLE_STATE = 'table_state'         # off, loading, building, complete
TABLE_ENTRIES = 'table_entries'     # fault sets in the table, served at once
TABLE_MISSING = 'table_missing'     # fault sets of the plan still being built
TABLE_OFF = 'off'
TABLE_LOADING = 'loading'
TABLE_BUILDING = 'building'
TABLE_COMPLETE = 'complete'

TRUE = 'true'
FALSE = 'false'


def status_prefix(node_fqn):
    """
    Return the status-name prefix of the node ``node_fqn`` (its fully qualified name).

    ``'/recovery_node'`` gives ``'recovery_node: '`` (the name ``diagnostic_aggregator``
    users already know) and ``'/robot1/recovery_node'`` gives
    ``'robot1/recovery_node: '``: the namespace is part of the name, so two robots'
    statuses on the shared ``/diagnostics`` never mix.
    """
    return node_fqn.lstrip('/') + ': '


def node_fqn(namespace='/', name=NODE_NAME):
    """Return the fully qualified name of node ``name`` in ``namespace`` ('' = root)."""
    namespace = namespace.strip('/')
    return f'/{namespace}/{name}' if namespace else f'/{name}'


def joint_status(joint):
    """Return the status name of a failed joint."""
    return JOINT_STATUS + joint


def arm_status(side):
    """Return the status name of a frozen arm."""
    return ARM_STATUS + side


def gesture_key(gesture, field):
    """Return the 'reconfiguration' key of one gesture's ``field``, e.g. 'wai.score_after'."""
    return f'{gesture}.{field}'


def note_key(index):
    """Return the key of the ``index``-th engine note of 'reconfiguration'."""
    return f'note[{index}]'


def rejected_key(index):
    """Return the key of the ``index``-th (newest first) rejected input of 'inputs'."""
    return f'rejected[{index}]'


def flag(value):
    """Return a boolean as the diagnostics write it ('true' / 'false')."""
    return TRUE if value else FALSE


def format_stamp(stamp_ns):
    """Return a header stamp (integer nanoseconds) as 'SEC.NANOSEC' (9 digits)."""
    return f'{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d}'


def parse_stamp(text):
    """Return the nanoseconds of a format_stamp() text, or None if it is not one."""
    match = re.fullmatch(r'(\d+)\.(\d{9})', text or '')
    if match is None:
        return None
    return int(match.group(1)) * 1_000_000_000 + int(match.group(2))


# --- the version tag that ends a successful /reconfigure_gestures answer ----------------

_VERSION_TAG = re.compile(r'\[library version (\d+), stamp (\d+\.\d{9})\]\s*$')


def version_tag(version, stamp_ns):
    """Return the tag the node appends to a /reconfigure_gestures answer."""
    return f'[{version_text(version, stamp_ns)}]'


def version_text(version, stamp_ns):
    """Return the words of :func:`version_tag`, without the brackets."""
    return f'library version {version}, stamp {format_stamp(stamp_ns)}'


def parse_version_tag(message):
    """Return ``(library version, stamp ns)`` from an answer's tag, or ``(None, None)``."""
    match = _VERSION_TAG.search(message or '')
    if match is None:
        return None, None
    return int(match.group(1)), parse_stamp(match.group(2))
