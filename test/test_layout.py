"""
The package's layout rules, checked on the source with ``ast`` (fast, no ROS needed).

- every import of our modules (in the package and in the tests) names a module or
  name that exists, and the import graph has no cycle (module-level and
  function-level imports alike, relative ones resolved);
- no module uses a ``_private`` name of another of our modules;
- only modules under ``ros/`` import rclpy or a message package, and nothing the
  offline commands load at import time reaches them;
- no module imports a module of a higher layer (:data:`LAYERS`: the numerical core
  below the node's runtime, below ROS, below the benchmarks and the command line);
- every subpackage's ``__init__`` docstring names each of its modules.
"""

import ast
from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = 'namo_fault_recovery'
ROS_PACKAGES = ('rclpy', 'rcl_interfaces', 'builtin_interfaces')
ROS_SUFFIXES = ('_msgs', '_srvs')
OFFLINE_ENTRY = f'{PACKAGE}.cli.main'
# Executables in ros/ that reach rclpy only through other ros/ modules, imported late:
# recovery_node installs its signal handlers before anything imports rclpy.
ROS_ENTRY_POINTS = {f'{PACKAGE}.ros.recovery_node'}
# The subpackages (and root modules) from the bottom up; a module may import its own
# layer and those below it, never one above.  One tuple is one layer.
LAYERS = (
    ('errors', 'resources', 'files'),
    ('model',),
    ('objective',),
    ('optimize',),
    ('recovery',),
    ('sim', 'playback', 'explore'),
    ('runtime',),
    ('ros',),
    ('benchmarks',),
    ('cli',),
)
# Known findings, per check.  A ratchet, not a waiver: each test fails on a finding not
# listed here AND on a listed one that is gone, so fixing one means deleting its line.
KNOWN_FINDINGS = {
    'private': set(),
    'docstring': set(),
    'ros': set(),           # ROS imports outside ros/ (module: what it imports)
    'upward': set(),        # upward arrows (importer -> imported)
}


def assert_only_known(kind, found, scope=''):
    """
    Fail on a finding that is not known, and on a known one that is fixed.

    ``found`` maps findings to where they are; ``scope`` limits the known ones to those
    starting with it (one subpackage).
    """
    known = {k for k in KNOWN_FINDINGS[kind] if k.startswith(scope + ':' if scope else '')}
    new = sorted(set(found) - known)
    fixed = sorted(known - set(found))
    assert not new, f'{kind} findings:\n' + '\n'.join(f'{k} ({found[k]})' for k in new)
    assert not fixed, (f'fixed, delete from KNOWN_FINDINGS[{kind!r}]:\n'
                       + '\n'.join(fixed))


