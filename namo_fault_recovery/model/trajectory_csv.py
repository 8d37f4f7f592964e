"""
Dense recorded trajectories: a CSV of ``time, J joint angles``, validated on load.

The file has one row per sample: the time from the start of the gesture (s), then the
angles of all arm joints (14 on Namo) in the robot's joint order (right arm first).  An optional
header row names the columns: ``time`` and the joint names, in any order, which then
map the columns.  Lines starting with ``#`` are comments.  Every error names the file,
the line and the column, as a ConfigError does for YAML.
"""

import csv
import math
from pathlib import Path

import numpy as np

from ..errors import ConfigError


def load_trajectory_csv(path, robot, scale):
    """
    Read a trajectory CSV; return ``(times (T,), angles (T, J) in rad)``.

    ``scale`` converts the file's angle unit to radians.  Times must be non-negative and
    strictly increasing, and every angle finite and within the joint's limits.
    """
    path = Path(path)
    names = list(robot.joint_names)
    rows = _read_rows(path)
    if not rows:
        raise ConfigError(path, None, f'no samples; expected rows of time and '
                          f'{len(names)} joint angles')
    order = list(range(len(names) + 1))
    if not _is_number(rows[0][1][0]):
        order = _header_order(path, *rows[0], names)
        rows = rows[1:]
        if not rows:
            raise ConfigError(path, None, 'a header but no samples')
    times = np.empty(len(rows))
    angles = np.empty((len(rows), len(names)))
    limits = np.concatenate([[robot.arms[s].lower, robot.arms[s].upper]
                             for s in ('right', 'left')], axis=1)
    for r, (line, row) in enumerate(rows):
        values = _row_values(path, line, row, order, names)
        t = values[0]
        if t < 0 or (r and t <= times[r - 1]):
            raise ConfigError(path, f'line {line}, column time',
                              f'times must be non-negative and strictly increasing; got '
                              f'{t:g}' + (f' after {times[r - 1]:g}' if r else ''))
        times[r] = t
        angles[r] = np.array(values[1:]) * scale
        outside = np.nonzero((angles[r] < limits[0] - 1e-9) | (angles[r] > limits[1] + 1e-9))[0]
        if outside.size:
            j = int(outside[0])
            raise ConfigError(path, f'line {line}, column {names[j]}',
                              f'angle {values[1 + j]:g} is outside the joint limits '
                              f'[{limits[0, j] / scale:g}, {limits[1, j] / scale:g}]')
    return times, angles


def _read_rows(path):
    """Return the file's ``(line number, cells)`` rows, without comments and blank lines."""
    try:
        with path.open(newline='', encoding='utf-8') as stream:
            return [(n, row) for n, row in enumerate(csv.reader(stream), start=1)
                    if row and not row[0].lstrip().startswith('#')]
    except OSError as exc:
        raise ConfigError(path, None, f'cannot read file ({exc.strerror or exc})') from exc
    except csv.Error as exc:
        raise ConfigError(path, None, f'not a valid CSV file ({exc})') from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(path, None, f'not a UTF-8 text file (byte {exc.start}: '
                          f'{exc.reason})') from exc


def _header_order(path, line, first, names):
    """Return the column of ``time`` and of each joint, named by the header row."""
    header = [c.strip() for c in first]
    expected = ['time'] + names
    unknown = [c for c in header if c not in expected]
    if unknown:
        raise ConfigError(path, f'line {line}',
                          f'unknown column {unknown[0]!r}; expected time and the joint '
                          f'names {", ".join(names)}')
    missing = [c for c in expected if c not in header]
    if missing or len(header) != len(expected):
        what = f'missing column {missing[0]!r}' if missing else 'a column repeats'
        raise ConfigError(path, f'line {line}', f'{what}; expected time and the '
                          f'{len(names)} joint names')
    return [header.index(c) for c in expected]


def _row_values(path, line, row, order, names):
    """Return one sample row as floats, time first, then the joints in robot order."""
    if len(row) != len(names) + 1:
        raise ConfigError(path, f'line {line}',
                          f'expected {len(names) + 1} values (time and {len(names)} '
                          f'joint angles), got {len(row)}')
    values = []
    for e, c in enumerate(order):
        cell = row[c].strip()
        column = 'time' if e == 0 else names[e - 1]
        if not _is_number(cell) or not math.isfinite(float(cell)):
            raise ConfigError(path, f'line {line}, column {column}',
                              f'expected a finite number, got {cell!r}')
        values.append(float(cell))
    return values


def write_trajectory_csv(path, times, angles_deg, joint_names, comment=''):
    """Write a trajectory CSV (angles in degrees) with a header row."""
    path = Path(path)
    with path.open('w', newline='', encoding='utf-8') as stream:
        for line in comment.splitlines():
            stream.write(f'# {line}\n')
        writer = csv.writer(stream, lineterminator='\n')
        writer.writerow(['time'] + list(joint_names))
        for t, row in zip(times, angles_deg):
            writer.writerow([f'{t:.4f}'] + [f'{a:.6f}' for a in row])


def _is_number(text):
    try:
        float(text)
    except ValueError:
        return False
    return True
