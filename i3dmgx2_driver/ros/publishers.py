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
The topics of one sensor, the publishers made on them, and their QoS.

Named once, so that the node's publishers and its check of the
``qos_overrides`` parameters (the unknown-parameter warning) agree, and so
that the core that publishes and the managed node that keeps its publishers
across configure/cleanup (lifecycle_node.py) make them the same way.

Every publisher the driver makes is created with rclpy's
``QoSOverridingOptions`` for :data:`POLICIES`, so that rclpy declares the
read-only parameters ``qos_overrides.<topic>.publisher.<policy>`` that every
ROS user knows from other nodes (``-p qos_overrides./imu/raw_data.publisher.reliability:=
best_effort``), and applies them on top of the profile the driver asks for.
The topic in the name is the resolved one: under a namespace or a remapping
it is the name the topic really has (``/robot1/imu/raw_data``).

The policies offered are those a subscriber's match depends on and that a
person tunes: history, depth, reliability, durability. rclpy refuses a bad
one with a traceback; :func:`create_publisher` turns that into the
``ParameterError`` every other bad parameter gives.
"""

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import NamedTuple

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSPolicyKind, QoSProfile,
                       ReliabilityPolicy)
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import Bool

from .parameters import DriverConfig, given_value, ParameterError
from .sensor_set import SensorSetting, SINGLE_NAME

#: The policies that get a ``qos_overrides`` parameter on every publisher.
POLICIES = (QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH, QoSPolicyKind.RELIABILITY,
            QoSPolicyKind.DURABILITY)
#: The words rclpy takes for each named policy (in any case): its enum's
#: members but UNKNOWN, which rmw reports and nobody can ask for.
CHOICES = {kind: tuple(member.name.lower() for member in enum if member.name != 'UNKNOWN')
           for kind, enum in ((QoSPolicyKind.HISTORY, HistoryPolicy),
                              (QoSPolicyKind.RELIABILITY, ReliabilityPolicy),
                              (QoSPolicyKind.DURABILITY, DurabilityPolicy))}
#: Largest history depth rmw takes (DDS holds it in a signed 32-bit integer).
MAX_DEPTH = 2 ** 31 - 1


def override_name(topic: str, policy: QoSPolicyKind) -> str:
    """Return rclpy's parameter name for ``policy`` of the publisher on resolved ``topic``."""
    return f'qos_overrides.{topic}.publisher.{policy.name.lower()}'


def override_names(node: Node, topics: Iterable[str]) -> list[str]:
    """
    Return every QoS parameter name the publishers of ``topics`` on ``node`` may declare.

    For the unknown-parameter warning, which runs before the publishers
    exist (and a topic switched off never declares its own): a misspelt
    topic or policy is still named, a right one is not.
    """
    return [override_name(node.resolve_topic_name(topic), policy)
            for topic in topics for policy in POLICIES]


def create_publisher(node: Node, msg_type: type, topic: str, qos: QoSProfile | int,
                     make: Callable[..., Publisher] | None = None) -> Publisher:
    """
    Make a publisher on ``topic`` (with ``make``, default ``node.create_publisher``).

    rclpy declares and applies the ``qos_overrides`` parameters there, and
    would refuse a bad value with a traceback (a RuntimeError that names the
    policy but not the parameter, a type error, or rcl's failure to set the
    depth, after rmw has printed its own error). So they are checked first:
    a bad one raises ParameterError naming the parameter, what was given and
    what is valid, and the node stops as for any bad parameter.
    """
    if (problem := bad_override(node, node.resolve_topic_name(topic))) is not None:
        raise ParameterError(problem)
    make = make or node.create_publisher
    return make(msg_type, topic, qos, qos_overriding_options=QoSOverridingOptions(POLICIES))


def bad_override(node: Node, topic: str) -> str | None:
    """
    Say what is wrong with the first bad ``qos_overrides`` parameter of ``topic``; None if none.

    ``topic`` is resolved. A parameter rclpy declared already (a managed
    node configured again) is read; any other is read as it was given.
    """
    for policy in POLICIES:
        name = override_name(topic, policy)
        value = (node.get_parameter(name).value if node.has_parameter(name)
                 else given_value(node, name))
        if policy == QoSPolicyKind.DEPTH:
            valid = f'0..{MAX_DEPTH} (0: the system default)'
            fine = type(value) is int and 0 <= value <= MAX_DEPTH
        else:
            valid = 'one of ' + ', '.join(map(repr, CHOICES[policy]))
            fine = isinstance(value, str) and value.lower() in CHOICES[policy]
        if value is not None and not fine:
            return f'parameter {name!r} must be {valid}, got {value!r}'
    return None


class RecordTopic(NamedTuple):
    """
    A topic the stream's records are published on: one row of :data:`RECORD_TOPICS`.

    ``suffix`` is the topic under the sensor's name (``imu/<suffix>``);
    ``packer`` names the message factory's packers of a record
    (``<packer>_cdr`` and ``fill_<packer>``, conversions.py), which return
    None for a record with nothing for this topic; ``wanted(config, sensor)``
    says whether the sensor publishes it (its stream carries it, a parameter
    asks for it). The first row is the stream's own message: it is stamped,
    timed and counted as the record published.
    """

    suffix: str
    msg_type: type
    packer: str
    wanted: Callable[[DriverConfig, SensorSetting], bool]


#: Every topic a record goes to. A new one is a row here and its packer in conversions.py.
RECORD_TOPICS = (
    RecordTopic('raw_data', Imu, 'imu', lambda config, sensor: True),
    # Only streams with a field (named 'mag' in each layout) have a magnetometer topic.
    RecordTopic('mag', MagneticField, 'mag',
                lambda config, sensor: config.publish_mag and bool(sensor.stream_choice.mag)),
)


@dataclass(frozen=True)
class SensorTopics:
    """The topics one sensor's publishers use, named once for the node and its QoS names."""

    #: One per row of RECORD_TOPICS, in its order.
    records: tuple[str, ...]
    temperature: str
    is_calibrated: str

    @classmethod
    def of(cls, name: str, several: bool) -> 'SensorTopics':
        """Return the topics of the sensor called ``name`` (sensor_set.py: ``imu`` alone)."""
        return cls(tuple(f'{name}/{row.suffix}' for row in RECORD_TOPICS), f'{name}/temperature',
                   f'~/{name}/is_calibrated' if several else '~/is_calibrated')

    def __iter__(self) -> Iterator[str]:
        """Every topic, the records' first."""
        return iter((*self.records, self.temperature, self.is_calibrated))

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

    #: Each row of RECORD_TOPICS the sensor publishes, with its publisher, in order.
    records: tuple[tuple[RecordTopic, Publisher], ...]
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
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=config.qos_depth,
                      reliability=ReliabilityPolicy[config.qos_reliability.upper()])


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
        tuple((row, create(row.msg_type, topic))
              for row, topic in zip(RECORD_TOPICS, topics.records, strict=True)
              if row.wanted(config, sensor)),
        create(Temperature, topics.temperature) if config.temperature_period > 0 else None,
        create_publisher(node, Bool, topics.is_calibrated, calibrated_qos()))
