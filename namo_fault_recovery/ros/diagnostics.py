"""
``/diagnostics`` of the node, built from a snapshot of its state.

Free of DDS: :func:`statuses` takes a :class:`Snapshot` (the run book's state, the input
counters, the persistence problems, the settings) and returns the ``DiagnosticStatus``
list that the node publishes.  Every value in it is bounded: rejected inputs are kept
truncated, and only the last few.
"""

from dataclasses import dataclass, field
import math
import time

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from .messages import fmt_angle
from ..model.structure import ArmCorrection
from ..recovery.locks import frozen_arms
from ..recovery.result import summary
from ..runtime import diagnostic_keys as dk

DEFAULT_PREFIX = dk.status_prefix(dk.node_fqn())
status_prefix = dk.status_prefix


def status(prefix, name, level, message, hardware_id, pairs=()):
    """Return one DiagnosticStatus (level is one of OK, WARN, ERROR, STALE)."""
    return DiagnosticStatus(level=getattr(DiagnosticStatus, level), name=prefix + name,
                            message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=str(k), value=str(v)) for k, v in pairs])


@dataclass
class Snapshot:
    """Everything the diagnostics show, copied at one instant."""

    faults: dict
    fault_version: int
    current: object              # LibraryResult published, or None
    version: int
    stamp_ns: int
    pending: bool
    running: bool
    failed: object               # (generation, reason) or None
    settings: object             # the RecoverySettings in use
    rejections: list = field(default_factory=list)   # (wall time, source, reason)
    rejected_total: int = 0
    joint_states_received: int = 0
    measured_joints: tuple = ()
    last_accepted: float = 0.0
    state_problem: str = None
    state_file: str = ''
    engine_restarts: int = 0
    waiting_callers: int = 0
    request_to_publish: float = None
    publish_path: float = None
    fault_to_request: float = None
    fault_sync: float = None
    fault_to_publish: float = None
    table: tuple = (dk.TABLE_OFF, 0, 0)   # the contingency table: (state, entries, missing)


def snapshot(book, inputs, settings, state_problem, state_file, engine_restarts,
             table=(dk.TABLE_OFF, 0, 0)):
    """
    Return a :class:`Snapshot` of a RunBook, an InputMonitor and the node's state.

    ``table`` is the contingency table's ``(state, entries, missing)``
    (:meth:`~..runtime.contingency_keeper.ContingencyKeeper.status`).
    """
    b = book.snapshot()
    return Snapshot(
        faults=b['faults'], fault_version=b['fault_version'], current=b['current'],
        version=b['version'], stamp_ns=b['stamp_ns'], pending=b['pending'],
        running=b['running'], failed=b['failed'], settings=settings,
        rejections=list(inputs.rejections), rejected_total=inputs.rejected_total,
        joint_states_received=inputs.states_received,
        measured_joints=inputs.measured_joints(), last_accepted=inputs.last_accepted,
        state_problem=state_problem, state_file=str(state_file),
        engine_restarts=engine_restarts, waiting_callers=b['waiting_callers'],
        request_to_publish=b['request_to_publish'], publish_path=b['publish_path'],
        fault_to_request=b['fault_to_request'], fault_sync=b['fault_sync'],
        fault_to_publish=b['fault_to_publish'], table=tuple(table))


def statuses(robot, snap, prefix=DEFAULT_PREFIX):
    """Return the node's DiagnosticStatus list for ``snap``."""
    hw = robot.name
    faults, current = snap.faults, snap.current
    strategy = snap.settings.lock_strategy
    up_to_date = current is not None and not snap.pending and set(current.locks) == set(faults)
    out = [status(prefix, dk.FAULTS, 'ERROR' if faults else 'OK',
                  f'{len(faults)} failed joint(s): {", ".join(faults)}' if faults
                  else 'no faults', hw,
                  [(dk.FAULT_VERSION, snap.fault_version), (dk.FAILED_JOINTS, ' '.join(faults)),
                   (dk.LOCK_STRATEGY, strategy)])]
    for joint, fault in faults.items():
        out.append(_joint_status(robot, prefix, joint, fault, current, up_to_date, strategy))
    for side in frozen_arms(robot, faults):
        out.append(status(
            prefix, dk.arm_status(side), 'ERROR',
            f'all {len(robot.arms[side].joint_names)} joints of the {side} arm failed: the '
            f'arm is frozen at its lock angles; the other arm is still reconfigured', hw,
            [(dk.ARM, side), (dk.FROZEN, dk.TRUE)]))
    out.append(reconfiguration_status(snap, up_to_date, hw, prefix,
                                      robot.shared.names if robot.shared else ()))
    out.append(_inputs_status(snap, hw, prefix))
    problem = snap.state_problem
    out.append(status(prefix, dk.STATE, 'WARN' if problem else 'OK',
                      problem or f'state persisted in {snap.state_file}', hw,
                      [(dk.STATE_FILE, snap.state_file),
                       (dk.ENGINE_RESTARTS, snap.engine_restarts),
                       (dk.WAITING_CALLERS, snap.waiting_callers)]))
    out.append(_table_status(snap.table, hw, prefix))
    return out


