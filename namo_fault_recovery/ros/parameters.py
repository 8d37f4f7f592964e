"""
The node's parameter table: names, defaults, descriptors, validation, and settings.

Free of DDS (only the ``rcl_interfaces`` descriptor types): :func:`parameter_specs` lists
every parameter with its descriptor, :func:`check_parameter` is the on-set validator
(one reason, naming the value and what was expected), and :func:`node_settings` turns the
parameter values into the engine's :class:`RecoverySettings` plus the node's own options.
A parameter name is the engine's setting name (``deadline_sec``, ``lock_strategy``...).
"""

from dataclasses import dataclass
import math

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from ..errors import shorten
from ..model.robot import ARMS
from ..objective.score import COMPONENTS, ScoreWeights
from ..optimize import ALGORITHMS, PRESETS
from ..recovery.engine import RecoverySettings
from ..recovery.keyframes import BIMANUAL_MODES
from ..recovery.locks import LOCK_STRATEGIES
from ..recovery.motion import DEFAULT_CONTINUITY, DEFAULT_DISTORTION_MM, METHODS

DEFAULT_STATE_DIR = '~/.ros/namo_fault_recovery'
WEIGHT_PARAMS = tuple(f'weights.{c}' for c in COMPONENTS)
CHOICES = {
    'lock_strategy': LOCK_STRATEGIES,
    'optimizer': tuple(ALGORITHMS),
    'optimizer_preset': tuple(PRESETS),
    'bimanual': tuple(BIMANUAL_MODES),
    'trajectory_method': METHODS,
    'tool_arm': ARMS,
}
# Changing one of these changes what the library should be: the node reconfigures again.
RERUN_PARAMS = frozenset(('deadline_sec', 'lock_strategy', 'optimizer', 'optimizer_preset',
                          'seed', 'bimanual', 'collision_check', 'tool_length_mm',
                          'tool_arm', 'trajectory_method', 'vq_distortion_mm',
                          'continuity_weight', 'weights.normalise') + WEIGHT_PARAMS)
MARKER_PARAMS = frozenset(('marker_frame_id', 'marker_spacing'))
TYPE_NAMES = {str: 'a string', float: 'a floating-point number', int: 'an integer',
              bool: 'true or false'}


@dataclass(frozen=True)
class NodeSettings:
    """What the node runs with: the engine's settings plus the node's own options."""

    engine: RecoverySettings
    seed: object                 # None draws one per run
    marker_frame_id: str = 'base_link'
    marker_spacing: float = 0.8
    refine_budget_sec: float = 10.0
    contingency_table: bool = True


def fp_range(low, high):
    return [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]


