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
package.xml names everything the installed package runs with, and no more.

``rosdep install`` on a ROS machine installs what package.xml says and
nothing else, so every module the installed code imports (the package and
the launch file, read as code) must map to an ``exec_depend``: a ROS package
of the same name, or the rosdep key of a Python library. The one exception
is an optional extra (matplotlib, for the plot tool only: on a robot it
would pull in a GUI stack), which is no ``exec_depend`` and is imported
only inside the functions that draw, never when a module loads.
"""

import ast
import os
import sys
from xml.etree import ElementTree

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: rosdep keys of the Python libraries imported under another name.
ROSDEP_KEYS = {'serial': 'python3-serial', 'numpy': 'python3-numpy',
               'matplotlib': 'python3-matplotlib'}
#: Needed at run time without an import of our own: rclpy.lifecycle loads it.
RUNTIME_ONLY = {'lifecycle_msgs'}
#: Optional extras (setup.py's extras_require): imported only where they are used.
OPTIONAL = {'matplotlib': 'plot', 'rosbags': 'bag'}


def installed_sources() -> list[str]:
    """Every .py file colcon installs: the package and the launch files."""
    paths = []
    for top in ('i3dmgx2_driver', 'launch'):
        for folder, _, files in os.walk(os.path.join(REPO, top)):
            paths += [os.path.join(folder, f) for f in files if f.endswith('.py')]
    return paths


def imported_roots(path: str) -> set[str]:
    """Top-level names of the absolute imports in ``path``."""
    with open(path) as handle:
        tree = ast.parse(handle.read(), path)
    roots = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots |= {alias.name.split('.')[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            roots.add(node.module.split('.')[0])
    return roots


def load_time_roots(path: str) -> set[str]:
    """Top-level names imported when ``path`` loads (outside any function)."""
    with open(path) as handle:
        tree = ast.parse(handle.read(), path)
    roots = set()
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        if isinstance(node, ast.Import):
            roots |= {alias.name.split('.')[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            roots.add(node.module.split('.')[0])
        stack.extend(ast.iter_child_nodes(node))
    return roots


def exec_depends() -> set[str]:
    root = ElementTree.parse(os.path.join(REPO, 'package.xml')).getroot()
    return {e.text.strip() for e in root.iter() if e.tag in ('exec_depend', 'depend')}


def test_every_import_of_the_installed_package_is_an_exec_depend():
    needed = {}
    for path in installed_sources():
        for root in imported_roots(path):
            if root in sys.stdlib_module_names or root in ('i3dmgx2_driver', *OPTIONAL):
                continue
            needed.setdefault(ROSDEP_KEYS.get(root, root), os.path.relpath(path, REPO))
    for key in RUNTIME_ONLY:
        needed.setdefault(key, 'run time')
    missing = {key: where for key, where in needed.items() if key not in exec_depends()}
    assert missing == {}, f'imported but not in package.xml: {missing}'


def test_the_launch_files_and_the_managed_node_dependencies_are_named():
    depends = exec_depends()
    assert {'launch', 'launch_ros', 'ament_index_python', 'lifecycle_msgs'} <= depends


def test_optional_extras_are_no_exec_depend_and_load_with_no_module():
    depends = exec_depends()
    for root in OPTIONAL:
        assert ROSDEP_KEYS.get(root, root) not in depends, \
            f'{root} is optional: a robot that runs the node must not install it'
    loaded = {os.path.relpath(path, REPO): load_time_roots(path) & set(OPTIONAL)
              for path in installed_sources()}
    assert {path: roots for path, roots in loaded.items() if roots} == {}, \
        'import an optional extra inside the function that uses it (tools/figures.py)'


def setup_arguments(monkeypatch) -> dict:
    """Return what setup.py passes to ``setup()``."""
    import runpy

    import setuptools
    captured = {}
    monkeypatch.setattr(setuptools, 'setup', lambda **kwargs: captured.update(kwargs))
    monkeypatch.chdir(REPO)
    runpy.run_path(os.path.join(REPO, 'setup.py'))
    return captured


def test_setup_offers_the_optional_extras(monkeypatch):
    extras = setup_arguments(monkeypatch).get('extras_require', {})
    for root, extra in OPTIONAL.items():
        assert root in extras.get(extra, []), f'setup.py: extras_require[{extra!r}]'


# catkin_pkg's parser still calls docutils' traverse(), which docutils 0.22 deprecates.
@pytest.mark.filterwarnings('ignore:nodes.Node.traverse:DeprecationWarning')
def test_package_xml_setup_py_and_the_changelog_name_one_version(monkeypatch):
    """
    A release takes its version from package.xml, its Debian changelog from CHANGELOG.rst.

    bloom warns when the changelog has no section for that version, and stops
    when its newest section is another; setup.py's version is what pip and the
    installed metadata say. The file is in the
    form ``catkin_generate_changelog`` writes and ``catkin_prepare_release``
    stamps (the headlines below are catkin_pkg's own), which bloom parses.
    """
    from catkin_pkg.changelog import get_changelog_from_path
    from catkin_pkg.changelog_generator import generate_package_headline, \
        generate_version_headline

    root = ElementTree.parse(os.path.join(REPO, 'package.xml')).getroot()
    version = root.findtext('version')
    assert setup_arguments(monkeypatch)['version'] == version, 'setup.py and package.xml'
    path = os.path.join(REPO, 'CHANGELOG.rst')
    changelog = get_changelog_from_path(path, root.findtext('name'))
    newest, date, _ = next(iter(changelog.foreach_version()))
    assert newest == version, f'CHANGELOG.rst starts at {newest}, package.xml says {version}'
    with open(path) as handle:
        text = handle.read()
    top = generate_package_headline(root.findtext('name')) + '\n' + generate_version_headline(
        version, date.strftime('%Y-%m-%d'))
    assert text.startswith(top), f'CHANGELOG.rst does not start with:\n{top}'