def table_state(enabled, keeper):
    """Return the contingency table's (state, entries, missing): ``keeper``'s, or 'off'."""
    return keeper.status() if enabled else (dk.TABLE_OFF, 0, 0)


def _table_status(table, hw, prefix):
    """Return the ``contingency_table`` status: how many faults are served at once."""
    state, entries, missing = table
    message = {dk.TABLE_OFF: 'off (contingency_table is false): every fault is searched live',
               dk.TABLE_LOADING: 'loading: a fault meanwhile is searched live',
               dk.TABLE_BUILDING: f'{entries} fault sets served at once; {missing} more '
                                  f'being built in the background',
               dk.TABLE_COMPLETE: f'{entries} fault sets served at once; every planned one '
                                  f'is built'}.get(state, state)
    return status(prefix, dk.CONTINGENCY_TABLE, 'OK', message, hw,
                  [(dk.TABLE_STATE, state), (dk.TABLE_ENTRIES, entries),
                   (dk.TABLE_MISSING, missing)])


def _joint_status(robot, prefix, joint, fault, current, up_to_date, strategy):
    side, index = robot.locate_played(joint)            # 'shared': a torso, both arms'
    if up_to_date and joint in current.locks:
        lock = current.locks[joint]
        source = dk.LOCK_SOURCE_REPORT if fault.angle is not None else f'{strategy} strategy'
        text = f'failed; locked at {fmt_angle(lock)} ({source})'
        pairs = [(dk.LOCK_ANGLE_RAD, repr(lock)),
                 (dk.LOCK_ANGLE_DEG, f'{math.degrees(lock):.4f}'), (dk.LOCK_SOURCE, source)]
    else:
        text = 'failed; lock angle pending reconfiguration'
        pairs = [(dk.LOCK_ANGLE_RAD, '' if fault.angle is None else repr(fault.angle)),
                 (dk.LOCK_SOURCE, dk.LOCK_SOURCE_PENDING)]
    return status(prefix, dk.joint_status(joint), 'ERROR', text, joint,
                  [(dk.JOINT, joint), (dk.ARM, side), (dk.INDEX, index + 1)] + pairs)


def _inputs_status(snap, hw, prefix):
    rejections = snap.rejections
    last = rejections[-1] if rejections else None
    recent = last is not None and last[0] >= snap.last_accepted
    pairs = [(dk.REJECTED_TOTAL, snap.rejected_total),
             (dk.JOINT_STATES_RECEIVED, snap.joint_states_received),
             (dk.MEASURED_JOINTS, ' '.join(snap.measured_joints))]
    if last:
        pairs += [(dk.LAST_REJECTED_SOURCE, last[1]), (dk.LAST_REJECTED_REASON, last[2])]
    pairs += [(dk.rejected_key(i), f'{time.strftime("%H:%M:%S", time.localtime(t))} {src}: '
               f'{why}') for i, (t, src, why) in enumerate(reversed(rejections))]
    message = (f'rejected {last[1]}: {last[2]}' if recent else
               f'last rejected input: {last[1]}: {last[2]}' if last else 'no rejected input')
    return status(prefix, dk.INPUTS, 'WARN' if recent else 'OK', message, hw, pairs)


def corrections_text(result):
    """Return the measured corrections a library was searched on, e.g. ``right: ...``."""
    return '; '.join(f'{side}: {ArmCorrection.from_dict(c).describe()}'
                     for side, c in sorted(result.corrections.items()))