def parameter_specs():
    """Return (name, default, descriptor) for every parameter of the node."""
    specs = [
        ('robot_file', '', ParameterDescriptor(
            description='arm model YAML (DH, joint names, limits); empty = the packaged '
                        'Namo model', read_only=True)),
        ('gesture_file', '', ParameterDescriptor(
            description='reference gesture library YAML; empty = the packaged library',
            read_only=True)),
        ('deadline_sec', 1.0, ParameterDescriptor(
            description='hard budget (s) for one reconfiguration of the whole library',
            floating_point_range=fp_range(0.01, 60.0))),
        ('lock_strategy', 'average', ParameterDescriptor(
            description='lock angle of a joint reported without a position',
            additional_constraints='one of: ' + ', '.join(LOCK_STRATEGIES))),
        ('optimizer', 'abc', ParameterDescriptor(
            description="optimiser (abc = the paper's artificial bee colony; the others for "
                        'comparison)',
            additional_constraints='one of: ' + ', '.join(ALGORITHMS))),
        ('optimizer_preset', 'default', ParameterDescriptor(
            description='optimiser settings: default (product tuning) or paper (Table 3)',
            additional_constraints='one of: ' + ', '.join(PRESETS))),
        ('bimanual', 'auto', ParameterDescriptor(
            description='two-handed gestures: let the healthy arm move too (stage 2): '
                        'auto = when the faulted arm alone scores poorly',
            additional_constraints='one of: ' + ', '.join(BIMANUAL_MODES))),
        ('collision_check', True, ParameterDescriptor(
            description='keep the arms and the torso apart, and report poses that collide')),
        ('tool_length_mm', 0.0, ParameterDescriptor(
            description='a tool in the hand of tool_arm lengthens it by this much (mm): a '
                        'structure change; 0 = none.  Changing it re-adapts the library',
            floating_point_range=fp_range(0.0, 300.0))),
        ('tool_arm', 'right', ParameterDescriptor(
            description='the arm whose hand holds the tool',
            additional_constraints='one of: ' + ', '.join(ARMS))),
        ('trajectory_method', 'auto', ParameterDescriptor(
            description='motions: kriging = typical points + Kriging (the second paper); '
                        'per_point = every point in order; auto = kriging, then per point '
                        'where the deadline allows',
            additional_constraints='one of: ' + ', '.join(METHODS))),
        ('vq_distortion_mm', DEFAULT_DISTORTION_MM, ParameterDescriptor(
            description='quantisation distortion threshold (mm of fingertip) that sets '
                        'the number of typical points of a dense motion',
            floating_point_range=fp_range(1.0, 1000.0))),
        ('continuity_weight', DEFAULT_CONTINUITY, ParameterDescriptor(
            description='per-point adaptation: penalty per deg^2 of joint jump away from '
                        'the previous point plus the designed step',
            floating_point_range=fp_range(0.0, 100.0))),
        ('seed', -1, ParameterDescriptor(
            description='random seed for reproducible runs; -1 draws one per run',
            integer_range=[IntegerRange(from_value=-1, to_value=2 ** 31 - 1, step=1)])),
    ]
    for component in COMPONENTS:
        specs.append((f'weights.{component}', 1.0, ParameterDescriptor(
            description=f'score weight of the {component} component (>= 0)',
            floating_point_range=fp_range(0.0, 1000.0))))
    specs += [
        ('weights.normalise', True, ParameterDescriptor(
            description='scale the weights a gesture uses so they sum to 1 (the paper)')),
        ('state_dir', DEFAULT_STATE_DIR, ParameterDescriptor(
            description='directory where the fault set and the last library persist',
            read_only=True)),
        ('marker_frame_id', 'base_link', ParameterDescriptor(
            description='frame of the /gesture_markers skeletons (the torso centre)')),
        ('marker_spacing', 0.8, ParameterDescriptor(
            description='distance (m) between the gestures shown on /gesture_markers',
            floating_point_range=fp_range(0.0, 10.0))),
        ('refine_budget_sec', 10.0, ParameterDescriptor(
            description='after a deadline result the node keeps searching in the background '
                        'for this long (s), and publishes each better library as a new '
                        'version; 0 = off.  A new fault cancels it',
            floating_point_range=fp_range(0.0, 600.0))),
        ('contingency_table', True, ParameterDescriptor(
            description='precompute, at low priority, the library for every single fault '
                        '(and every further one once faults are active), kept in state_dir; '
                        'a fault found there is answered at once')),
        ('contingency_file', '', ParameterDescriptor(
            description="a table built offline by 'namo-recovery precompute' to load at "
                        'start (used only if built for this robot, library and settings)',
            read_only=True)),
        ('diagnostics_period_sec', 1.0, ParameterDescriptor(
            description='period (s) of /diagnostics (also published on every change)',
            floating_point_range=fp_range(0.1, 60.0), read_only=True)),
    ]
    return specs