def _module_name(path):
    parts = list(path.relative_to(ROOT).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def _modules():
    """Return {module name: (path, ast tree)} for every module of the package."""
    return {_module_name(p): (p, ast.parse(p.read_text(), str(p)))
            for p in sorted((ROOT / PACKAGE).rglob('*.py'))}


MODULES = _modules()


class Import:
    """One import statement's effect: the module it loads and the names it takes."""

    def __init__(self, source, target, names, line, module_level):
        self.source, self.target, self.names = source, target, names
        self.line, self.module_level = line, module_level

    def __repr__(self):
        where = 'module level' if self.module_level else 'in a function'
        return f'{self.source}:{self.line} imports {self.target} ({where})'


def _resolve(source, node):
    """Return the absolute module name of a ``from ... import`` (relative resolved)."""
    if not node.level:
        return node.module
    path = MODULES[source][0]
    package = source if path.name == '__init__.py' else source.rpartition('.')[0]
    base = package.split('.')
    if node.level > 1:
        base = base[:-(node.level - 1)]
    return '.'.join(base + ([node.module] if node.module else []))


def _imports(source):
    """Return every import of one module, each with its targets resolved."""
    tree = MODULES[source][1]
    top = {id(n) for n in tree.body}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.append(Import(source, alias.name, (), node.lineno, id(node) in top))
        elif isinstance(node, ast.ImportFrom):
            module = _resolve(source, node)
            for alias in node.names:
                # `from pkg import sub` loads the submodule pkg.sub if there is one.
                sub = f'{module}.{alias.name}'
                if sub in MODULES:
                    found.append(Import(source, sub, (), node.lineno, id(node) in top))
                else:
                    found.append(Import(source, module, (alias.name,), node.lineno,
                                        id(node) in top))
    return found


IMPORTS = {name: _imports(name) for name in MODULES}


def _ours(target):
    return target in MODULES


def find_cycle(edges):
    """Return one cycle of the directed graph ``edges`` as a list of nodes, or None."""
    state, stack = {}, []

    def visit(node):
        state[node] = 'open'
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 'open':
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        state[node] = 'done'
        stack.pop()
        return None
    for node in sorted(edges):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def _graph(module_level_only=False):
    edges = {}
    for source, imports in IMPORTS.items():
        for imp in imports:
            if _ours(imp.target) and imp.target != source and (
                    imp.module_level or not module_level_only):
                edges.setdefault(source, set()).add(imp.target)
    return edges


def test_the_checker_finds_a_cycle_and_resolves_relative_imports():
    assert find_cycle({'a': {'b'}, 'b': {'c'}, 'c': {'a'}}) == ['a', 'b', 'c', 'a']
    assert find_cycle({'a': {'b'}, 'b': {'c'}, 'c': set()}) is None
    targets = {imp.target for imp in IMPORTS[f'{PACKAGE}.cli.main']}
    assert f'{PACKAGE}.model.kinematics' in targets     # from ..model.kinematics import ...
    assert f'{PACKAGE}.cli.node_commands' in targets    # from . import node_commands
    levels = {imp.module_level for imp in IMPORTS[f'{PACKAGE}.cli.main']}
    assert levels == {True, False}                      # both kinds are counted


def _defined_names(module):
    """Return the names bound at module level (None: a module __getattr__ makes any)."""
    names = set()
    for node in MODULES[module][1].body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            if node.name == '__getattr__':
                return None
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).partition('.')[0] for a in node.names}
        elif isinstance(node, (ast.If, ast.Try)):
            names |= {n.id for n in ast.walk(node)
                      if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
    return names


def _test_imports():
    """Return the imports of our package made by the test modules (absolute ones)."""
    found = []
    for path in sorted((ROOT / 'test').glob('*.py')):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom) and not node.level:
                for alias in node.names:
                    sub = f'{node.module}.{alias.name}'
                    target, names = (sub, ()) if sub in MODULES else (node.module, (alias.name,))
                    found.append(Import(f'test/{path.name}', target, names, node.lineno, True))
            elif isinstance(node, ast.Import):
                found += [Import(f'test/{path.name}', a.name, (), node.lineno, True)
                          for a in node.names]
    return found


def test_every_import_of_our_modules_resolves():
    broken = []
    for imports in list(IMPORTS.values()) + [_test_imports()]:
        for imp in imports:
            if not imp.target.startswith(PACKAGE):
                continue
            if imp.target not in MODULES:
                broken.append(f'{imp!r}: no such module')
                continue
            defined = _defined_names(imp.target)
            missing = [n for n in imp.names if defined is not None and n not in defined]
            if missing:
                broken.append(f'{imp!r}: no {missing}')
    assert not broken, 'imports that fail at run time:\n' + '\n'.join(broken)


def test_the_import_graph_has_no_cycle():
    cycle = find_cycle(_graph())
    assert cycle is None, 'import cycle: ' + ' -> '.join(cycle)


