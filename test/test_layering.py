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
Who may import whom, outside the driver package: read from the sources with ast.

``test/`` and ``benchmarks/`` never import each other, neither by name nor
by putting the other's directory on ``sys.path``; what both need is in
``harness/`` (harness/__init__.py). ``harness/`` imports neither of them,
and the driver package imports none of the three.
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
