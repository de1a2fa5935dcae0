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

from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'i3dmgx2_driver'

setup(
    name=package_name,
    version='1.0.0',
    packages=find_packages(include=['i3dmgx2_driver', 'i3dmgx2_driver.*']),
    data_files=[
        ('share/ament_index/resource_index/packages',
            ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'), glob('config/*.yaml')),
        (os.path.join('share', package_name, 'launch'), glob('launch/*.launch.py')),
        (os.path.join('share', package_name, 'udev'), glob('udev/*.rules')),
        (os.path.join('share', package_name, 'urdf'), glob('urdf/*.xacro')),
    ],
    install_requires=['setuptools'],
    # Only the plot tool (and noise's allan.png) draws; on a robot matplotlib would pull in a
    # GUI stack. Only replay --bag and noise --bag read or write bags (rosbags, pure Python).
    extras_require={'plot': ['matplotlib'], 'bag': ['rosbags']},
    zip_safe=True,
    maintainer='The i3dmgx2_driver Authors',
    maintainer_email='maintainers@i3dmgx2-driver.invalid',
    description='ROS 2 driver for the MicroStrain 3DM-GX2 IMU.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'node = i3dmgx2_driver.ros.main:main',
            'lifecycle_node = i3dmgx2_driver.ros.lifecycle_node:main',
            'simulator = i3dmgx2_driver.simulator.cli:main',
            'replay = i3dmgx2_driver.tools.replay:main',
            'plot = i3dmgx2_driver.tools.plot:main',
            'monitor = i3dmgx2_driver.tools.monitor:main',
            'discover = i3dmgx2_driver.tools.discover:main',
            'bringup = i3dmgx2_driver.tools.bringup:main',
            'noise = i3dmgx2_driver.tools.noise:main',
            'magcal = i3dmgx2_driver.tools.magcal:main',
        ],
    },
)
