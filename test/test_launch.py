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
The launch file, read as code: ``launch`` is not on PyPI, so it cannot run here.

What can be checked without it is checked: it compiles, declares the
arguments the README documents (``address`` without a default), starts the
``node`` executable of this package, passes the installed params file and
puts the node under the ``namespace`` argument.
"""

import ast
import os

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCH = os.path.join(REPO, 'launch', 'i3dmgx2.launch.py')


def calls(tree: ast.AST, name: str) -> list:
    """Return every call of ``name`` in the tree."""
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call)
            and getattr(node.func, 'id', getattr(node.func, 'attr', None)) == name]


def keywords(call: ast.Call) -> dict:
    """Return a call's keyword arguments that are constants, by name."""
    return {k.arg: k.value.value for k in call.keywords if isinstance(k.value, ast.Constant)}


def test_launch_file_declares_the_documented_arguments():
    with open(LAUNCH) as handle:
        tree = ast.parse(handle.read(), LAUNCH)
    compile(tree, LAUNCH, 'exec')
    declared = {c.args[0].value: keywords(c) for c in calls(tree, 'DeclareLaunchArgument')}
    assert set(declared) == {'port', 'address', 'namespace', 'params_file'}
    assert 'default_value' not in declared['address'], 'address must have no default'
    assert declared['port']['default_value'] == '/dev/ttyUSB0'
    generate = [f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)]
    assert [f.name for f in generate] == ['generate_launch_description']


def test_launch_file_starts_this_packages_node_with_the_params_file():
    with open(LAUNCH) as handle:
        source = handle.read()
    tree = ast.parse(source)
    (node,) = calls(tree, 'Node')
    assert keywords(node) == {'package': 'i3dmgx2_driver', 'executable': 'node',
                              'name': 'i3dmgx2_driver', 'output': 'screen',
                              'emulate_tty': True}
    assert "LaunchConfiguration('namespace')" in ast.get_source_segment(source, node)
    assert "'config', 'i3dmgx2.yaml'" in source
    assert os.path.exists(os.path.join(REPO, 'config', 'i3dmgx2.yaml'))
