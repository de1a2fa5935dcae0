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
The record path's counting, in this process: what is published, lost, left unpublished.

The record publisher is given real rclpy publishers on a node of its own
and fed records as the reader thread would; what reaches a subscriber is
the node tests' business (test_node_messages.py), here it is the counters
that diagnostics and the self test read.
"""

from i3dmgx2_driver.codec import streams
from i3dmgx2_driver.codec.data_rate import ticks_per_cycle
from i3dmgx2_driver.codec.records import AccelAngRate, TICKS_PER_SECOND
from i3dmgx2_driver.ros.conversions import MessageSettings
from i3dmgx2_driver.ros.publishers import calibrated_qos, Publishers, RECORD_TOPICS
from i3dmgx2_driver.ros.record_publisher import RecordPublisher, Stamping
from packets import packet_of
import pytest
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import Imu
from std_msgs.msg import Bool

DIVIDER = 10
TICKS = ticks_per_cycle(DIVIDER)
PERIOD = TICKS / TICKS_PER_SECOND


@pytest.fixture
def records():
    """Return a record publisher of the inertial stream on a node of its own."""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node('record_publisher_test', context=context)
    stream = streams.parse('inertial')
    publishers = Publishers(((RECORD_TOPICS[0], node.create_publisher(Imu, 'imu/raw_data', 10)),),
                            None, node.create_publisher(Bool, '~/is_calibrated', calibrated_qos()))
    records = RecordPublisher(publishers, MessageSettings('imu_link', 'enu', stream=stream),
                              Stamping(device_time=True, offset=0.0, wire_time=0.0),
                              node.get_logger(), publishing=False)
    records.stream_known(TICKS, bias_kept=False)  # what the device side hands it
    yield records
    node.destroy_node()
    rclpy.shutdown(context=context)


def feed(records: RecordPublisher, cycles: list[int], start: float = 100.0) -> None:
    """Hand over one inertial record per cycle number, timer and read time in step."""
    for cycle in cycles:
        record = AccelAngRate((0.0, 0.0, -1.0), (0.0, 0.0, 0.0), 1000 + cycle * TICKS)
        mono = start + cycle * PERIOD
        records.on_record(packet_of(95, record, 0, 0), 1.7e9 + mono, mono)


def test_records_are_counted_not_published_until_publishing_is_on(records):
    feed(records, [0, 1, 2])
    assert (records.stats.published, records.stats.unpublished) == (0, 3)
    records.set_publishing(True)
    feed(records, [3, 4])
    assert (records.stats.published, records.stats.unpublished) == (2, 3)
    assert records.published() == (2, records.stats.last_time)


def test_a_timer_step_counts_the_records_in_between_as_lost(records):
    records.set_publishing(True)
    feed(records, [0, 1, 2, 5, 6])
    assert (records.stats.published, records.stats.lost) == (5, 2)


def test_a_deliberate_pause_is_no_loss(records):
    records.set_publishing(True)
    feed(records, [0, 1, 2])
    records.forget_last_sample()
    feed(records, [7, 8])
    assert (records.stats.published, records.stats.lost) == (5, 0)
