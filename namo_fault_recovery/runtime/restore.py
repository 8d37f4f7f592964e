"""
The checks a library passes before it is published or restored, and the restore decision.

Free of ROS.  :func:`check_result` refuses a library whose gestures, keyframes or locks do
not match the configuration, or with an angle that is not finite or not within its
limits exactly; :func:`restore_decision` says whether the library saved in ``state_dir``
can be republished after a restart or must be recomputed, and why.
"""

from dataclasses import dataclass, field
import math


def check_result(robot, library, result, faults=None):
    """Return None if ``result`` is safe to publish, else the reason it is not."""
    if result.names != library.names:
        return (f'library gestures {list(result.names)} do not match the configured '
                f'{list(library.names)}')
    if faults is not None and set(result.locks) != set(faults):
        return (f'locked joints {sorted(result.locks)} do not match the fault set '
                f'{sorted(faults)}')
    joint_names = tuple(robot.joint_names)
    columns, held = {}, {}
    for joint, angle in result.locks.items():
        try:
            usable = math.isfinite(angle) and robot.joint_within_limits(joint, angle, 0.0)
        except KeyError as exc:
            return exc.args[0]
        if not usable:
            return f'lock angle {angle!r} of {joint} is not usable'
        if joint in joint_names:
            columns[joint_names.index(joint)] = angle
        else:                         # a torso held where it stuck: every gesture holds it
            held[joint] = angle
    right = len(robot.arms['right'].joint_names)
    for gesture in result.gestures:
        if len(gesture.times) != len(library[gesture.name].keyframes):
            return f'{gesture.name}: wrong number of keyframes'
        lean = _lean_problem(robot, gesture)
        if lean:
            return lean
        if any(gesture.shared.get(j, 0.0) != a for j, a in held.items()):
            return f'{gesture.name}: the torso is not held at its lock angles {held}'
        split = gesture.right_columns(len(joint_names))
        if split != right:
            return (f'{gesture.name}: rows split after {split or "unknown"} columns, not '
                    f'after the {right} of the right arm')
        for q in gesture.positions:
            if len(q) != len(joint_names):
                return f'{gesture.name}: expected {len(joint_names)} angles'
            for k, angle in enumerate(q):
                if not (math.isfinite(angle)
                        and robot.joint_within_limits(joint_names[k], angle, 0.0)):
                    return (f'{gesture.name}: angle {angle!r} of {joint_names[k]} '
                            f'is not finite or outside its limits')
                if k in columns and angle != columns[k]:
                    return (f'{gesture.name}: failed joint {joint_names[k]} at '
                            f'{angle!r}, not at its lock angle {columns[k]!r}')
    return None


def _lean_problem(robot, gesture):
    """Return why a gesture's torso lean (``shared``) cannot be published, or ''."""
    names = robot.shared.names if robot.shared is not None else ()
    for joint, angle in gesture.shared.items():
        if joint not in names:
            return f'{gesture.name}: leans {joint!r}, not a joint both arms hang from'
        if not (math.isfinite(angle) and robot.joint_within_limits(joint, angle, 0.0)):
            return f'{gesture.name}: lean {angle!r} of {joint} is not finite or outside its limits'
    return ''


def validate_faults(robot, faults):
    """Return why a persisted fault set cannot be used, or None."""
    for joint, fault in faults.items():
        try:
            robot.locate_played(joint)
        except KeyError as exc:
            return f'fault on {exc.args[0]}'
        for value in (fault.angle, fault.measured):
            if value is not None and not robot.joint_within_limits(joint, value):
                return f'angle {value!r} of faulted joint {joint} is outside its limits'
    return None


def _tool(length_mm, arm):
    """Return a comparable structure change: no tool is the same on either arm."""
    return (float(length_mm), arm) if length_mm > 0 else (0.0, None)


def restore_decision(robot, library, state, fingerprint, settings):
    """
    Return None if ``state.library`` can be republished as it is, else the reason.

    ``settings`` are the node's engine settings now; the saved library must have been
    computed from the same files, for the same fault set, lock strategy (with faults:
    it chose their angles) and tool, on the same measured corrections.
    """
    saved = state.library
    if saved is None:
        return 'no library was saved'
    if state.fingerprint != fingerprint:
        return 'the robot or gesture file changed since it was saved'
    if saved.faults != {j: f.angle for j, f in state.faults.items()}:
        return 'the saved library was computed for another fault set'
    if saved.faults and saved.settings.get('lock_strategy') != settings.lock_strategy:
        return 'the lock strategy changed since it was saved'
    if (_tool(saved.tool_mm, saved.tool_arm)
            != _tool(settings.tool_length_mm, settings.tool_arm)):
        return 'the tool (tool_length_mm, tool_arm) changed since it was saved'
    if saved.corrections != {c.side: c.to_dict() for c in state.corrections}:
        return 'the saved library was computed for other measured corrections'
    return check_result(robot, library, saved, state.faults)


@dataclass(frozen=True)
class RestartPlan:
    """What a restarted node does: the faults it restores and the library it republishes."""

    faults: dict = field(default_factory=dict)
    library: object = None        # the saved LibraryResult if it can be republished
    problem: str = None           # an unusable state file (it was set aside)
    message: str = ''
    corrections: tuple = ()       # ArmCorrection per arm, measured on the robot


def plan_restart(store, robot, library, fingerprint, settings):
    """Read the state file of ``store`` and decide what to restore (see RestartPlan)."""
    state, problem = store.load()
    if state is not None:
        problem = validate_faults(robot, state.faults)
        if problem:
            problem = store.set_aside(problem)
            state = None
    if state is None or not (state.faults or state.corrections):
        return RestartPlan(problem=problem)
    reason = restore_decision(robot, library, state, fingerprint, settings)
    what = ', '.join([f'faults {", ".join(state.faults)}'] * bool(state.faults)
                     + [f'the measured {c.side} arm ({", ".join(c.groups) or "nominal"})'
                        for c in state.corrections])
    if reason is None:
        return RestartPlan(dict(state.faults), state.library, problem,
                           f'restored {what} and their library from {store.path}',
                           state.corrections)
    return RestartPlan(dict(state.faults), None, problem,
                       f'restored {what} from {store.path}; {reason}: reconfiguring',
                       state.corrections)
