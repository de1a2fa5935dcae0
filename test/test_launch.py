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
arguments the README documents (``address`` empty: the node requires it
unless ``addresses`` is given), starts the
``node`` executable of this package, or ``lifecycle_node`` with
``managed:=true``, passes the installed params file, puts the node under the
``namespace`` argument, and with ``autostart:=true`` configures the managed
node and activates it once configured. ``stream`` and ``data_rate`` reach
the node only when given (the parameter file decides otherwise), and as
substitutions, which launch_ros reads as YAML the way ``-p`` is read;
``frame_id`` likewise, as text. So do the several sensors' arguments
(``addresses``, ``sensor_names``, ``frame_ids``, ``streams``,
``data_rates``) and the calibration ones (``gyro_bias``,
``accel_bias``, ``calibration_file`` as text) and the fault capture's
(``fault_capture_dir``, ``fault_capture_seconds``, ``fault_captures_kept``),
each named as the node's parameter. ``node_name`` names the node and the topic arguments remap its
topics, so that two sensors run side by side: the
launch file's own functions are run with two command lines and nothing the
two nodes make may collide. The README's two-sensor launch file compiles and
passes only arguments this one declares.
"""

import ast
import os

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCH = os.path.join(REPO, 'launch', 'i3dmgx2.launch.py')


#: The launch arguments of several sensors and of the calibration: the node's parameters.
SEVERAL = ('addresses', 'sensor_names', 'frame_ids', 'streams', 'data_rates')
CALIBRATION = ('gyro_bias', 'accel_bias', 'calibration_file')
CAPTURE = ('fault_capture_dir', 'fault_capture_seconds', 'fault_captures_kept')


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
                             'autostart', 'stream', 'data_rate', 'node_name', 'frame_id',
                             'imu_topic', 'mag_topic', 'temperature_topic', *SEVERAL,
                             *CALIBRATION, *CAPTURE}
    # No address of its own: the node refuses to start unless one is given (or addresses).
    assert declared['address']['default_value'] == ''
    for name in (*SEVERAL, *CALIBRATION, *CAPTURE):
        assert declared[name]['default_value'] == '', name
    assert declared['port']['default_value'] == '/dev/ttyUSB0'
    # The plain node unless asked; a managed node waits for its manager unless asked.
    assert declared['managed']['default_value'] == 'false'
    assert declared['autostart']['default_value'] == 'false'
    # Empty: as the parameter file says.
    assert declared['stream']['default_value'] == declared['data_rate']['default_value'] == ''
    # The name everything documents, unless asked; empty: the parameter file, no remapping.
    assert declared['node_name']['default_value'] == 'i3dmgx2_driver'
    for name in ('frame_id', 'imu_topic', 'mag_topic', 'temperature_topic'):
        assert declared[name]['default_value'] == '', name
    functions = [f.name for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)]
    assert functions == ['optional_overrides', 'topic_remappings', 'driver_actions',
                         'generate_launch_description']
    (opaque,) = calls(tree, 'OpaqueFunction')
    assert ast.get_source_segment(source, opaque) == 'OpaqueFunction(function=driver_actions)'


def test_launch_file_starts_this_packages_node_with_the_params_file():
    source, tree = parse()
    common = assigned(tree, 'common')
    assert {k.value: v.value for k, v in zip(common.keys, common.values, strict=True)
            if isinstance(v, ast.Constant)} == {
        'package': 'i3dmgx2_driver', 'output': 'screen', 'emulate_tty': True}
    common_text = ast.get_source_segment(source, common)
    assert "'name': LaunchConfiguration('node_name')" in common_text
    assert "'namespace': LaunchConfiguration('namespace')" in common_text
    assert "'remappings': topic_remappings(context)" in common_text
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


class ParameterValue:
    """Stands in for launch_ros's: the substitution and the type it is read as."""

    def __init__(self, value: object, value_type: type) -> None:
        self.value, self.value_type = value, value_type