def _private_uses():
    """Yield (module, line, what) for every use of another module's _private name."""
    for source, imports in IMPORTS.items():
        aliases = {}
        for imp in imports:
            if not _ours(imp.target) or imp.target == source:
                continue
            for name in imp.names:
                if name.startswith('_') and not name.startswith('__'):
                    yield source, imp.line, f'imports {name} from {imp.target}'
            if imp.target.rpartition('.')[2].startswith('_') and not imp.target.endswith('__'):
                yield source, imp.line, f'imports the private module {imp.target}'
        # `from . import messages as conv` then `conv._thing`: private by attribute.
        tree = MODULES[source][1]
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                pairs = [(a.asname or a.name, a.name) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                module = _resolve(source, node)
                pairs = [(a.asname or a.name, f'{module}.{a.name}') for a in node.names]
            else:
                continue
            aliases.update((alias, target) for alias, target in pairs
                           if _ours(target) and target != source)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith('_')
                    and not node.attr.startswith('__')):
                yield source, node.lineno, f'uses {node.value.id}.{node.attr}'


def test_no_module_uses_a_private_name_of_another():
    found = {f'{source} {what}': f'line {line}' for source, line, what in _private_uses()}
    assert_only_known('private', found)


def _is_ros(target):
    top = target.partition('.')[0]
    return top in ROS_PACKAGES or top.endswith(ROS_SUFFIXES)


def _in_ros(module):
    return module == f'{PACKAGE}.ros' or module.startswith(f'{PACKAGE}.ros.')


def _ros_imports_outside_ros():
    """Return {'module: imported ROS module': where} for every ROS import outside ros/."""
    return {f'{source}: {imp.target}': f'line {imp.line}'
            for source, imports in IMPORTS.items() if not _in_ros(source)
            for imp in imports if _is_ros(imp.target)}


def _imports_ros(module):
    return any(_is_ros(imp.target) for imp in IMPORTS[module])


def _may_use_ros(module):
    return _in_ros(module) or _imports_ros(module)


def test_only_ros_imports_ros():
    assert_only_known('ros', _ros_imports_outside_ros())


def _uses_ros(module):
    """Return True if ``module`` imports ROS, or is an entry point importing a module that does."""
    if _imports_ros(module):
        return True
    return module in ROS_ENTRY_POINTS and any(
        _in_ros(imp.target) and _imports_ros(imp.target) for imp in IMPORTS[module])


def test_ros_holds_only_modules_that_import_ros():
    free = sorted(m for m in MODULES if _in_ros(m) and m != f'{PACKAGE}.ros'
                  and not _uses_ros(m))
    assert not free, f'modules in ros/ that import nothing from ROS (runtime/?): {free}'


def test_the_offline_commands_do_not_load_ros_at_import_time():
    edges = _graph(module_level_only=True)
    reached, todo = set(), [OFFLINE_ENTRY]
    while todo:
        module = todo.pop()
        if module not in reached:
            reached.add(module)
            todo += sorted(edges.get(module, ()))
    ros_side = sorted(m for m in reached if _may_use_ros(m))
    assert not ros_side, f'{OFFLINE_ENTRY} loads at import time: {ros_side}'


def test_show_score_and_solve_run_without_importing_ros():
    script = (
        'import io, sys\n'
        'from namo_fault_recovery.cli.main import main\n'
        "for argv in (['show'], ['score', '--gesture', 'wai', '--right'] + ['0'] * 7,\n"
        "             ['solve', '--fault', 'right_arm_joint2', '--gesture', 'wai',\n"
        "              '--deadline', '0.05', '--seed', '0']):\n"
        '    assert main(argv, io.StringIO()) == 0, argv\n'
        "ros = sorted(m for m in sys.modules if m.split('.')[0] in "
        f'{ROS_PACKAGES!r} or m.split(".")[0].endswith({ROS_SUFFIXES!r}))\n'
        'print(ros)\n')
    proc = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == '[]', proc.stdout


