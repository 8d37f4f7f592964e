"""Small validators shared by the config loaders; each error names the file and key."""

import math
from pathlib import Path

import yaml

from ..errors import ConfigError


def load_yaml(path):
    """Read a YAML mapping from ``path`` or raise a ConfigError naming the file."""
    path = Path(path)
    try:
        text = path.read_text(encoding='utf-8')
    except OSError as exc:
        raise ConfigError(path, None, f'cannot read file ({exc.strerror or exc})') from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(path, None, f'not valid YAML ({exc})') from exc
    if data is None:
        raise ConfigError(path, None, 'file is empty; expected a YAML mapping')
    if not isinstance(data, dict):
        raise ConfigError(path, None, f'expected a YAML mapping at top level, got '
                          f'{type(data).__name__}')
    return data


def require(mapping, key, file, where=''):
    """Return ``mapping[key]`` or raise a ConfigError for the missing key."""
    full = f'{where}.{key}' if where else key
    if not isinstance(mapping, dict):
        raise ConfigError(file, where or key, f'expected a mapping, got {mapping!r}')
    if key not in mapping:
        raise ConfigError(file, full, 'missing key')
    return mapping[key]


def as_number(value, file, key):
    """Return ``value`` as a finite float or raise a ConfigError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(file, key, f'expected a number, got {value!r}')
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(file, key, f'expected a finite number, got {value!r}')
    return value


def as_row(value, length, file, key):
    """Return ``value`` as a list of ``length`` floats or raise a ConfigError."""
    if not isinstance(value, (list, tuple)):
        raise ConfigError(file, key, f'expected a list of {length} numbers, got {value!r}')
    if len(value) != length:
        raise ConfigError(file, key, f'expected {length} values, got {len(value)}: {value!r}')
    return [as_number(v, file, f'{key}[{i}]') for i, v in enumerate(value)]


def as_angle_scale(unit, file, key):
    """Return the factor that converts ``unit`` to radians."""
    scales = {'deg': math.pi / 180.0, 'degrees': math.pi / 180.0,
              'rad': 1.0, 'radians': 1.0}
    if unit not in scales:
        raise ConfigError(file, key, f"unknown angle unit {unit!r}; expected 'deg' or 'rad'")
    return scales[unit]
