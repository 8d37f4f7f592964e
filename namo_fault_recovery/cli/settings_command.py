"""
``namo-recovery settings``: the files that list the settings, written from their declaration.

``config/recovery_node.yaml``, the README's parameter table and the one of
``msg_docs/interfaces.md`` are generated from
:data:`~namo_fault_recovery.recovery.settings.SETTINGS`: ``--yaml``, ``--markdown`` and
``--reference`` print them, ``--write`` rewrites them in a source tree and ``--check``
says which one is out of date (``test/test_settings.py`` runs it).  The tables sit
between two HTML comments in their Markdown file; the text around them is kept.
"""

from pathlib import Path
import re
import textwrap

from .common import UsageError

SOURCE_ROOT = Path(__file__).resolve().parents[2]
YAML_FILE = Path('config') / 'recovery_node.yaml'
README_FILE = Path('README.md')
REFERENCE_FILE = Path('msg_docs') / 'interfaces.md'
BEGIN = '<!-- parameters: written by `namo-recovery settings --write` from ' \
        'namo_fault_recovery/recovery/settings.py; edit them there -->'
END = '<!-- end of parameters -->'
ROS_TYPES = {str: 'string', float: 'double', int: 'int', bool: 'bool'}
YAML_HEADER = """\
# Parameter defaults of recovery_node (namo_fault_recovery).
#
#   ros2 run namo_fault_recovery recovery_node --ros-args --params-file <this file>
#   recovery_node --ros-args --params-file config/recovery_node.yaml -p deadline_sec:=0.5
#
# Angles on every ROS interface are radians; times are seconds.  Doubles must be written
# with a decimal point (1.0, not 1), as ROS 2 parameters are typed.
#
# Written by `namo-recovery settings --write` from the declaration in
# namo_fault_recovery/recovery/settings.py: edit the settings there, not here.
/**:
  ros__parameters:
"""


def _settings():
    from ..recovery.settings import SETTINGS
    return SETTINGS


def yaml_value(value):
    """Return ``value`` as a YAML scalar (strings quoted unless plain words)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (int, float)):
        return repr(value)
    return value if re.fullmatch(r'[A-Za-z_][A-Za-z0-9_]*', value) else f"'{value}'"


def _sentence(text):
    text = text[0].upper() + text[1:]
    return text if text.endswith('.') else text + '.'


def _range(s):
    return ' .. '.join(f'{v:g}' if isinstance(v, float) else str(v) for v in s.limits)


def yaml_comment(s):
    """Return the comment lines above a setting in the YAML file."""
    parts = [_sentence(s.doc)]
    if s.unit:
        parts.append(f'Unit: {s.unit}.')
    if s.limits is not None:
        parts.append(f'Range {_range(s)}.')
    if s.choices is not None:
        parts.append('One of: ' + ', '.join(s.choices) + '.')
    if s.read_only:
        parts.append('Read-only.')
    return textwrap.wrap('  '.join(parts), 86)


def render_yaml():
    """Return ``config/recovery_node.yaml``: every parameter, its comment and default."""
    lines, group = [], None
    for s in _settings():
        prefix, _, key = s.name.rpartition('.')
        indent = '    ' + ('  ' if prefix else '')
        if prefix != group and prefix:
            lines += ['', f'    {prefix}:']
        elif not (prefix and prefix == group):
            lines.append('')
        group = prefix
        lines += [f'{indent}# {line}' for line in yaml_comment(s)]
        lines.append(f'{indent}{key}: {yaml_value(s.default)}')
    return YAML_HEADER + '\n'.join(lines[1:]) + '\n'


def _md_value(value, code=False):
    if isinstance(value, str):
        return f'`{value}`' if value else "`''`"
    return f'`{yaml_value(value)}`' if code else yaml_value(value)


def render_markdown():
    """Return the README's table: every parameter, its default and what it is."""
    rows = ['| name | default | meaning |', '|------|---------|---------|']
    for s in _settings():
        unit = f' {s.unit}' if s.unit else ''
        rows.append(f'| `{s.name}` | {_md_value(s.default)}{unit} | {s.doc}'
                    + ('; read-only' if s.read_only else '') + ' |')
    return '\n'.join(rows) + '\n'


def render_reference():
    """Return the table of ``msg_docs/interfaces.md``: types, constraints and meanings."""
    rows = ['| name | type, default | constraint | meaning |',
            '|------|---------------|------------|---------|']
    for s in _settings():
        constraint = []
        if s.limits is not None:
            constraint.append(_range(s).replace('..', '…') + (f' {s.unit}' if s.unit else ''))
        elif s.unit:
            constraint.append(s.unit)
        if s.choices is not None:
            constraint.append(', '.join(f'`{c}`' for c in s.choices))
        constraint += [flag for flag, on in (('read-only', s.read_only), ('rerun', s.rerun))
                       if on]
        default = _md_value(s.default, code=True)
        rows.append(f'| `{s.name}` | {ROS_TYPES[s.value_type]}, {default} | '
                    f'{"; ".join(constraint)} | {s.doc} |')
    return '\n'.join(rows) + '\n'


def spliced(text, table, path):
    """Return ``text`` with the part between the two markers replaced by ``table``."""
    if text.count(BEGIN) != 1 or text.count(END) != 1:
        raise UsageError(f'{path}: expected one {BEGIN!r} and one {END!r} line')
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f'{head}{BEGIN}\n{table}{END}{tail}'


def generated(root):
    """Return ``{path: the text it should hold}`` for the three files under ``root``."""
    root = Path(root)
    files = {root / YAML_FILE: render_yaml()}
    for name, table in ((README_FILE, render_markdown()),
                        (REFERENCE_FILE, render_reference())):
        path = root / name
        files[path] = spliced(path.read_text(encoding='utf-8'), table, path)
    return files


def stale(root):
    """Return the files under ``root`` that differ from what the declaration gives."""
    return [path for path, text in generated(root).items()
            if not path.exists() or path.read_text(encoding='utf-8') != text]


def cmd_settings(args, out):
    """Print or write the settings' files; with --check, exit 1 if one is out of date."""
    root = Path(args.root)
    if args.write:
        for path, text in generated(root).items():
            if not path.exists() or path.read_text(encoding='utf-8') != text:
                path.write_text(text, encoding='utf-8')
                out.write(f'wrote {path}\n')
        return 0
    if args.check:
        behind = stale(root)
        for path in behind:
            out.write(f'{path}: out of date; run namo-recovery settings --write\n')
        return 1 if behind else 0
    render = {'yaml': render_yaml, 'markdown': render_markdown,
              'reference': render_reference}[args.format]
    out.write(render())
    return 0


def register(sub):
    """Add ``settings``."""
    p = sub.add_parser('settings', help='print or write the files that list the settings')
    what = p.add_mutually_exclusive_group()
    for name, text in (('yaml', 'config/recovery_node.yaml'),
                       ('markdown', "the README's parameter table"),
                       ('reference', "msg_docs/interfaces.md's parameter table")):
        what.add_argument(f'--{name}', dest='format', action='store_const', const=name,
                          help=f'print {text} (the default: --yaml)')
    what.add_argument('--write', action='store_true',
                      help='rewrite the three files under --root')
    what.add_argument('--check', action='store_true',
                      help='exit 1 naming each of the three files that is out of date')
    p.add_argument('--root', default=str(SOURCE_ROOT), metavar='DIR',
                   help=f'the source tree (default {SOURCE_ROOT})')
    p.set_defaults(func=cmd_settings, format='yaml')
    return p
