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
rosbag2 bags, in and out: a capture as the messages the node would have published.

rosbags, not mcap with mcap-ros2-support: one pure-Python library reads
both storages rosbag2 writes (sqlite3 and MCAP, for ``noise --bag``) and
writes MCAP with the rosbag2 metadata that ``ros2 bag info`` and ``play``
expect (for ``replay --bag``); mcap's packages read and write MCAP only,
and leave the rosbag2 directory and its metadata.yaml to the caller. Like
matplotlib for ``plot`` it is an optional extra (``pip install
"i3dmgx2_driver[bag]"``): the robot's image needs neither, and nothing
imports it until a bag is read or written.

A capture becomes messages through the node's own record path
(ros/record_publisher.py ``RecordPath``: the stamp, from the record's timer
with the receive times standing for the host clock, and the packers of the
topics the node publishes, ready-serialized as it publishes them) with the
node's parameters at their defaults; the temperatures (replies to 0xD1
polls) as the node's poller stamps them, at their read.
"""

from collections import Counter
from collections.abc import Iterable, Iterator
import contextlib
from pathlib import Path
from typing import Any, NamedTuple

from rclpy.serialization import serialize_message
from sensor_msgs.msg import Temperature

from ..codec import layouts, line_budget, streams
from ..codec.framing import DataPacket, MIN_ADDRESS
from ..codec.parser import SensorStreamParser
from ..device.sample_clock import SampleClock
from ..ros.conversions import set_stamp
from ..ros.parameter_table import SPECS
from ..ros.parameters import driver_config
from ..ros.publishers import RECORD_TOPICS, SensorTopics
from ..ros.record_publisher import RecordPath, Stamping
from ..ros.sensor_set import SINGLE_NAME

#: What to do when rosbags is missing.
ROSBAGS_HINT = (
    'reading and writing bags needs rosbags, an optional extra the driver does not install: '
    'pip install rosbags (pip install "i3dmgx2_driver[bag]" from a source checkout)')


def bag_type(msg_type: type) -> str:
    """Return the name rosbag2 gives a message class (``sensor_msgs/msg/Imu``)."""
    return f'{msg_type.__module__.split(".")[0]}/msg/{msg_type.__name__}'


def _rosbags() -> Any:
    try:
        import rosbags.highlevel
        import rosbags.rosbag2
        import rosbags.typesys
    except ImportError as exc:
        raise ImportError(ROSBAGS_HINT) from exc
    return rosbags


def typestore() -> Any:
    """Return rosbags' message definitions of ROS 2 Jazzy, the driver's distribution."""
    typesys = _rosbags().typesys
    return typesys.get_typestore(typesys.Stores.ROS2_JAZZY)


@contextlib.contextmanager
def bag_reader(path: Path) -> Iterator[Any]:
    """Open a rosbag2 bag, sqlite3 or MCAP (a directory, or its one storage file)."""
    highlevel = _rosbags().highlevel
    with highlevel.AnyReader([path], default_typestore=typestore()) as reader:
        yield reader


def deserializer(reader: Any) -> Any:
    """Return ``decode(raw, msgtype)`` for the messages of ``reader``."""
    return reader.deserialize


class BagMessage(NamedTuple):
    """One message as a bag holds it: topic, type, receive time (ns) and CDR bytes."""

    topic: str
    msgtype: str
    time_ns: int
    data: bytes


def stream_of(codes: Iterable[int]) -> streams.Stream:
    """Return the stream most of a capture's data records (their codes) belong to."""
    for code, _ in Counter(codes).most_common():
        if code in streams.BY_CODE:
            return streams.BY_CODE[code]
    raise ValueError('no record of a stream the driver publishes '
                     f'({", ".join(s.label for s in streams.STREAMS)})')


def capture_messages(chunks: Iterable[tuple[float, bytes]], header: dict,
                     baud: int | None = None) -> list[BagMessage]:
    """
    Return the messages the node (default parameters) would have published for a capture.

    The stream is the one most records are of; its records go through the
    node's record path, stamped from their timers and their reads' receive
    times (the node's ``time_source`` device).
    """
    address = header.get('address') if isinstance(header.get('address'), int) else None
    wireless = bool(header.get('wireless', True))
    parser = SensorStreamParser(address, wireless)
    events = [(t, event) for t, data in chunks for event in parser.feed(data)
              if isinstance(event, DataPacket)]
    stream = stream_of(event.code for _, event in events)
    # A node at its parameters' defaults, streaming ``stream``.
    config = driver_config({**{spec.name: spec.default for spec in SPECS}, 'stream': stream.name,
                            'address': MIN_ADDRESS if address is None else address})
    sensor = config.sensors[0]
    topics = SensorTopics.of(SINGLE_NAME, several=False)
    # The node's own table: each topic the sensor publishes with its parameters' defaults.
    rows = [(row, '/' + topic) for row, topic in zip(RECORD_TOPICS, topics.records, strict=True)
            if row.wanted(config, sensor)]
    wire = line_budget.wire_time(stream.code, baud or int(header.get('baud') or 115200), wireless)
    path = RecordPath(config.messages_for(sensor), Stamping(True, 0.0, wire),
                      [row for row, _ in rows], SampleClock(offset=lambda: 0.0))
    names = [(topic, bag_type(row.msg_type)) for row, topic in rows]
    temperature = Temperature()
    temperature.header.frame_id = path.factory.frame_id
    out = []
    for receive_time, event in events:
        time_ns = round(receive_time * 1e9)
        if event.code == stream.code:
            for (topic, msgtype), data in zip(
                    names, path.messages(event.values, receive_time, receive_time), strict=True):
                if data is not None:
                    out.append(BagMessage(topic, msgtype, time_ns, data))
        elif event.code == layouts.TEMPERATURES:
            temperature.temperature = event.record.accel_celsius
            set_stamp(temperature.header, receive_time)
            out.append(BagMessage('/' + topics.temperature, bag_type(Temperature), time_ns,
                                  serialize_message(temperature)))
    return out


def write_bag(path: Path, messages: Iterable[BagMessage]) -> int:
    """Write ``messages`` as a rosbag2 bag with MCAP storage at ``path``; return how many."""
    rosbag2 = _rosbags().rosbag2
    store = typestore()
    count, connections = 0, {}
    with rosbag2.Writer(path, version=9, storage_plugin=rosbag2.StoragePlugin.MCAP) as writer:
        for message in messages:
            if message.topic not in connections:
                connections[message.topic] = writer.add_connection(
                    message.topic, message.msgtype, typestore=store)
            writer.write(connections[message.topic], message.time_ns, message.data)
            count += 1
    return count
