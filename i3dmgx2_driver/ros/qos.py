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
person tunes: history, depth, reliability, durability. rclpy refuses a bad
one with a traceback; :func:`create_publisher` turns that into the
``ParameterError`` every other bad parameter gives.
"""

from collections.abc import Callable, Iterable
from typing import Any

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSPolicyKind, QoSProfile,
                       ReliabilityPolicy)
from rclpy.qos_overriding_options import QoSOverridingOptions

from .parameters import given_value, ParameterError

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


def overriding_options() -> QoSOverridingOptions:
    """Return the options every publisher of the driver is created with."""
    return QoSOverridingOptions(POLICIES)


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
    problem = bad_override(node, node.resolve_topic_name(topic))
    if problem is not None:
        raise ParameterError(problem)
    make = make or node.create_publisher
    return make(msg_type, topic, qos, qos_overriding_options=overriding_options())


def _valid(policy: QoSPolicyKind) -> str:
    if policy == QoSPolicyKind.DEPTH:
        return f'0..{MAX_DEPTH} (0: the system default)'
    return 'one of ' + ', '.join(repr(choice) for choice in CHOICES[policy])


def _is_valid(policy: QoSPolicyKind, value: Any) -> bool:
    if policy == QoSPolicyKind.DEPTH:
        return type(value) is int and 0 <= value <= MAX_DEPTH
    return isinstance(value, str) and value.lower() in CHOICES[policy]


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
        if value is not None and not _is_valid(policy, value):
            return f'parameter {name!r} must be {_valid(policy)}, got {value!r}'
    return None