def layer(module):
    """Return the index in LAYERS of the subpackage (or root module) of ``module``."""
    parts = module.split('.')
    name = parts[1] if len(parts) > 1 else None
    for index, members in enumerate(LAYERS):
        if name in members:
            return index
    raise KeyError(f'{module}: its subpackage {name!r} is in no layer of LAYERS')


def _upward_arrows():
    """Return {'importer -> imported': where} for every import of a higher layer."""
    return {f'{imp.source} -> {imp.target}': f'line {imp.line}'
            for source, imports in IMPORTS.items() if source != PACKAGE
            for imp in imports
            if _ours(imp.target) and imp.target != PACKAGE
            and layer(imp.target) > layer(source)}


def test_every_subpackage_has_a_layer():
    for module in MODULES:
        if module != PACKAGE:
            layer(module)
    with pytest.raises(KeyError):
        layer(f'{PACKAGE}.nowhere.module')
    assert layer(f'{PACKAGE}.model.gestures') < layer(f'{PACKAGE}.objective.score')
    assert layer(f'{PACKAGE}.sim.physics') == layer(f'{PACKAGE}.playback.timing')


def test_no_arrow_runs_up_between_subpackages():
    assert_only_known('upward', _upward_arrows())


SUBPACKAGES = sorted(name for name, (path, _) in MODULES.items()
                     if path.name == '__init__.py' and name != PACKAGE)


@pytest.mark.parametrize('package', SUBPACKAGES)
def test_every_subpackage_docstring_names_its_modules(package):
    path, tree = MODULES[package]
    doc = ast.get_docstring(tree)
    assert doc, f'{path} has no docstring'
    modules = sorted(p.stem for p in path.parent.glob('*.py') if p.name != '__init__.py')
    missing = {f'{package}: {m}': 'the docstring' for m in modules
               if f':mod:`.{m}`' not in doc}
    assert_only_known('docstring', missing, package)


# --- one result type -------------------------------------------------------------------

RESULT_MODULE = f'{PACKAGE}.recovery.result'
RESULT_TYPES = ('GestureResult', 'LibraryResult')
# A class repeats a result type when at least this many of its fields are fields of that
# type and they are most of its fields (OptimizeResult, scipy-shaped, shares only half).
RESULT_COPY_MIN = 5


def _class_fields(node):
    """Return the field names of a class: its annotated class attributes and ``self.x``."""
    names = {s.target.id for s in node.body
             if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)}
    for sub in ast.walk(node):
        targets = (sub.targets if isinstance(sub, ast.Assign)
                   else [sub.target] if isinstance(sub, (ast.AnnAssign, ast.AugAssign)) else [])
        for t in targets:
            for e in (t.elts if isinstance(t, ast.Tuple) else [t]):
                if (isinstance(e, ast.Attribute) and isinstance(e.value, ast.Name)
                        and e.value.id == 'self'):
                    names.add(e.attr)
    return names


def _classes(trees):
    """Yield ``(where, class node)`` for every class of ``trees`` ({name: (path, tree)})."""
    for name, (_, tree) in trees.items():
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                yield f'{name}.{node.name}', node


def result_copies(trees, result_tree):
    """Return ``{class: (result type, shared fields)}`` for classes that repeat a result."""
    results = {node.name: _class_fields(node) for node in ast.walk(result_tree)
               if isinstance(node, ast.ClassDef) and node.name in RESULT_TYPES}
    assert set(results) == set(RESULT_TYPES), f'{RESULT_MODULE}: {sorted(results)}'
    found = {}
    for where, node in _classes(trees):
        if where.startswith(RESULT_MODULE + '.'):
            continue
        own = _class_fields(node)
        for kind, fields in results.items():
            shared = own & fields
            if len(shared) >= RESULT_COPY_MIN and 2 * len(shared) > len(own):
                found[where] = (kind, sorted(shared))
    return found


