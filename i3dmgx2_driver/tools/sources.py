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
Where an analysis tool's data comes from: a capture, a bag, or the running node.

noise and magcal read the same three sources, named by the same options
(``--capture``, ``--bag``, ``--minutes``, ``--topic``, ``-o``), and listen to
the node the same way: their own rclpy context, a spinner thread, Ctrl-C
(or SIGTERM) ending the listening rather than the tool, so that what came
is analysed. Which messages a tool keeps and what it makes of them are its own.
"""

import argparse
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager, suppress
import sys
import threading
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Imu, MagneticField

from .imu_samples import DEFAULT_TOPIC, mag_topic
from .. import lifetime


def add_sources(parser: argparse.ArgumentParser, what: str, writes: str) -> None:
    """Add the three sources (one required), ``--topic`` and ``-o DIR`` (writing ``writes``)."""
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument('--capture', metavar='FILE',
                        help="a capture: the node's capture_file, a fault capture, bringup's")
    source.add_argument('--bag', metavar='PATH', help='a rosbag2 bag, sqlite3 or MCAP')
    source.add_argument('--minutes', type=float, metavar='M',
                        help=f'listen to the running node for M minutes (Ctrl-C ends early '
                             f'and {what} what came)')
    parser.add_argument('--topic', default=DEFAULT_TOPIC,
                        help='the Imu topic (default %(default)s): of the bag, or live')
    parser.add_argument('-o', '--output', metavar='DIR', help=f'write {writes} here')


def parse_args(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> Any:
    """Parse the tool's own arguments: those before ``--ros-args`` (``ros2 run`` adds it)."""
    args = list(sys.argv[1:] if argv is None else argv)
    return parser.parse_args(args[:args.index('--ros-args')] if '--ros-args' in args else args)


def read_source(args: Any, from_capture: Callable[[str], Any],
                from_bag: Callable[[str, str], Any], listen: Callable[[str, float], Any]) -> Any:
    """Return what the source ``args`` names gives: a capture's, a bag's or the node's."""
    if args.capture:
        return from_capture(args.capture)
    return from_bag(args.bag, args.topic) if args.bag else listen(args.topic, args.minutes * 60.0)


def stamp_of(msg: Any) -> tuple[int, int]:
    """Return a message's stamp as it came: what pairs the Imu and field of one record."""
    return msg.header.stamp.sec, msg.header.stamp.nanosec


def paired(imu: dict[tuple[int, int], Any], fields: Iterable[Any]) -> list[tuple[Any, Any]]:
    """Return each field with the Imu message (``imu``, by :func:`stamp_of`) of its stamp."""
    return [(imu[stamp], m) for m in fields if (stamp := stamp_of(m)) in imu]


@contextmanager
def listening(name: str, topic: str, on_imu: Callable[[Imu], Any],
              on_field: Callable[[MagneticField], Any]) -> Iterator[tuple[Node, Any]]:
    """
    Spin a node ``name`` in its own context; yield it and the stop signal.

    It hands the Imu messages of ``topic`` to ``on_imu`` and the fields of
    its mag topic to ``on_field``, on the spinner thread. Best effort
    (``qos_profile_sensor_data``): it matches the driver's reliable
    publisher and never slows it. On leaving, the line the tool kept on
    stderr is ended and everything shut down.
    """
    lifetime.die_with_parent()
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node(name)
    node.create_subscription(Imu, topic, on_imu, qos_profile_sensor_data)
    node.create_subscription(MagneticField, mag_topic(topic), on_field, qos_profile_sensor_data)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    # Not a threading.Event: a signal handler may not take a lock (lifetime.py says why).
    stopped = lifetime.StopSignal().install()
    spinner = threading.Thread(target=_spin, args=(executor,), daemon=True)
    spinner.start()
    try:
        yield node, stopped
    finally:
        print(file=sys.stderr)
        stopped.restore()
        executor.shutdown(timeout_sec=1.0)
        spinner.join(timeout=5.0)
        node.destroy_node()
        rclpy.try_shutdown()


def _spin(executor: SingleThreadedExecutor) -> None:
    with suppress(ExternalShutdownException):
        executor.spin()
