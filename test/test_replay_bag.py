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
``replay FILE --bag OUT``: a capture as the node's messages, in a bag any ROS tool opens.

A short capture of a still sensor (0xCC through the base station, one
temperature reply among its records) is written as an MCAP bag and read
back with rosbags' own reader and deserializer, which share no code with
the driver: the node's topics and types, one Imu per record, the values in
REP-103 axes and SI units, stamps from the sensor's timer, the field in
tesla, the temperature. ``noise --bag`` reads it back, and a sqlite3 bag too.
"""

from pathlib import Path
import sys

from i3dmgx2_driver.capture.file_format import CaptureWriter, default_header
from i3dmgx2_driver.codec import framing
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.codec.commands import encode_record
from i3dmgx2_driver.codec.parser import SensorStreamParser
from i3dmgx2_driver.simulator.still_capture import still_chunks
from i3dmgx2_driver.tools import noise, replay
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Writer
from rosbags.typesys import get_typestore, Stores

RECORDS = 1200
GRAVITY = 9.80665


@pytest.fixture(scope='module')
def capture(tmp_path_factory):
    """Twelve seconds at 100 Hz of 0xCC (noise needs 10), a temperature reply after record 250."""
    path = tmp_path_factory.mktemp('bag') / 'still.gx2cap'
    chunks = list(still_chunks(12.0, 100.0, lay.ACCEL_ANG_RATE_MAG_ORIENTATION, seed=7,
                               per_read=1))
    reply = framing.encode_data_packet(95, encode_record(rec.Temperatures(1900, (1910, 1915, 1905),
                                                                          123)), 220, 180)
    chunks.insert(250, (chunks[249][0] + 0.002, reply))
    with CaptureWriter(path, default_header(address=95, wireless=True),
                       flush_interval=None) as writer:
        for receive_time, data in chunks:
            writer.write(data, receive_time)
    parser = SensorStreamParser(95, True)
    records = [e.record for _, d in chunks for e in parser.feed(d)]
    return path, records, chunks


@pytest.fixture(scope='module')
def bag(capture, tmp_path_factory):
    out = tmp_path_factory.mktemp('out') / 'still_bag'
    assert replay.main([str(capture[0]), '--bag', str(out)]) == 0
    return out


def read_back(path: Path) -> dict:
    messages: dict = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for connection, time_ns, raw in reader.messages():
            messages.setdefault(connection.topic, []).append(
                (time_ns, reader.deserialize(raw, connection.msgtype)))
    return {'types': types, 'messages': messages}


def test_the_bag_holds_the_nodes_topics_and_types_in_mcap(bag):
    assert (bag / 'metadata.yaml').is_file() and list(bag.glob('*.mcap'))
    got = read_back(bag)
    assert got['types'] == {'/imu/raw_data': 'sensor_msgs/msg/Imu',
                            '/imu/mag': 'sensor_msgs/msg/MagneticField',
                            '/imu/temperature': 'sensor_msgs/msg/Temperature'}
    counts = {topic: len(m) for topic, m in got['messages'].items()}
    assert counts == {'/imu/raw_data': RECORDS, '/imu/mag': RECORDS, '/imu/temperature': 1}


def test_each_imu_message_is_its_record_in_rep103_si_stamped_by_the_sensor_timer(capture, bag):
    _, records, chunks = capture
    data = [r for r in records if isinstance(r, rec.AccelAngRateMagOrientation)]
    got = read_back(bag)['messages']
    imu = [m for _, m in got['/imu/raw_data']]
    assert all(m.header.frame_id == 'imu_link' for m in imu)
    rate = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
                     for m in imu])
    accel = np.array([[m.linear_acceleration.x, m.linear_acceleration.y,
                       m.linear_acceleration.z] for m in imu])
    # FRD to FLU: y and z change sign; g to m/s^2.
    signs = np.array([1.0, -1.0, -1.0])
    assert np.allclose(rate, np.array([r.angular_rate for r in data]) * signs, rtol=0, atol=1e-12)
    assert np.allclose(accel, np.array([r.accel for r in data]) * signs * GRAVITY,
                       rtol=0, atol=1e-9)
    field = np.array([[m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z]
                      for _, m in got['/imu/mag']])
    assert np.allclose(field, np.array([r.mag for r in data]) * signs * 1e-4, atol=1e-15)
    assert imu[0].angular_velocity_covariance[0] == pytest.approx(0.012 ** 2)
    stamps = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in imu])
    # Stamped from the timer: 10 ms apart (the sensor's clock, not the reads' times).
    assert np.allclose(np.diff(stamps), 0.01, atol=2e-4)
    assert abs(stamps[0] - chunks[0][0]) < 0.05
    # The bag's own times are the reads'.
    times = [t for t, _ in got['/imu/raw_data']]
    assert times[0] == round(chunks[0][0] * 1e9)


def test_the_temperature_is_the_accelerometers_stamped_at_its_read(capture, bag):
    _, records, chunks = capture
    (_, temperature), = read_back(bag)['messages']['/imu/temperature']
    expected = next(r for r in records if isinstance(r, rec.Temperatures)).accel_celsius
    assert temperature.temperature == pytest.approx(expected)
    assert temperature.header.stamp.sec + temperature.header.stamp.nanosec * 1e-9 == \
        pytest.approx(chunks[250][0], abs=1e-6)
    assert temperature.header.frame_id == 'imu_link'


def test_noise_reads_an_mcap_bag_and_a_sqlite3_bag(bag, tmp_path, capsys):
    assert noise.main(['--bag', str(bag)]) == noise.MARKED     # 12 s: B and K too short
    mcap_out = capsys.readouterr().out
    assert '1200 samples' in mcap_out
    # The same messages in a sqlite3 bag, as `ros2 bag record` writes by default on Humble.
    sqlite = tmp_path / 'sqlite_bag'
    store = get_typestore(Stores.ROS2_JAZZY)
    with AnyReader([bag], default_typestore=store) as reader, \
            Writer(sqlite, version=8) as writer:
        connections = {}
        for connection, time_ns, raw in reader.messages():
            if connection.topic not in connections:
                connections[connection.topic] = writer.add_connection(
                    connection.topic, connection.msgtype, typestore=store)
            writer.write(connections[connection.topic], time_ns, raw)
    assert noise.main(['--bag', str(sqlite)]) == noise.MARKED
    sqlite_out = capsys.readouterr().out
    # The same figures from either storage.
    strip = [line for line in sqlite_out.splitlines() if line.startswith('  ')]
    assert strip == [line for line in mcap_out.splitlines() if line.startswith('  ')]
    assert noise.main(['--bag', str(sqlite), '--topic', '/nothing']) == 1
    assert "no topic '/nothing'; its Imu topics: /imu/raw_data" in capsys.readouterr().err


def test_without_rosbags_both_tools_say_how_to_install_it(capture, tmp_path, monkeypatch,
                                                          capsys):
    for name in ('rosbags', 'rosbags.highlevel', 'rosbags.rosbag2', 'rosbags.typesys'):
        monkeypatch.setitem(sys.modules, name, None)
    assert replay.main([str(capture[0]), '--bag', str(tmp_path / 'out')]) == 1
    assert 'pip install rosbags' in capsys.readouterr().err
    assert noise.main(['--bag', str(tmp_path / 'any')]) == 1
    assert 'pip install rosbags' in capsys.readouterr().err