def test_one_result_type():
    # Outside recovery/result.py no class repeats most of GestureResult's or
    # LibraryResult's fields: a wrapper holds a LibraryResult instead of copying it.
    tests = {p.stem: (p, ast.parse(p.read_text(), str(p)))
             for p in sorted((ROOT / 'test').glob('*.py'))}
    found = result_copies({**MODULES, **tests}, MODULES[RESULT_MODULE][1])
    assert not found, 'classes that copy a result type:\n' + '\n'.join(
        f'{where}: {kind} fields {", ".join(shared)}' for where, (kind, shared) in found.items())


def test_the_result_check_finds_a_copy():
    copy = ast.parse('from dataclasses import dataclass\n\n\n@dataclass\nclass Shape:\n'
                     '    name: str\n    score_before: float\n    score_after: float\n'
                     '    status: str\n    message: str\n    version: int\n\n\n'
                     'class Holder:\n    def __init__(self, result):\n'
                     '        self.result, self.version = result, 1\n')
    found = result_copies({'x': (None, copy)}, MODULES[RESULT_MODULE][1])
    assert list(found) == ['x.Shape'] and found['x.Shape'][0] == 'GestureResult'


# -- readable sizes ---------------------------------------------------------------------

MAX_FUNCTION_LINES = 60     # from the ``def`` line to the last line, docstring included
MAX_CLASS_LINES = 300
MAX_ARGUMENTS = 10          # parameters of one function, ``self`` and ``cls`` not counted
# Functions that are a data table (one literal, named once), exempt from the line limit.
DATA_TABLES = set()


def sizes(trees):
    """Yield (kind, 'module:qualified name', lines, arguments) for each def and class."""
    def walk(node, module, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f'{prefix}{child.name}'
                lines = child.end_lineno - child.lineno + 1
                if isinstance(child, ast.ClassDef):
                    yield 'class', f'{module}:{name}', lines, 0
                else:
                    args = child.args
                    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
                    count = len([n for n in names if n not in ('self', 'cls')])
                    yield 'function', f'{module}:{name}', lines, count
                yield from walk(child, module, f'{name}.')
    for module, tree in trees.items():
        yield from walk(tree, module, '')


def oversized(trees):
    """Return the defs and classes over the limits, as readable lines."""
    found = []
    for kind, name, lines, count in sizes(trees):
        if kind == 'class' and lines > MAX_CLASS_LINES:
            found.append(f'class {name}: {lines} lines (limit {MAX_CLASS_LINES})')
        if kind == 'function' and lines > MAX_FUNCTION_LINES and name not in DATA_TABLES:
            found.append(f'function {name}: {lines} lines (limit {MAX_FUNCTION_LINES})')
        if kind == 'function' and count > MAX_ARGUMENTS:
            found.append(f'function {name}: {count} arguments (limit {MAX_ARGUMENTS})')
    return sorted(found)


def _package_trees():
    return {name: ast.parse(path.read_text()) for name, (path, _) in MODULES.items()}


def test_functions_and_classes_stay_readable():
    found = oversized(_package_trees())
    assert not found, 'over the size limits:\n' + '\n'.join(found)


def test_the_size_check_finds_a_long_function_and_a_long_argument_list():
    body = '\n'.join(f'    x{i} = {i}' for i in range(MAX_FUNCTION_LINES))
    args = ', '.join(f'a{i}' for i in range(MAX_ARGUMENTS + 1))
    tree = ast.parse(f'def long():\n{body}\n\n\ndef wide({args}):\n    pass\n\n\n'
                     f'class Short:\n    def fine(self, a, b):\n        return a + b\n')
    found = oversized({'m': tree})
    assert found == [f'function m:long: {MAX_FUNCTION_LINES + 1} lines (limit '
                     f'{MAX_FUNCTION_LINES})',
                     f'function m:wide: {MAX_ARGUMENTS + 1} arguments (limit '
                     f'{MAX_ARGUMENTS})']