def _launch_functions(arguments: dict) -> dict:
    """
    Run the launch file's constants and functions with ``arguments`` as the command line.

    Returns its namespace: ``optional_overrides`` and ``topic_remappings``
    among them, called with any context.
    """
    _, tree = parse()
    wanted = {'optional_overrides', 'topic_remappings'}
    body = [n for n in tree.body
            if (isinstance(n, ast.FunctionDef) and n.name in wanted)
            or (isinstance(n, ast.Assign) and n.targets[0].id.isupper())]

    class LaunchConfiguration:
        """Stands in for launch's: ``launch`` is not on PyPI."""

        def __init__(self, name: str) -> None:
            self.name = name

        def perform(self, context: object) -> str:
            return arguments.get(self.name, '')

    namespace = {'LaunchConfiguration': LaunchConfiguration, 'LaunchContext': object,
                 'ParameterValue': ParameterValue}
    module = ast.fix_missing_locations(ast.Module(body, []))
    exec(compile(module, LAUNCH, 'exec'), namespace)
    return namespace


def _optional_overrides(arguments: dict) -> dict:
    """Run the launch file's optional_overrides with ``arguments`` as the command line."""
    namespace = _launch_functions(arguments)
    assert namespace['OPTIONAL_PARAMETERS'][:3] == ('address', 'stream', 'data_rate')
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


def test_several_sensors_calibration_and_capture_reach_either_node_only_when_given():
    assert _optional_overrides({'address': '', **dict.fromkeys(SEVERAL, ''),
                                **dict.fromkeys(CALIBRATION, '')}) == {}
    several = {'addresses': '[95, 12]', 'sensor_names': '[front, rear]',
               'frame_ids': '[front_link, rear_link]', 'streams': "['full', '0xC2']",
               'data_rates': '[100, 50]'}
    overrides = _optional_overrides(several)
    # Each as a substitution under the parameter's own name, read as YAML like -p.
    assert sorted(overrides) == sorted(several)
    for name, value in overrides.items():
        assert not isinstance(value, (str, ParameterValue)) and value.name == name
    overrides = _optional_overrides({'address': '95', 'gyro_bias': '[0.01, 0.0, -0.02]',
                                     'accel_bias': '[0.001, 0.0, 0.0]',
                                     'calibration_file': '/home/robot/bias.yaml'})
    assert sorted(overrides) == ['accel_bias', 'address', 'calibration_file', 'gyro_bias']
    assert overrides['address'].name == 'address'
    assert overrides['gyro_bias'].name == 'gyro_bias'
    assert isinstance(overrides['calibration_file'], ParameterValue)
    assert overrides['calibration_file'].value_type is str
    assert _optional_overrides(dict.fromkeys(CAPTURE, '')) == {}
    capture = {'fault_capture_dir': '/var/log/imu', 'fault_capture_seconds': '10',
               'fault_captures_kept': '5'}
    overrides = _optional_overrides(capture)
    assert sorted(overrides) == sorted(capture)
    # Read as YAML like -p (not as text): a number arrives as one, "''" as '' (off).
    for name, value in overrides.items():
        assert not isinstance(value, (str, ParameterValue)) and value.name == name
    # The same overrides go to both node kinds: the common arguments hold them.
    source, tree = parse()
    assert 'optional_overrides(context)' in ast.get_source_segment(
        source, assigned(tree, 'common'))
    # Every one names a parameter the node declares.
    from i3dmgx2_driver.ros.parameter_table import SPECS
    names = {spec.name for spec in SPECS}
    functions = _launch_functions({})
    assert set(functions['OPTIONAL_PARAMETERS']) <= names
    assert set(functions['OPTIONAL_TEXT_PARAMETERS']) <= names


def test_frame_id_reaches_the_node_only_when_given_and_as_text():
    assert 'frame_id' not in _optional_overrides({})
    frame = _optional_overrides({'frame_id': 'imu_front'})['frame_id']
    # As text whatever it looks like: a frame named 1 is no integer.
    assert isinstance(frame, ParameterValue) and frame.value_type is str
    assert frame.value.name == 'frame_id'


