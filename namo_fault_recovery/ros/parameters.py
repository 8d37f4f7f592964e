"""
The node's parameters: descriptors, validation and configuration, from one declaration.

Every parameter is a :class:`~namo_fault_recovery.recovery.settings.Setting` of
:data:`~namo_fault_recovery.recovery.settings.SETTINGS` (name, type, default, range or
choices, unit, doc, read-only, rerun).  From it, and free of DDS (only the
``rcl_interfaces`` descriptor types): :func:`parameter_specs` lists every parameter with
its descriptor, :func:`check_parameter` is the on-set validator (one reason, naming the
value and what was expected) and :func:`node_config` turns the parameter values into a
:class:`NodeConfig`: the engine's :class:`RecoverySettings` plus the node's own options.
A parameter name is the engine's setting name (``deadline_sec``, ``lock_strategy``...).
"""

from dataclasses import dataclass, fields
from pathlib import Path
import sys

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from ..errors import shorten
from ..recovery.settings import (check, DEFAULT_STATE_DIR, RecoverySettings, SETTINGS,
                                 settings_from, TYPE_NAMES, WEIGHT_PARAMS)

__all__ = ['check_parameter', 'CHOICES', 'declare_parameters', 'DEFAULT_STATE_DIR',
           'descriptor_of', 'MARKER_PARAMS', 'node_config', 'NodeConfig', 'one_line',
           'parameter_specs', 'RERUN_PARAMS', 'shorten', 'source', 'StartupError',
           'TYPE_NAMES', 'WEIGHT_PARAMS']

CHOICES = {s.name: s.choices for s in SETTINGS if s.choices is not None}
# Changing one of these changes what the library should be: the node reconfigures again.
RERUN_PARAMS = frozenset(s.name for s in SETTINGS if s.rerun)
MARKER_PARAMS = frozenset(s.name for s in SETTINGS if s.name.startswith('marker_'))


@dataclass(frozen=True)
class NodeConfig:
    """What the node runs with: the engine's settings plus the node's own options."""

    settings: RecoverySettings
    seed: object                 # None draws one per run
    marker_frame_id: str
    marker_spacing: float
    refine_budget_sec: float
    contingency_table: bool


def descriptor_of(s):
    """Return the ROS ParameterDescriptor of one Setting (range, choices, read-only)."""
    d = ParameterDescriptor(description=s.doc + (f'; unit: {s.unit}' if s.unit else ''),
                            read_only=s.read_only)
    if s.choices is not None:
        d.additional_constraints = 'one of: ' + ', '.join(s.choices)
    if s.limits is not None and s.value_type is float:
        d.floating_point_range = [FloatingPointRange(
            from_value=float(s.limits[0]), to_value=float(s.limits[1]), step=0.0)]
    elif s.limits is not None:
        d.integer_range = [IntegerRange(from_value=int(s.limits[0]), to_value=int(s.limits[1]),
                                        step=1)]
    return d


def parameter_specs():
    """Return (name, default, descriptor) for every parameter of the node."""
    return [(s.name, s.default, descriptor_of(s)) for s in SETTINGS]


def check_parameter(name, value, current=None):
    """
    Return None if ``value`` is acceptable for parameter ``name``, else the reason.

    ``current`` maps the other parameters to their values, for the checks that involve
    several (the score weights).  Ranges are enforced by the descriptors.
    """
    return check(name, value, current)


def node_config(values):
    """Return the :class:`NodeConfig` of a complete ``{parameter: value}`` mapping."""
    own = {f.name: values[f.name] for f in fields(NodeConfig) if f.name not in (
        'settings', 'seed')}
    seed = int(values['seed'])
    return NodeConfig(settings=settings_from(values), seed=None if seed < 0 else seed, **own)


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
                + f', got {shorten(repr(value))}{source(name)}') from None
        except ParameterException as exc:
            reason = last_reason()
            if reason is None:
                reason = one_line(exc).split('Reason: ', 1)[-1].removesuffix(f': {name}')
            if not reason.startswith(name):
                reason = f'{name}: {reason}'
            raise StartupError(f'invalid parameter {reason}{source(name)}') from None
    values = {name: node.get_parameter(name).value for name, _, _ in parameter_specs()}
    for name, value in values.items():
        reason = check_parameter(name, value, values)
        if reason:
            raise StartupError(f'invalid parameter {reason}{source(name)}')
    return values


def source(name, argv=None):
    """
    Return ' (in FILE)' if the last ``--params-file`` of ``argv`` that sets ``name`` is FILE.

    A ``-p name:=value`` on the command line wins over the files: then, and if no file
    sets ``name``, return ''.  ``argv`` defaults to the process' arguments.
    """
    argv = sys.argv if argv is None else list(argv)
    if any(token.startswith(f'{name}:=') for token in argv):
        return ''
    found = ''
    for flag, path in zip(argv, argv[1:]):
        if flag == '--params-file' and name in _file_parameters(path):
            found = f' (in {path})'
    return found


def _file_parameters(path):
    """Return the dotted names a ROS parameter file sets, for any node (empty if unreadable)."""
    import yaml
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return set()
    names = set()

    def flatten(mapping, prefix):
        for key, value in mapping.items():
            if isinstance(value, dict):
                flatten(value, f'{prefix}{key}.')
            else:
                names.add(f'{prefix}{key}')

    def walk(node):
        if isinstance(node, dict):
            for key, value in node.items():
                if key == 'ros__parameters' and isinstance(value, dict):
                    flatten(value, '')
                else:
                    walk(value)

    walk(doc)
    return names
