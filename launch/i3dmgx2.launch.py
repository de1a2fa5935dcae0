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
Launch the 3DM-GX2 driver with the installed parameter file.

    ros2 launch i3dmgx2_driver i3dmgx2.launch.py port:=/dev/ttyUSB0 address:=95
    ros2 launch i3dmgx2_driver i3dmgx2.launch.py address:=95 managed:=true
    ros2 launch i3dmgx2_driver i3dmgx2.launch.py address:=95 managed:=true autostart:=true
    ros2 launch i3dmgx2_driver i3dmgx2.launch.py address:=95 stream:=0xC2 data_rate:=250
    ros2 launch i3dmgx2_driver i3dmgx2.launch.py addresses:='[95, 12]' \
        sensor_names:='[front, rear]' streams:="['full', '0xC2']" data_rates:='[100, 50]'
    ros2 launch i3dmgx2_driver i3dmgx2.launch.py address:=95 \
        gyro_bias:='[0.0125, -0.0031, 0.0007]' calibration_file:=$HOME/imu_bias.yaml

The driver publishes ``imu/raw_data``, ``imu/mag`` and ``imu/temperature``
(REP-145 would call ``imu/raw_data`` ``imu/data`` for the ``full`` stream, which
carries orientation, and ``imu/data_raw`` for streams without it: the
README's "Wiring it to a fusion stack" says which is which). ``imu_topic:=``,
``mag_topic:=`` and ``temperature_topic:=`` rename them (a remapping, e.g.
``imu_topic:=imu/data_raw`` for imu_filter_madgwick); ``namespace:=robot1``
moves them all to ``/robot1/...``. Values given here override the parameter
file.

``node_name``, ``frame_id`` and the topic arguments let two sensors (two base
stations, two ports) run side by side from one launch file: include this one
twice, each in a ``GroupAction`` of its own, with its own ``node_name``,
``port``, ``address``, ``frame_id`` and topics (README, Running it).

``managed:=true`` starts the managed (lifecycle) node instead of the plain
one, with the same name, parameters and topics. It starts unconfigured, for
a bringup manager (or ``ros2 lifecycle set``) to drive; ``autostart:=true``
lets this launch file drive it instead: configure at once, activate once
configure has succeeded (and only then: a configure that fails leaves it
unconfigured, and a later deactivate is not undone).

``stream`` and ``data_rate`` choose what the sensor streams and how fast,
written as with ``-p`` (``stream:=inertial`` or ``stream:=0xC2``,
``data_rate:=250``). Left out, the parameter file decides; so they are
passed to the node only when given, which is why the node is built once the
arguments are known (``OpaqueFunction``).

Several sensors behind one base station, served by one node (README,
Several sensors), take the same way: ``addresses`` instead of ``address``
(one of the two is required; the node says so when neither is given),
``sensor_names``, ``frame_ids``, ``streams`` and ``data_rates``, each a
YAML list as with ``-p`` (quote a stream written as a command byte,
``"['full', '0xC2']"``: unquoted, 0xC2 is a number in a list of names).
So do the calibration settings (README, Calibration): ``gyro_bias`` and
``accel_bias`` (three numbers, rad/s and g) and ``calibration_file`` (text);
and the fault capture's (README, Fault captures): ``fault_capture_dir``
(read as YAML like the rest, so that ``fault_capture_dir:="''"`` turns it
off as ``-p`` does), ``fault_capture_seconds`` and ``fault_captures_kept``.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchContext, LaunchDescription
from launch.actions import (DeclareLaunchArgument, EmitEvent, OpaqueFunction,
                            RegisterEventHandler)
from launch.conditions import IfCondition, UnlessCondition
from launch.events import matches_action
from launch.substitutions import AndSubstitution, LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.parameter_descriptions import ParameterValue
from lifecycle_msgs.msg import Transition


#: Launch arguments that override the parameter file only when given, read as YAML.
OPTIONAL_PARAMETERS = ('address', 'stream', 'data_rate', 'addresses', 'sensor_names',
                       'frame_ids', 'streams', 'data_rates', 'gyro_bias', 'accel_bias',
                       'fault_capture_dir', 'fault_capture_seconds', 'fault_captures_kept')
#: The same, always passed as text (a frame named ``1`` is no number).
OPTIONAL_TEXT_PARAMETERS = ('frame_id', 'calibration_file')
#: Launch argument -> the driver's topic it renames (remaps) when given.
TOPIC_ARGUMENTS = {'imu_topic': 'imu/raw_data', 'mag_topic': 'imu/mag',
                   'temperature_topic': 'imu/temperature'}


def optional_overrides(context: LaunchContext) -> dict:
    """
    Return the optional arguments that were given, by parameter name.

    Each goes on as a substitution, not as its text: launch_ros reads a
    substitution's result as YAML, as ``-p`` does, so ``data_rate:=250``
    arrives as a number (the node takes an integer for a rate in hertz) and
    ``stream:=0xC2`` as the integer 194, which the node takes for the
    record's command byte. Plain text would arrive as a string.
    """
    given = (name for name in OPTIONAL_PARAMETERS
             if LaunchConfiguration(name).perform(context))
    overrides = {name: LaunchConfiguration(name) for name in given}
    for name in OPTIONAL_TEXT_PARAMETERS:
        if LaunchConfiguration(name).perform(context):
            overrides[name] = ParameterValue(LaunchConfiguration(name), value_type=str)
    return overrides


def topic_remappings(context: LaunchContext) -> list:
    """Return (driver's topic, new name) for each topic argument that was given."""
    return [(topic, LaunchConfiguration(argument).perform(context))
            for argument, topic in TOPIC_ARGUMENTS.items()
            if LaunchConfiguration(argument).perform(context)]


def driver_actions(context: LaunchContext) -> list:
    """Build the driver node, plain or managed, once the arguments are known."""
    managed = LaunchConfiguration('managed')
    # What both executables are started with.
    common = {
        'package': 'i3dmgx2_driver',
        'name': LaunchConfiguration('node_name'),
        'namespace': LaunchConfiguration('namespace'),
        'remappings': topic_remappings(context),
        'output': 'screen',
        'emulate_tty': True,
        'parameters': [
            LaunchConfiguration('params_file'),
            {'port': LaunchConfiguration('port')},
            optional_overrides(context),
        ],
    }
    plain_node = Node(executable='node', condition=UnlessCondition(managed), **common)
    managed_node = LifecycleNode(executable='lifecycle_node', condition=IfCondition(managed),
                                 **common)
    autostart = IfCondition(AndSubstitution(managed, LaunchConfiguration('autostart')))
    configure = EmitEvent(
        event=ChangeState(lifecycle_node_matcher=matches_action(managed_node),
                          transition_id=Transition.TRANSITION_CONFIGURE),
        condition=autostart)
    activate_once_configured = RegisterEventHandler(
        OnStateTransition(
            target_lifecycle_node=managed_node, start_state='configuring',
            goal_state='inactive',
            entities=[EmitEvent(event=ChangeState(
                lifecycle_node_matcher=matches_action(managed_node),
                transition_id=Transition.TRANSITION_ACTIVATE))]),
        condition=autostart)
    return [plain_node, managed_node, activate_once_configured, configure]


def generate_launch_description() -> LaunchDescription:
    """Declare the arguments; the driver node follows once they are known."""
    params_file = os.path.join(
        get_package_share_directory('i3dmgx2_driver'), 'config', 'i3dmgx2.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('port', default_value='/dev/ttyUSB0',
                              description='Serial port of the base station'),
        # Empty: none, and the node refuses to start unless addresses names several: it
        # must not talk to a sensor nobody chose.
        DeclareLaunchArgument('address', default_value='',
                              description='Node address of the sensor (1..65534); required '
                                          'unless addresses is given'),
        DeclareLaunchArgument('addresses', default_value='',
                              description='Several sensors behind the base station, e.g. '
                                          "'[95, 12]' (instead of address); empty: one"),
        DeclareLaunchArgument('sensor_names', default_value='',
                              description="With addresses: each sensor's name (topic "
                                          "prefix), e.g. '[front, rear]'; empty: imu_<address>"),
        DeclareLaunchArgument('frame_ids', default_value='',
                              description="With addresses: each sensor's frame; empty: "
                                          '<name>_link'),
        DeclareLaunchArgument('streams', default_value='',
                              description="With addresses: each sensor's stream, e.g. "
                                          "\"['full', '0xC2']\"; empty: stream for all"),
        DeclareLaunchArgument('data_rates', default_value='',
                              description="With addresses: each sensor's data rate (Hz), e.g. "
                                          "'[100, 50]'; empty: data_rate for all"),
        DeclareLaunchArgument('gyro_bias', default_value='',
                              description='Gyro bias [x, y, z] in rad/s written at every start; '
                                          'empty: as the parameter file says'),
        DeclareLaunchArgument('accel_bias', default_value='',
                              description='Accelerometer bias [x, y, z] in g written at every '
                                          'start; empty: as the parameter file says'),
        DeclareLaunchArgument('calibration_file', default_value='',
                              description='Parameter file an accepted gyro bias capture is '
                                          'written to; empty: as the parameter file says'),
        DeclareLaunchArgument('fault_capture_dir', default_value='',
                              description="Directory of the fault captures, \"''\" to turn "
                                          'them off; empty: as the parameter file says'),
        DeclareLaunchArgument('fault_capture_seconds', default_value='',
                              description='Seconds of the port kept for a fault capture; '
                                          'empty: as the parameter file says'),
        DeclareLaunchArgument('fault_captures_kept', default_value='',
                              description='Fault captures kept, the oldest deleted; '
                                          'empty: as the parameter file says'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='Namespace of the node and its topics'),
        DeclareLaunchArgument('node_name', default_value='i3dmgx2_driver',
                              description='Name of the node (one per sensor when several '
                                          'run side by side)'),
        DeclareLaunchArgument('frame_id', default_value='',
                              description='Frame of the published messages; empty: as the '
                                          'parameter file says'),
        DeclareLaunchArgument('imu_topic', default_value='',
                              description='Publish imu/raw_data under this name instead '
                                          '(e.g. imu/data_raw, imu/data); empty: imu/raw_data'),
        DeclareLaunchArgument('mag_topic', default_value='',
                              description='Publish imu/mag under this name instead; '
                                          'empty: imu/mag'),
        DeclareLaunchArgument('temperature_topic', default_value='',
                              description='Publish imu/temperature under this name instead; '
                                          'empty: imu/temperature'),
        DeclareLaunchArgument('params_file', default_value=params_file,
                              description='Parameter file'),
        DeclareLaunchArgument('managed', default_value='false',
                              description='true: start the managed (lifecycle) node, '
                                          'unconfigured, for a bringup manager to drive'),
        DeclareLaunchArgument('autostart', default_value='false',
                              description='With managed:=true, configure and activate it '
                                          'from this launch file'),
        DeclareLaunchArgument('stream', default_value='',
                              description="What the sensor streams: a name ('full', "
                                          "'inertial', ...) or a command byte ('0xC2'); "
                                          'empty: as the parameter file says'),
        DeclareLaunchArgument('data_rate', default_value='',
                              description='Data rate in Hz (0: leave the device as it is); '
                                          'empty: as the parameter file says'),
        OpaqueFunction(function=driver_actions),
    ])
