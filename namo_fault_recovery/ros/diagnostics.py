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
from ..recovery.locks import frozen_arms
from ..recovery.result import summary

DEFAULT_PREFIX = 'recovery_node: '


def status_prefix(node_fqn):
    """Return the status-name prefix of a node: ``ns/name: `` (``name: `` at the root)."""
    return node_fqn.lstrip('/') + ': '


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
    settings: object             # NodeSettings
    rejections: list = field(default_factory=list)   # (wall time, source, reason)
    rejected_total: int = 0
    joint_states_received: int = 0
    measured_joints: tuple = ()
    last_accepted: float = 0.0
    state_problem: str = None
    state_file: str = ''
    engine_restarts: int = 0
    waiting_callers: int = 0


def snapshot(book, inputs, settings, state_problem, state_file, engine_restarts):
    """Return a :class:`Snapshot` of a RunBook, an InputMonitor and the node's state."""
    b = book.snapshot()
    return Snapshot(
        faults=b['faults'], fault_version=b['fault_version'], current=b['current'],
        version=b['version'], stamp_ns=b['stamp_ns'], pending=b['pending'],
        running=b['running'], failed=b['failed'], settings=settings,
        rejections=list(inputs.rejections), rejected_total=inputs.rejected_total,
        joint_states_received=inputs.states_received,
        measured_joints=inputs.measured_joints(), last_accepted=inputs.last_accepted,
        state_problem=state_problem, state_file=str(state_file),
        engine_restarts=engine_restarts, waiting_callers=b['waiting_callers'])


def statuses(robot, snap, prefix=DEFAULT_PREFIX):
    """Return the node's DiagnosticStatus list for ``snap``."""
    hw = robot.name
    faults, current = snap.faults, snap.current
    strategy = snap.settings.engine.lock_strategy
    up_to_date = current is not None and not snap.pending and set(current.locks) == set(faults)
    out = [status(prefix, 'faults', 'ERROR' if faults else 'OK',
                  f'{len(faults)} failed joint(s): {", ".join(faults)}' if faults
                  else 'no faults', hw,
                  [('fault_version', snap.fault_version), ('failed_joints', ' '.join(faults)),
                   ('lock_strategy', strategy)])]
    for joint, fault in faults.items():
        out.append(_joint_status(robot, prefix, joint, fault, current, up_to_date, strategy))
    for side in frozen_arms(robot, faults):
        out.append(status(
            prefix, f'arm {side}', 'ERROR',
            f'all {len(robot.arms[side].joint_names)} joints of the {side} arm failed: the '
            f'arm is frozen at its lock angles; the other arm is still reconfigured', hw,
            [('arm', side), ('frozen', 'true')]))
    out.append(reconfiguration_status(snap, up_to_date, hw, prefix))
    out.append(_inputs_status(snap, hw, prefix))
    problem = snap.state_problem
    out.append(status(prefix, 'state', 'WARN' if problem else 'OK',
                      problem or f'state persisted in {snap.state_file}', hw,
                      [('state_file', snap.state_file),
                       ('engine_restarts', snap.engine_restarts),
                       ('waiting_callers', snap.waiting_callers)]))
    return out


def _joint_status(robot, prefix, joint, fault, current, up_to_date, strategy):
    side, index = robot.locate_joint(joint)
    if up_to_date and joint in current.locks:
        lock = current.locks[joint]
        source = 'fault report' if fault.angle is not None else f'{strategy} strategy'
        text = f'failed; locked at {fmt_angle(lock)} ({source})'
        pairs = [('lock_angle_rad', repr(lock)),
                 ('lock_angle_deg', f'{math.degrees(lock):.4f}'), ('lock_source', source)]
    else:
        text = 'failed; lock angle pending reconfiguration'
        pairs = [('lock_angle_rad', '' if fault.angle is None else repr(fault.angle)),
                 ('lock_source', 'pending')]
    return status(prefix, f'joint {joint}', 'ERROR', text, joint,
                  [('joint', joint), ('arm', side), ('index', index + 1)] + pairs)


def _inputs_status(snap, hw, prefix):
    rejections = snap.rejections
    last = rejections[-1] if rejections else None
    recent = last is not None and last[0] >= snap.last_accepted
    pairs = [('rejected_total', snap.rejected_total),
             ('joint_states_received', snap.joint_states_received),
             ('measured_joints', ' '.join(snap.measured_joints))]
    if last:
        pairs += [('last_rejected_source', last[1]), ('last_rejected_reason', last[2])]
    pairs += [(f'rejected[{i}]', f'{time.strftime("%H:%M:%S", time.localtime(t))} {src}: '
               f'{why}') for i, (t, src, why) in enumerate(reversed(rejections))]
    message = (f'rejected {last[1]}: {last[2]}' if recent else
               f'last rejected input: {last[1]}: {last[2]}' if last else 'no rejected input')
    return status(prefix, 'inputs', 'WARN' if recent else 'OK', message, hw, pairs)


def reconfiguration_status(snap, up_to_date, hw, prefix):
    """Return the ``reconfiguration`` status: the library published and how it was made."""
    current, running, failed = snap.current, snap.running, snap.failed
    version, stamp, settings = snap.version, snap.stamp_ns, snap.settings.engine
    pairs = [('library_version', version),
             ('library_stamp', f'{stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d}'),
             ('up_to_date', str(up_to_date).lower()),
             ('running', str(running).lower()), ('optimizer', settings.optimizer),
             ('optimizer_preset', settings.optimizer_preset),
             ('deadline_sec', settings.deadline_sec)]
    if current is None:
        return status(prefix, 'reconfiguration', 'STALE', 'no library published yet', hw,
                      pairs)
    pairs += [('wall_time_sec', f'{current.wall_time:.4f}'),
              ('deadline_met', str(current.deadline_met).lower()),
              ('success', str(current.success).lower()),
              ('frozen_arms', ' '.join(current.frozen_arms)),
              ('seed', '' if current.seed is None else current.seed),
              ('tool_length_mm', f'{current.tool_mm:g}'), ('tool_arm', current.tool_arm)]
    for g in current.gestures:
        pairs += [(f'{g.name}.score_before', f'{g.score_before:.6g}'),
                  (f'{g.name}.score_after', f'{g.score_after:.6g}'),
                  (f'{g.name}.time_sec', f'{g.wall_time:.4f}'),
                  (f'{g.name}.status', g.status),
                  (f'{g.name}.stage', g.stage),
                  (f'{g.name}.method', g.method),
                  (f'{g.name}.typical_points', g.typical_points),
                  (f'{g.name}.tip_error_mm', f'{g.tip_error_mm:.3f}'),
                  (f'{g.name}.max_jump_deg', f'{g.max_jump_deg:.3f}')]
        if current.settings.get('collision_check'):
            pairs.append((f'{g.name}.collides', str(g.collides).lower()))
            if g.colliding_pairs:
                pairs.append((f'{g.name}.colliding_pairs', ' '.join(g.colliding_pairs)))
    for k, note in enumerate(current.notes):
        pairs.append((f'note[{k}]', note))
    level = 'OK'
    message = summary(current)
    if failed and not up_to_date:
        level, message = 'ERROR', f'last run failed: {failed[1]}; {message}'
    elif not up_to_date:
        message = f'reconfiguring; last published: {message}'
    elif not current.success or any(g.collides for g in current.gestures):
        level = 'WARN'
    return status(prefix, 'reconfiguration', level, message, hw, pairs)
