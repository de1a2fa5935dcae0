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
``node`` executable of this package, or ``lifecycle_node`` with
``managed:=true``, passes the installed params file, puts the node under the
``namespace`` argument, and with ``autostart:=true`` configures the managed
node and activates it once configured. ``stream`` and ``data_rate`` reach
the node only when given (the parameter file decides otherwise), and as
substitutions, which launch_ros reads as YAML the way ``-p`` is read.
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


def parse() -> tuple[str, ast.AST]:
    with open(LAUNCH) as handle:
        source = handle.read()
    return source, ast.parse(source, LAUNCH)


def assigned(tree: ast.AST, name: str) -> ast.AST:
    """Return the value assigned to ``name`` (once) in the launch file."""
    (value,) = [n.value for n in ast.walk(tree) if isinstance(n, ast.Assign)
                and [getattr(t, 'id', None) for t in n.targets] == [name]]
    return value


def test_launch_file_declares_the_documented_arguments():
    source, tree = parse()
    compile(tree, LAUNCH, 'exec')
    declared = {c.args[0].value: keywords(c) for c in calls(tree, 'DeclareLaunchArgument')}
    assert set(declared) == {'port', 'address', 'namespace', 'params_file', 'managed',
                             'autostart', 'stream', 'data_rate'}
    assert 'default_value' not in declared['address'], 'address must have no default'
    assert declared['port']['default_value'] == '/dev/ttyUSB0'
    # The plain node unless asked; a managed node waits for its manager unless asked.
    assert declared['managed']['default_value'] == 'false'
    assert declared['autostart']['default_value'] == 'false'
    # Empty: as the parameter file says.
    assert declared['stream']['default_value'] == declared['data_rate']['default_value'] == ''
    functions = [f.name for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)]
    assert functions == ['optional_overrides', 'driver_actions', 'generate_launch_description']
    (opaque,) = calls(tree, 'OpaqueFunction')
    assert ast.get_source_segment(source, opaque) == 'OpaqueFunction(function=driver_actions)'


def test_launch_file_starts_this_packages_node_with_the_params_file():
    source, tree = parse()
    common = assigned(tree, 'common')
    assert {k.value: v.value for k, v in zip(common.keys, common.values, strict=True)
            if isinstance(v, ast.Constant)} == {
        'package': 'i3dmgx2_driver', 'name': 'i3dmgx2_driver', 'output': 'screen',
        'emulate_tty': True}
    common_text = ast.get_source_segment(source, common)
    assert "'namespace': LaunchConfiguration('namespace')" in common_text
    assert "LaunchConfiguration('params_file')" in common_text
    # After the params file, so that what is given wins.
    assert common_text.index("LaunchConfiguration('params_file')") < \
        common_text.index('optional_overrides(context)')
    assert "'config', 'i3dmgx2.yaml'" in source
    assert os.path.exists(os.path.join(REPO, 'config', 'i3dmgx2.yaml'))


def test_managed_option_chooses_the_lifecycle_node_instead_of_the_plain_one():
    source, tree = parse()
    assert ast.get_source_segment(source, assigned(tree, 'managed')) == \
        "LaunchConfiguration('managed')"
    (plain,) = calls(tree, 'Node')
    (managed,) = calls(tree, 'LifecycleNode')
    for call, executable, condition in ((plain, 'node', 'UnlessCondition(managed)'),
                                        (managed, 'lifecycle_node', 'IfCondition(managed)')):
        assert keywords(call) == {'executable': executable}
        text = ast.get_source_segment(source, call)
        assert f'condition={condition}' in text and '**common' in text
    # Both executables are console entry points colcon installs.
    with open(os.path.join(REPO, 'setup.py')) as handle:
        setup = handle.read()
    assert "'node = i3dmgx2_driver.ros.main:main'" in setup
    assert "'lifecycle_node = i3dmgx2_driver.ros.lifecycle_node:main'" in setup


def test_autostart_configures_then_activates_only_after_a_successful_configure():
    source, tree = parse()
    assert ast.get_source_segment(source, assigned(tree, 'autostart')) == \
        "IfCondition(AndSubstitution(managed, LaunchConfiguration('autostart')))"
    events = {ast.get_source_segment(source, c.keywords[1].value): c
              for c in calls(tree, 'ChangeState')}
    assert set(events) == {'Transition.TRANSITION_CONFIGURE',
                           'Transition.TRANSITION_ACTIVATE'}
    for call in events.values():
        assert ast.get_source_segment(source, call.keywords[0].value) == \
            'matches_action(managed_node)'
    (handler,) = calls(tree, 'OnStateTransition')
    assert keywords(handler) == {'start_state': 'configuring', 'goal_state': 'inactive'}
    handler_text = ast.get_source_segment(source, handler)
    assert 'TRANSITION_ACTIVATE' in handler_text and 'TRANSITION_CONFIGURE' not in handler_text
    for name in ('configure', 'activate_once_configured'):
        assert 'condition=autostart' in ast.get_source_segment(source, assigned(tree, name))


def _optional_overrides(arguments: dict) -> dict:
    """Run the launch file's optional_overrides with ``arguments`` as the command line."""
    _, tree = parse()
    (function,) = [f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)
                   and f.name == 'optional_overrides']
    optional = ast.Assign([ast.Name('OPTIONAL_PARAMETERS', ast.Store())],
                          assigned(tree, 'OPTIONAL_PARAMETERS'), lineno=0)

    class LaunchConfiguration:
        """Stands in for launch's: ``launch`` is not on PyPI."""

        def __init__(self, name: str) -> None:
            self.name = name

        def perform(self, context: object) -> str:
            return arguments[self.name]

    namespace = {'LaunchConfiguration': LaunchConfiguration, 'LaunchContext': object}
    module = ast.fix_missing_locations(ast.Module([optional, function], []))
    exec(compile(module, LAUNCH, 'exec'), namespace)
    assert namespace['OPTIONAL_PARAMETERS'] == ('stream', 'data_rate')
    return namespace['optional_overrides'](None)


def test_stream_and_rate_reach_the_node_only_when_given_and_as_substitutions():
    # Left out: nothing, so the parameter file's values stand.
    assert _optional_overrides({'stream': '', 'data_rate': ''}) == {}
    overrides = _optional_overrides({'stream': '0xC2', 'data_rate': ''})
    assert list(overrides) == ['stream']
    # A substitution (read as YAML by launch_ros, 0xC2 -> 194), not the text '0xC2'.
    assert not isinstance(overrides['stream'], str)
    assert overrides['stream'].name == 'stream'
    overrides = _optional_overrides({'stream': 'inertial', 'data_rate': '250'})
    assert sorted(overrides) == ['data_rate', 'stream']
    assert overrides['data_rate'].name == 'data_rate'
