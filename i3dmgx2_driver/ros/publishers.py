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
The topics of one sensor and the publishers made on them.

Named once, so that the node's publishers and its check of the
``qos_overrides`` parameters (unknown_parameters.py) agree, and so that the
core that publishes and the managed node that keeps its publishers across
configure/cleanup (lifecycle_node.py) make them the same way.
"""

from typing import NamedTuple

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import Bool

from .parameters import DriverConfig
from .qos import create_publisher
from .sensor_set import SensorSetting, SINGLE_NAME


class SensorTopics(NamedTuple):
    """The topics one sensor's publishers use, named once for the node and its QoS names."""

    imu: str
    mag: str
    temperature: str
    is_calibrated: str

    @classmethod
    def of(cls, name: str, several: bool) -> 'SensorTopics':
        """Return the topics of the sensor called ``name`` (sensor_set.py: ``imu`` alone)."""
        return cls(f'{name}/raw_data', f'{name}/mag', f'{name}/temperature',
                   f'~/{name}/is_calibrated' if several else '~/is_calibrated')

    @staticmethod
    def of_every_sensor(config: DriverConfig) -> list[str]:
        """Return every topic the node may publish with ``config``, /diagnostics too."""
        several = len(config.sensors) > 1
        return [*(topic for sensor in config.sensors
                  for topic in SensorTopics.of(sensor.name, several)), '/diagnostics']


#: The topics of a node with one sensor: what is checked when the parameters fail.
ALONE_TOPICS = [*SensorTopics.of(SINGLE_NAME, several=False), '/diagnostics']


class Publishers(NamedTuple):
    """The publishers; None where the parameters turn a topic off."""

    imu: Publisher
    mag: Publisher | None
    temperature: Publisher | None
    #: ``~/is_calibrated``: a plain publisher even on a managed node, so that
    #: its latched value holds in every state.
    is_calibrated: Publisher


def calibrated_qos() -> QoSProfile:
    """Return the QoS of ``~/is_calibrated``: the last value kept for late subscribers."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def publisher_qos(config: DriverConfig) -> QoSProfile:
    """
    Return the data publishers' QoS before rclpy's ``qos_overrides`` parameters.

    The deprecated ``qos_reliability`` and ``qos_depth`` still set it (for
    one release); a ``qos_overrides`` parameter wins over them.
    """
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=config.qos_depth,
        reliability=(ReliabilityPolicy.RELIABLE if config.qos_reliability == 'reliable'
                     else ReliabilityPolicy.BEST_EFFORT))


def create_publishers(node: Node, config: DriverConfig, lifecycle: bool = False,
                      sensor: SensorSetting | None = None) -> Publishers:
    """
    Make the data publishers of ``sensor`` (default: the one sensor) on ``node``.

    Lifecycle publishers if ``lifecycle``. The topics are under the sensor's
    name: ``imu/raw_data`` for the one sensor, ``<name>/raw_data`` for each
    of several (sensor_set.py).

    A managed node makes them once and keeps them across configure/cleanup
    cycles: destroying a publisher while a multi-threaded executor builds
    its wait set can crash the executor in rclpy (Jazzy), because the
    publisher's QoS event handlers are waitables whose invalid handles it
    does not skip (ros2/rclpy#1284). Its parameters are read-only, so the
    publishers it made first are the ones every later configure needs.
    """
    sensor = sensor if sensor is not None else config.sensors[0]
    topics = SensorTopics.of(sensor.name, several=len(config.sensors) > 1)
    make = node.create_lifecycle_publisher if lifecycle else node.create_publisher

    def create(kind: type, topic: str) -> Publisher:
        # A profile each: rclpy writes the overrides into the one it is given.
        return create_publisher(node, kind, topic, publisher_qos(config), make)

    return Publishers(
        create(Imu, topics.imu),
        # Only streams with a field (named 'mag' in each layout) have a magnetometer topic.
        create(MagneticField, topics.mag)
        if config.publish_mag and sensor.stream_choice.mag else None,
        create(Temperature, topics.temperature) if config.temperature_period > 0
        else None,
        create_publisher(node, Bool, topics.is_calibrated, calibrated_qos()))
