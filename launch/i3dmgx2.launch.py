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

Topics land under the ``imu`` namespace as REP-145 asks (``imu/raw_data``,
``imu/mag``, ``imu/temperature``); ``namespace:=robot1`` moves them all to
``/robot1/imu/...``. Values given here override the parameter file.

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


#: Launch arguments that override the parameter file only when given.
OPTIONAL_PARAMETERS = ('stream', 'data_rate')


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
    return {name: LaunchConfiguration(name) for name in given}


def driver_actions(context: LaunchContext) -> list:
    """Build the driver node, plain or managed, once the arguments are known."""
    managed = LaunchConfiguration('managed')
    # What both executables are started with.
    common = {
        'package': 'i3dmgx2_driver',
        'name': 'i3dmgx2_driver',
        'namespace': LaunchConfiguration('namespace'),
        'output': 'screen',
        'emulate_tty': True,
        'parameters': [
            LaunchConfiguration('params_file'),
            {
                'port': LaunchConfiguration('port'),
                'address': ParameterValue(LaunchConfiguration('address'), value_type=int),
            },
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
        # No default: the node must not talk to a sensor nobody chose.
        DeclareLaunchArgument('address',
                              description='Node address of the sensor (1..65534), required'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='Namespace of the node and its topics'),
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
