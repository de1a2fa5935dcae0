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
A problem seen in the field, reproduced offline: the node reads a replay.

The real-records fixture is replayed into a pseudo-terminal as a capture
would be; the replay answers no request (it only ACKs), so this also proves
the node streams from a device that never answers its dialogue. Every
message published carries exactly the values of a real record.
"""

from collections import Counter

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.capture.fixtures import fixture_chunks, load_fixture
from i3dmgx2_driver.codec.commands import decode_record
from i3dmgx2_driver.tools.replay import Replayer, schedule
import pytest
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.slow

G = 9.80665


def key(*values: float) -> tuple:
    """Return what identifies a record: its acceleration and angular rate."""
    return values


def test_node_publishes_the_real_records_of_a_replay(fixture_path):
    isolate_ros_domain()
    records = [decode_record(r) for s in load_fixture(fixture_path) for r in s.records]
    # ENU: accel (x, -y, -z) in m/s^2 and rate (x, -y, -z), exactly as the node computes
    # them; a few real records repeat (a sensor at rest), so count them.
    expected = Counter(key(r.accel[0] * G, -r.accel[1] * G, -r.accel[2] * G,
                           r.angular_rate[0], -r.angular_rate[1], -r.angular_rate[2])
                       for r in records)
    chunks = list(fixture_chunks(fixture_path))
    # A pace at which the replay lasts ~40 s: longer than the node's dialogue with a
    # device that answers nothing (~12 s), so the node is streaming well before the end.
    # Silences of the recording (between its four captures) are cut to 1 s.
    speed = schedule([t for t, _ in chunks], max_gap=1.0)[-1] / 40.0
    replayer = Replayer(chunks, speed=speed, max_gap=1.0, wait_for_host=True)
    replayer.start()
    listener = Listener({'imu/raw_data': Imu}, depth=5000)
    node = NodeProcess({'port': replayer.port, 'address': 95, 'time_source': 'host'})
    try:
        # No answer to ping, polls, identity or EEPROM: the node says so and streams on.
        assert node.wait_for_output('did not tell its data rate', timeout=60), node.output()
        assert node.wait_for_output('streaming 0xCC', timeout=30), node.output()
        assert node.stop()[0] == 0
        got = listener.received('imu/raw_data')
        assert 300 <= len(got) < len(records), 'expected part of one pass of the fixture'
        values = Counter(key(m.linear_acceleration.x, m.linear_acceleration.y,
                             m.linear_acceleration.z, m.angular_velocity.x,
                             m.angular_velocity.y, m.angular_velocity.z) for m in got)
        assert set(values) <= set(expected), 'a message carries no real record'
        assert all(n <= expected[v] for v, n in values.items()), 'a record published twice'
    finally:
        node.close()
        listener.close()
        replayer.stop()