def check_parameter(name, value, current=None):
    """
    Return None if ``value`` is acceptable for parameter ``name``, else the reason.

    ``current`` maps the other parameters to their values, for the checks that involve
    several (the score weights).  Types and ranges are also enforced by the descriptors.
    """
    if name in CHOICES and value not in CHOICES[name]:
        return (f'{name}: unknown value {shorten(repr(value))}; expected one of '
                f'{", ".join(CHOICES[name])}')
    if name in WEIGHT_PARAMS or name == 'weights.normalise':
        if name in WEIGHT_PARAMS and (not isinstance(value, float)
                                      or not math.isfinite(value) or value < 0):
            return f'{name}: expected a finite number >= 0, got {shorten(repr(value))}'
        if current is not None and all(p in current for p in WEIGHT_PARAMS):
            mapping = {p.split('.', 1)[1]: current[p] for p in WEIGHT_PARAMS
                       + ('weights.normalise',) if p in current}
            mapping[name.split('.', 1)[1]] = value
            try:
                ScoreWeights.from_mapping(mapping)
            except ValueError as exc:
                return str(exc)
    if name == 'deadline_sec' and (not isinstance(value, float) or not math.isfinite(value)
                                   or value <= 0):
        return f'deadline_sec: expected a positive number of seconds, got {shorten(repr(value))}'
    return None


def node_settings(values):
    """Return :class:`NodeSettings` for a complete ``{parameter: value}`` mapping."""
    weights = ScoreWeights.from_mapping({p.split('.', 1)[1]: values[p]
                                         for p in WEIGHT_PARAMS + ('weights.normalise',)})
    seed = int(values['seed'])
    engine = RecoverySettings(
        deadline_sec=float(values['deadline_sec']), lock_strategy=values['lock_strategy'],
        optimizer=values['optimizer'], optimizer_preset=values['optimizer_preset'],
        bimanual=values['bimanual'], collision_check=bool(values['collision_check']),
        tool_length_mm=float(values['tool_length_mm']), tool_arm=values['tool_arm'],
        trajectory_method=values['trajectory_method'],
        vq_distortion_mm=float(values['vq_distortion_mm']),
        continuity_weight=float(values['continuity_weight']), weights=weights)
    return NodeSettings(engine=engine, seed=None if seed < 0 else seed,
                        marker_frame_id=values['marker_frame_id'],
                        marker_spacing=float(values['marker_spacing']),
                        refine_budget_sec=float(values['refine_budget_sec']),
                        contingency_table=bool(values['contingency_table']))


class StartupError(Exception):
    """The node cannot start; the message is the one-line reason shown to the user."""


def one_line(exc):
    """Return an exception's text on one line."""
    return ' '.join(str(exc).split())


def declare_parameters(node, last_reason):
    """
    Declare every parameter on ``node``; raise StartupError naming a bad override.

    ``last_reason()`` returns the reason the node's on-set validator gave last, so that
    the user sees that rather than rclpy's generic text.
    """
    from rclpy.exceptions import InvalidParameterTypeException, ParameterException
    for name, default, descriptor in parameter_specs():
        try:
            node.declare_parameter(name, default, descriptor)
        except InvalidParameterTypeException:
            override = getattr(node, '_parameter_overrides', {}).get(name)
            value = override.value if override is not None else None
            raise StartupError(
                f'invalid parameter {name}: expected {TYPE_NAMES[type(default)]}'
                + (f' (write {float(value)!r}, not {value!r})' if isinstance(value, int)
                   and isinstance(default, float) else '')
                + f', got {shorten(repr(value))}') from None
        except ParameterException as exc:
            reason = last_reason()
            if reason is None:
                reason = one_line(exc).split('Reason: ', 1)[-1].removesuffix(f': {name}')
            if not reason.startswith(name):
                reason = f'{name}: {reason}'
            raise StartupError(f'invalid parameter {reason}') from None
    values = {name: node.get_parameter(name).value for name, _, _ in parameter_specs()}
    for name, value in values.items():
        reason = check_parameter(name, value, values)
        if reason:
            raise StartupError(f'invalid parameter {reason}')
    return values
