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
The QoS of every publisher: rclpy's standard override parameters.

Every publisher the driver makes is created with
:func:`overriding_options`, so that rclpy declares the read-only parameters
``qos_overrides.<topic>.publisher.<policy>`` that every ROS user knows from
other nodes (``-p qos_overrides./imu/raw_data.publisher.reliability:=
best_effort``), and applies them on top of the profile the driver asks for.
The topic in the name is the resolved one: under a namespace or a remapping
it is the name the topic really has (``/robot1/imu/raw_data``).

The policies offered are those a subscriber's match depends on and that a
person tunes: history, depth, reliability, durability.
"""

from collections.abc import Iterable

from rclpy.node import Node
from rclpy.qos import QoSPolicyKind
from rclpy.qos_overriding_options import QoSOverridingOptions

#: The policies that get a ``qos_overrides`` parameter on every publisher.
POLICIES = (QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH, QoSPolicyKind.RELIABILITY,
            QoSPolicyKind.DURABILITY)
#: Every topic the driver may publish, as it names them (before resolution).
TOPICS = ('imu/raw_data', 'imu/mag', 'imu/temperature', '~/is_calibrated', '/diagnostics')


def overriding_options() -> QoSOverridingOptions:
    """Return the options every publisher of the driver is created with."""
    return QoSOverridingOptions(POLICIES)


def override_name(topic: str, policy: QoSPolicyKind) -> str:
    """Return rclpy's parameter name for ``policy`` of the publisher on resolved ``topic``."""
    return f'qos_overrides.{topic}.publisher.{policy.name.lower()}'


def override_names(node: Node, topics: Iterable[str] = TOPICS) -> list[str]:
    """
    Return every QoS parameter name the driver's publishers on ``node`` may declare.

    For the unknown-parameter warning, which runs before the publishers
    exist (and a topic switched off never declares its own): a misspelt
    topic or policy is still named, a right one is not.
    """
    return [override_name(node.resolve_topic_name(topic), policy)
            for topic in topics for policy in POLICIES]
