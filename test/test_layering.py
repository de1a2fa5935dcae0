# Copyright 2026 The i3dmgx2_driver Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Who may import whom: read from the sources with ast.

``test/`` and ``benchmarks/`` never import each other, neither by name nor
by putting the other's directory on ``sys.path``; what both need is in
``harness/`` (harness/__init__.py). ``harness/`` imports neither of them,
and the driver package imports none of the three.

Inside the package, imports run down the layers (codec → device,
simulator, capture → ros, tools) and never in a circle: no module imports
one that imports it back, however far round, ``TYPE_CHECKING`` blocks and
imports inside functions included (a cycle hidden from the interpreter is
still two pieces that cannot be read or changed alone).
"""

import ast
from pathlib import Path
import sys

import pytest

REPO = Path(__file__).resolve().parents[1]
FOLDERS = ('test', 'benchmarks', 'harness', 'i3dmgx2_driver')
#: The folders each folder's modules must not reach.
FORBIDDEN = {
    'test': ('benchmarks',),
    'benchmarks': ('test',),
    'harness': ('test', 'benchmarks'),
    'i3dmgx2_driver': ('test', 'benchmarks', 'harness'),
}


def sources(folder: str) -> list[Path]:
    """Return the Python files under ``folder``."""
    return sorted(p for p in (REPO / folder).rglob('*.py') if '__pycache__' not in p.parts)


def module_names(folder: str) -> set[str]:
    """Return the names a file of ``folder`` is imported by when the folder is on sys.path."""
    return {p.stem for p in (REPO / folder).glob('*.py')} - {'__init__'}


def imported_roots(tree: ast.AST) -> set[str]:
    """Return the first component of every absolute import, at any depth of the module."""
    roots = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split('.')[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split('.')[0])
    return roots


def _names_folder(node: ast.AST, folder: str) -> bool:
    """Whether an expression names ``folder`` as a path: a string that is it or ends in it."""
    return any(isinstance(n, ast.Constant) and isinstance(n.value, str)
               and (n.value.rstrip('/') == folder or n.value.rstrip('/').endswith('/' + folder))
               for n in ast.walk(node))


def path_insertions(tree: ast.AST) -> list[tuple[ast.Call, list[ast.AST]]]:
    """
    Return the calls that change ``sys.path`` (insert, append, extend), each with its sources.

    A call's sources are what its argument may come from: the call itself,
    the loops it is in (``for p in (REPO, REPO / 'test'): sys.path.insert(0,
    p)``), and the assignments to the names it uses.
    """
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    assigned: dict[str, list[ast.AST]] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign):
            for target in node.targets:
                for name in ast.walk(target):
                    if isinstance(name, ast.Name):
                        assigned.setdefault(name.id, []).append(node.value)
    calls = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr in ('insert', 'append', 'extend')
                and isinstance(node.func.value, ast.Attribute)
                and node.func.value.attr == 'path'
                and isinstance(node.func.value.value, ast.Name)
                and node.func.value.value.id == 'sys'):
            found: list[ast.AST] = [node]
            parent = parents.get(node)
            while parent is not None:
                if isinstance(parent, ast.For):
                    found.append(parent.iter)
                parent = parents.get(parent)
            for name in ast.walk(node):
                if isinstance(name, ast.Name):
                    found += assigned.get(name.id, [])
            calls.append((node, found))
    return sorted(calls, key=lambda item: item[0].lineno)


def violations(path: Path, forbidden: tuple[str, ...]) -> list[str]:
    """Return what in the file at ``path`` reaches a forbidden folder."""
    tree = ast.parse(path.read_text(), str(path))
    where = path.relative_to(REPO)
    found = []
    roots = imported_roots(tree)
    for folder in forbidden:
        reached = roots & ({folder} | module_names(folder))
        found += [f'{where} imports {name} (from {folder}/)' for name in sorted(reached)]
        found += [f'{where}:{call.lineno} puts {folder}/ on sys.path'
                  for call, froms in path_insertions(tree)
                  if any(_names_folder(source, folder) for source in froms)]
    return found


@pytest.mark.parametrize('folder', FOLDERS)
def test_folder_reaches_no_forbidden_folder(folder):
    found = [v for path in sources(folder) for v in violations(path, FORBIDDEN[folder])]
    assert not found, '\n'.join(found)


def test_the_check_sees_imports_and_path_insertions(tmp_path, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], 'REPO', tmp_path)
    for folder in ('test', 'benchmarks'):
        (tmp_path / folder).mkdir()
    (tmp_path / 'benchmarks' / 'bench_common.py').write_text('')
    (tmp_path / 'test' / 'ros_rig.py').write_text('')
    bad = tmp_path / 'test' / 'test_bad.py'
    bad.write_text('import sys\n'
                   'from pathlib import Path\n'
                   "sys.path.insert(0, str(Path(__file__).parents[1] / 'benchmarks'))\n"
                   'def f():\n'
                   '    from benchmarks.fuzz_parser import check_input\n'
                   '    import bench_common\n')
    assert violations(bad, ('benchmarks',)) == [
        'test/test_bad.py imports bench_common (from benchmarks/)',
        'test/test_bad.py imports benchmarks (from benchmarks/)',
        'test/test_bad.py:3 puts benchmarks/ on sys.path',
    ]
    also_bad = tmp_path / 'benchmarks' / 'x.py'
    also_bad.write_text('import os, sys\n'
                        "sys.path.append(os.path.join('..', 'test'))\n"
                        "for p in ('.', '../test'):\n"
                        '    sys.path.insert(0, p)\n'
                        "HERE = os.path.join('..', 'test')\n"
                        'sys.path.insert(0, HERE)\n'
                        "sys.path.insert(0, '../harness')\n"
                        'import ros_rig\n')
    assert violations(also_bad, ('test',)) == [
        'benchmarks/x.py imports ros_rig (from test/)',
        'benchmarks/x.py:2 puts test/ on sys.path',
        'benchmarks/x.py:4 puts test/ on sys.path',
        'benchmarks/x.py:6 puts test/ on sys.path',
    ]


PACKAGE = 'i3dmgx2_driver'
#: The rooms of the package each room may import (its own besides); ``''`` is the
#: package's ``__init__``, ``arguments`` the argument types every command line shares,
#: ``lifetime`` how every executable ends (signals, its parent's end, the deadline).
LAYERS = {
    'codec': (),
    '': (),
    'arguments': (),
    'lifetime': (),
    'device': ('codec',),
    'simulator': ('codec', 'arguments', 'lifetime'),
    'capture': ('codec', ''),
    'ros': ('codec', 'device', 'capture', 'lifetime', ''),
    # A tool that writes what the node publishes (replay --bag) or measures it in the node's
    # units (noise) takes the node's own conversions: ros never imports tools.
    'tools': ('codec', 'device', 'simulator', 'capture', 'ros', 'arguments', 'lifetime', ''),
}


def package_imports(root: Path = REPO / PACKAGE) -> dict[str, set[str]]:
    """Return each module of the package (dotted name) with the package modules it imports."""
    modules: dict[str, tuple[Path, bool]] = {}
    for path in sorted(root.rglob('*.py')):
        if '__pycache__' in path.parts:
            continue
        parts = list(path.relative_to(root.parent).with_suffix('').parts)
        is_package = parts[-1] == '__init__'
        modules['.'.join(parts[:-1] if is_package else parts)] = (path, is_package)
    graph = {}
    for name, (path, is_package) in modules.items():
        here = name.split('.') if is_package else name.split('.')[:-1]
        found = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here[:len(here) - (node.level - 1)]
                    target = '.'.join(base + (node.module.split('.') if node.module else []))
                else:
                    target = node.module or ''
                if target in modules:
                    found.update(f'{target}.{alias.name}' if f'{target}.{alias.name}' in modules
                                 else target for alias in node.names)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names if alias.name in modules)
        graph[name] = found - {name}
    return graph


def room(module: str) -> str:
    """Return the room of a package module: its subpackage, or '' for the package itself."""
    parts = module.split('.')
    return parts[1] if len(parts) > 1 else ''


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """Return every import of a room the importing room may not reach."""
    return sorted(f'{module} imports {target}' for module, targets in graph.items()
                  for target in targets
                  if room(target) != room(module) and room(target) not in LAYERS[room(module)])


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Return the groups of modules that import each other, however far round (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for target in sorted(graph.get(module, ())):
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in on_stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            group = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                group.append(member)
                if member == module:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return found


def test_every_room_of_the_package_has_a_layer():
    rooms = {room(module) for module in package_imports()}
    assert rooms <= set(LAYERS), f'rooms with no layer: {sorted(rooms - set(LAYERS))}'


def test_package_imports_run_down_the_layers():
    assert not upward_imports(package_imports())


def test_no_module_of_the_package_imports_one_that_imports_it_back():
    assert circles(package_imports()) == []


def test_the_checks_see_a_hidden_circle_and_an_upward_import(tmp_path):
    package = tmp_path / PACKAGE
    (package / 'device').mkdir(parents=True)
    (package / 'ros').mkdir()
    for init in (package, package / 'device', package / 'ros'):
        (init / '__init__.py').write_text('')
    (package / 'device' / 'reader.py').write_text(
        'from typing import TYPE_CHECKING\n'
        'if TYPE_CHECKING:\n'
        '    from .exchange import Exchange\n')
    (package / 'device' / 'exchange.py').write_text('from . import reader\n')
    (package / 'device' / 'uses_ros.py').write_text(
        'def f():\n'
        '    from ..ros.node import Node\n')
    (package / 'ros' / 'node.py').write_text('from ..device.reader import x\n')
    graph = package_imports(package)
    assert circles(graph) == [[f'{PACKAGE}.device.exchange', f'{PACKAGE}.device.reader']]
    assert upward_imports(graph) == [f'{PACKAGE}.device.uses_ros imports {PACKAGE}.ros.node']
