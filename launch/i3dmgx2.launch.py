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

Topics land under the ``imu`` namespace as REP-145 asks (``imu/raw_data``,
``imu/mag``, ``imu/temperature``); ``namespace:=robot1`` moves them all to
``/robot1/imu/...``. Values given here override the parameter file.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description() -> LaunchDescription:
    """Declare the arguments and the driver node."""
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
        Node(
            package='i3dmgx2_driver',
            executable='node',
            name='i3dmgx2_driver',
            namespace=LaunchConfiguration('namespace'),
            output='screen',
            emulate_tty=True,
            parameters=[
                LaunchConfiguration('params_file'),
                {
                    'port': LaunchConfiguration('port'),
                    'address': ParameterValue(LaunchConfiguration('address'), value_type=int),
                },
            ],
        ),
    ])
