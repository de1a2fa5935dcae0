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
The fault capture in a running node: each fault writes a file, and a file replays.

A stall, a power cycle (a device reset), an unplug (a disconnect), a burst
of corrupted packets, a refused command (the base station NACKs the
temperature polls) and a call of ``~/save_capture`` each write a capture
named by its cause into ``fault_capture_dir``; the node logs where. Each
file, played back through a node of its own (``tools.replay``, from the
node's request for the stream on), is published as exactly the records the
capture holds, each once, and each one the node published when the fault
happened: a fault seen in the field is a test case offline.

One node meets the six in turn (the module's fixture); each capture is then
replayed in a test of its own.
"""

from collections import Counter
import os
import time

from typing import NamedTuple

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.capture.file_format import read_capture
from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.codec.framing import DataPacket
from i3dmgx2_driver.codec.parser import SensorStreamParser
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.tools.replay import Replayer
import pytest
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

pytestmark = [pytest.mark.slow, pytest.mark.long]

SECONDS = 3.0
#: The causes, in the order the field run meets them.
CAUSES = ('request', 'stall', 'device_reset', 'disconnect', 'corrupt', 'refused')


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


def key(m: Imu) -> tuple:
    """Return what identifies a published record: its acceleration and angular rate."""
    return (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z,
            m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z)


def files(directory) -> dict[str, str]:
    """Return the fault captures in ``directory`` by file name, with their cause."""
    names = sorted(os.listdir(directory)) if os.path.isdir(directory) else []
    return {name: read_capture(os.path.join(directory, name))[0]['cause'] for name in names}


def wait_for_cause(directory, cause: str, node: NodeProcess, timeout: float = 20.0) -> str:
    """Wait for a file whose cause names ``cause``; return its name."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for name, causes in files(directory).items():
            if cause in causes.split('+'):
                return name
        time.sleep(0.1)
    raise AssertionError(f'no {cause} capture in {files(directory)}:\n{node.output()}')


def node_parameters(port: str, directory) -> dict:
    return {'port': port, 'address': 95, 'fault_capture_dir': str(directory),
            'fault_capture_seconds': SECONDS, 'fault_captures_kept': 10,
            'read_timeout': 0.5, 'temperature_period': 0.2}


class FieldRun(NamedTuple):
    """What the node met in the field: its captures, what it published, what it said."""

    directory: object
    #: The capture file of each cause.
    names: dict[str, str]
    #: Every record published, by its identity, with how often.
    published: Counter
    output: str
    port: str


@pytest.fixture(scope='module')
def field(tmp_path_factory) -> FieldRun:
    """Take one node through the six faults, each its own episode, every record kept."""
    isolate_ros_domain()
    directory = tmp_path_factory.mktemp('field') / 'faults'
    names: dict[str, str] = {}
    with PtySimulator(SimulatorConfig(seed=81)) as sim:
        listener = Listener({'imu/raw_data': Imu}, depth=20000)
        node = NodeProcess(node_parameters(sim.port, directory))
        with listener, node:
            assert node.wait_for_output('fault capture: the last 3 s', timeout=30), \
                node.output()
            assert len(listener.wait_for('imu/raw_data', 100, timeout=30)) >= 100, \
                node.output()
            assert not files(directory), 'a start is no fault'
            # The capture asked for holds the last SECONDS: let them all be seconds this
            # listener heard. Its subscription may match the node's publisher a second or two
            # after the stream starts on a busy machine, and a record the node published
            # before then would count as one the replay published and the field did not.
            time.sleep(SECONDS + 0.5)
            reply = listener.call(Trigger, '/i3dmgx2_driver/save_capture')
            assert reply.success, reply.message
            names['request'] = os.path.basename(reply.message)
            time.sleep(SECONDS)  # the next fault, a new episode
            sim.stall(1.5)
            names['stall'] = wait_for_cause(directory, 'stall', node)
            time.sleep(SECONDS)
            sim.power_cycle(off_seconds=0.2, timer_start=12345)
            names['device_reset'] = wait_for_cause(directory, 'device_reset', node)
            time.sleep(SECONDS)
            sim.unplug(1.0)
            names['disconnect'] = wait_for_cause(directory, 'disconnect', node)
            time.sleep(SECONDS)
            sim.set_faults(corrupt_checksum_probability=0.5)
            time.sleep(1.0)
            sim.set_faults(corrupt_checksum_probability=0.0)
            names['corrupt'] = wait_for_cause(directory, 'corrupt', node)
            time.sleep(SECONDS)
            # The base station refuses the temperature polls made while streaming.
            sim.set_faults(nack_probability=1.0)
            names['refused'] = wait_for_cause(directory, 'refused', node)
            sim.set_faults(nack_probability=0.0)
            time.sleep(1.0)
            assert node.stop()[0] == 0
            published = Counter(key(m) for m in listener.received('imu/raw_data'))
            return FieldRun(directory, names, published, node.output(), sim.port)


def test_each_fault_writes_a_capture_named_by_its_cause(field):
    directory = field.directory
    written = files(directory)
    assert set(field.names.values()) <= set(written)
    assert written[field.names['request']] == 'request'
    for cause, name in field.names.items():
        assert cause in written[name].split('+'), (cause, written)
    assert f'written to {directory / field.names["disconnect"]}' in field.output
    assert 'capture saved on request' in field.output
    assert 'Traceback' not in field.output, field.output
    # Each file holds the seconds kept, up to its fault (and FAULT_AFTER after it).
    for name in written:
        header, chunks = read_capture(directory / name)
        times = [t for t, _ in chunks]
        assert times and times[-1] - times[0] <= SECONDS
        assert header['port'] == field.port and header['address'] == 95


def streamed_records(chunks) -> int:
    """Count the streamed records (0xCC of node 95) a capture holds, checksums good."""
    parser = SensorStreamParser(address=95)
    record_type = layouts.LAYOUTS[layouts.ACCEL_ANG_RATE_MAG_ORIENTATION].record_type
    return sum(1 for _, data in chunks for e in parser.feed(data)
               if isinstance(e, DataPacket) and isinstance(e.record, record_type))


@pytest.mark.parametrize('cause', CAUSES)
def test_each_capture_replays_into_the_records_published_at_the_time(field, cause, tmp_path):
    chunks = list(read_capture(field.directory / field.names[cause])[1])
    expected = streamed_records(chunks)
    assert expected >= 100
    # Played from the node's request for the stream on, at the recorded pace: the
    # node's own faults (a stall, a reset, a lost stream) come as they came.
    replayer = Replayer(chunks, wait_for_stream=True)
    replayer.start()
    listener = Listener({'imu/raw_data': Imu}, depth=5000)
    node = NodeProcess(node_parameters(replayer.port, "''"))
    try:
        assert replayer.wait(60), f'the playback did not end:\n{node.output()}'
        replayer.drain(5.0)
        time.sleep(1.0)
        assert node.stop()[0] == 0
        replayed = Counter(key(m) for m in listener.received('imu/raw_data'))
    finally:
        node.close()
        listener.close()
        replayer.stop()
    extra = {v: n for v, n in replayed.items() if n > field.published[v]}
    assert not extra, f'replayed records the node did not publish as often: {extra}'
    assert sum(replayed.values()) == expected, (sum(replayed.values()), expected,
                                                node.output())