def _seconds(value, digits=4):
    """Return a duration in seconds as text, '' if not measured yet."""
    return '' if value is None else f'{value:.{digits}f}'


def reconfiguration_status(snap, up_to_date, hw, prefix, shared=()):
    """
    Return the ``reconfiguration`` status: the library published and how it was made.

    ``shared`` names the joints both arms hang from (a torso), which end every
    gesture's ``joint_names``.
    """
    current, running, failed = snap.current, snap.running, snap.failed
    version, stamp, settings = snap.version, snap.stamp_ns, snap.settings
    pairs = [(dk.LIBRARY_VERSION, version), (dk.LIBRARY_STAMP, dk.format_stamp(stamp)),
             (dk.UP_TO_DATE, dk.flag(up_to_date)), (dk.RUNNING, dk.flag(running)),
             (dk.OPTIMIZER, settings.optimizer),
             (dk.OPTIMIZER_PRESET, settings.optimizer_preset),
             (dk.DEADLINE_SEC, settings.deadline_sec)]
    if current is None:
        return status(prefix, dk.RECONFIGURATION, 'STALE', 'no library published yet', hw,
                      pairs)
    pairs += [(dk.LIBRARY_ORIGIN, current.origin),
              (dk.GESTURES, ' '.join(g.name for g in current.gestures)),
              (dk.WALL_TIME_SEC, f'{current.wall_time:.4f}'),
              (dk.REQUEST_TO_PUBLISH_SEC, _seconds(snap.request_to_publish)),
              (dk.PUBLISH_PATH_SEC, _seconds(snap.publish_path, 6)),
              (dk.FAULT_TO_REQUEST_SEC, _seconds(snap.fault_to_request, 6)),
              (dk.FAULT_SYNC_SEC, _seconds(snap.fault_sync, 6)),
              (dk.FAULT_TO_PUBLISH_SEC, _seconds(snap.fault_to_publish, 6)),
              (dk.DEADLINE_MET, dk.flag(current.deadline_met)),
              (dk.SUCCESS, dk.flag(current.success)),
              (dk.FROZEN_ARMS, ' '.join(current.frozen_arms)),
              (dk.SHARED_JOINTS, ' '.join(shared)),
              (dk.SEED, '' if current.seed is None else current.seed),
              (dk.TOOL_LENGTH_MM, f'{current.tool_mm:g}'), (dk.TOOL_ARM, current.tool_arm),
              (dk.CORRECTIONS, corrections_text(current))]
    if current.refined_after is not None:
        pairs.append((dk.REFINED_AFTER_SEC, _seconds(current.refined_after)))
    for g in current.gestures:
        fields = [(dk.SCORE_BEFORE, f'{g.score_before:.6g}'),
                  (dk.SCORE_AFTER, f'{g.score_after:.6g}'),
                  (dk.TIME_SEC, f'{g.wall_time:.4f}'), (dk.STATUS, g.status),
                  (dk.STAGE, g.stage), (dk.METHOD, g.method),
                  (dk.TYPICAL_POINTS, g.typical_points),
                  (dk.TIP_ERROR_MM, f'{g.tip_error_mm:.3f}'),
                  (dk.MAX_JUMP_DEG, f'{g.max_jump_deg:.3f}'),
                  (dk.RIGHT_JOINTS, g.right_joints)]
        if current.settings.get('collision_check'):
            fields.append((dk.COLLIDES, dk.flag(g.collides)))
            if g.colliding_pairs:
                fields.append((dk.COLLIDING_PAIRS, ' '.join(g.colliding_pairs)))
        pairs += [(dk.gesture_key(g.name, key), value) for key, value in fields]
    for k, note in enumerate(current.notes):
        pairs.append((dk.note_key(k), note))
    level = 'OK'
    message = summary(current)
    if failed and not up_to_date:
        level, message = 'ERROR', f'last run failed: {failed[1]}; {message}'
    elif not up_to_date:
        message = f'reconfiguring; last published: {message}'
    elif not current.success or any(g.collides for g in current.gestures):
        level = 'WARN'
    return status(prefix, dk.RECONFIGURATION, level, message, hw, pairs)