def test_topic_arguments_remap_the_drivers_topics_only_when_given():
    remappings = _launch_functions({})['topic_remappings']
    assert remappings(None) == []
    remappings = _launch_functions({'imu_topic': 'imu/data_raw'})['topic_remappings']
    assert remappings(None) == [('imu/raw_data', 'imu/data_raw')]
    remappings = _launch_functions({'imu_topic': 'front/imu', 'mag_topic': 'front/mag',
                                    'temperature_topic': 'front/temp'})['topic_remappings']
    assert remappings(None) == [('imu/raw_data', 'front/imu'), ('imu/mag', 'front/mag'),
                                ('imu/temperature', 'front/temp')]


def _made_by(arguments: dict) -> dict:
    """Return what one include of the launch file makes: node, topics, frame, port."""
    functions = _launch_functions(arguments)
    renamed = dict(functions['topic_remappings'](None))
    topics = {renamed.get(topic, topic) for topic in functions['TOPIC_ARGUMENTS'].values()}
    name = arguments.get('node_name', 'i3dmgx2_driver')
    overrides = functions['optional_overrides'](None)
    frame = (arguments['frame_id'] if 'frame_id' in overrides else 'imu_link')
    return {'node': name, 'topics': topics | {f'{name}/is_calibrated'}, 'frame': frame,
            'port': arguments['port'], 'diagnostics': f'{name}: '}


def test_two_sensors_on_two_base_stations_run_side_by_side_from_one_launch_file():
    # README: the launch file included twice, each with its own arguments.
    front = _made_by({'node_name': 'imu_front', 'port': '/dev/ttyUSB0', 'address': '95',
                      'frame_id': 'imu_front_link', 'imu_topic': 'imu_front/data',
                      'mag_topic': 'imu_front/mag', 'temperature_topic': 'imu_front/temp'})
    rear = _made_by({'node_name': 'imu_rear', 'port': '/dev/ttyUSB1', 'address': '12',
                     'frame_id': 'imu_rear_link', 'imu_topic': 'imu_rear/data',
                     'mag_topic': 'imu_rear/mag', 'temperature_topic': 'imu_rear/temp'})
    for kind in ('node', 'frame', 'port', 'diagnostics'):
        assert front[kind] != rear[kind], kind
    assert not front['topics'] & rear['topics']
    # Left at their defaults the two would collide: what the arguments are for.
    plain = _made_by({'port': '/dev/ttyUSB0'})
    assert plain['topics'] == {'imu/raw_data', 'imu/mag', 'imu/temperature',
                               'i3dmgx2_driver/is_calibrated'}


def test_the_readmes_two_sensor_launch_file_compiles_and_passes_declared_arguments():
    # Tried by hand with ros2 launch on two simulators; here, what can drift without
    # launch installed: the snippet still compiles, includes this launch file, and
    # every argument it passes is one the launch file declares.
    with open(os.path.join(REPO, 'README.md')) as handle:
        readme = handle.read()
    start = readme.index('**Two sensors, two base stations, one launch file.**')
    block = readme[readme.index('```python\n', start) + len('```python\n'):]
    snippet = block[:block.index('```')]
    tree = ast.parse(snippet, 'README.md')
    compile(tree, 'README.md', 'exec')
    assert "'/launch/i3dmgx2.launch.py'" in snippet
    (include,) = calls(tree, 'IncludeLaunchDescription')
    (arguments,) = [k.value for k in include.keywords if k.arg == 'launch_arguments']
    passed = {key.value for key in arguments.func.value.keys}
    declared = {c.args[0].value for c in calls(parse()[1], 'DeclareLaunchArgument')}
    assert passed <= declared, passed - declared
    assert {'node_name', 'port', 'address', 'frame_id', 'imu_topic'} <= passed
    assert [f.name for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)] == \
        ['sensor', 'generate_launch_description']
