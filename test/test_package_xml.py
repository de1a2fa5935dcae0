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
package.xml names everything the installed package runs with.

``rosdep install`` on a ROS machine installs what package.xml says and
nothing else, so every module the installed code imports (the package and
the launch file, read as code) must map to an ``exec_depend``: a ROS package
of the same name, or the rosdep key of a Python library.
"""

import ast
import os
import sys
from xml.etree import ElementTree

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: rosdep keys of the Python libraries imported under another name.
ROSDEP_KEYS = {'serial': 'python3-serial', 'numpy': 'python3-numpy',
               'matplotlib': 'python3-matplotlib'}
#: Needed at run time without an import of our own: rclpy.lifecycle loads it.
RUNTIME_ONLY = {'lifecycle_msgs'}


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


def exec_depends() -> set[str]:
    root = ElementTree.parse(os.path.join(REPO, 'package.xml')).getroot()
    return {e.text.strip() for e in root.iter() if e.tag in ('exec_depend', 'depend')}


def test_every_import_of_the_installed_package_is_an_exec_depend():
    needed = {}
    for path in installed_sources():
        for root in imported_roots(path):
            if root in sys.stdlib_module_names or root == 'i3dmgx2_driver':
                continue
            needed.setdefault(ROSDEP_KEYS.get(root, root), os.path.relpath(path, REPO))
    for key in RUNTIME_ONLY:
        needed.setdefault(key, 'run time')
    missing = {key: where for key, where in needed.items() if key not in exec_depends()}
    assert missing == {}, f'imported but not in package.xml: {missing}'


def test_the_launch_files_and_the_managed_node_dependencies_are_named():
    depends = exec_depends()
    assert {'launch', 'launch_ros', 'ament_index_python', 'lifecycle_msgs'} <= depends
