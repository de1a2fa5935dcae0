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
named by its cause into ``fault_capture_dir``; the node logs where. A file
played back through the node (``tools.replay``) is published as the same
records the node published when the fault happened: a fault seen in the
field is a test case offline.
"""

from collections import Counter
import os
import time

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.capture import read_capture
from i3dmgx2_driver.codec.framing import DataPacket
from i3dmgx2_driver.codec.parser import SensorStreamParser
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.tools.replay import Replayer, schedule
import pytest
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

pytestmark = pytest.mark.slow

SECONDS = 3.0


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


def node_parameters(sim: PtySimulator, directory) -> dict:
    return {'port': sim.port, 'address': 95, 'fault_capture_dir': str(directory),
            'fault_capture_seconds': SECONDS, 'fault_captures_kept': 10,
            'read_timeout': 0.5}


def test_each_fault_writes_a_capture_named_by_its_cause(tmp_path):
    directory = tmp_path / 'faults'
    with PtySimulator(SimulatorConfig(seed=81)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess(dict(node_parameters(sim, directory), temperature_period=0.2))
        with listener, node:
            assert node.wait_for_output('fault capture: the last 3 s', timeout=30), \
                node.output()
            assert len(listener.wait_for('imu/raw_data', 100, timeout=30)) >= 100, \
                node.output()
            assert not files(directory), 'a start is no fault'
            reply = listener.call(Trigger, '/i3dmgx2_driver/save_capture')
            assert reply.success and os.path.basename(reply.message) in files(directory)
            assert files(directory)[os.path.basename(reply.message)] == 'request'
            sim.stall(1.5)
            wait_for_cause(directory, 'stall', node)
            time.sleep(SECONDS)  # the next fault, a new episode
            sim.power_cycle(off_seconds=0.2, timer_start=12345)
            wait_for_cause(directory, 'device_reset', node)
            time.sleep(SECONDS)
            sim.unplug(1.0)
            name = wait_for_cause(directory, 'disconnect', node)
            time.sleep(SECONDS)
            sim.set_faults(corrupt_checksum_probability=0.5)
            time.sleep(1.0)
            sim.set_faults(corrupt_checksum_probability=0.0)
            wait_for_cause(directory, 'corrupt', node)
            time.sleep(SECONDS)
            # The base station refuses the temperature polls made while streaming.
            sim.set_faults(nack_probability=1.0)
            wait_for_cause(directory, 'refused', node)
            sim.set_faults(nack_probability=0.0)
            assert node.stop()[0] == 0
            output = node.output()
    assert f'written to {directory / name}' in output
    assert 'capture saved on request' in output
    assert 'Traceback' not in output, output
    # Each file holds the seconds kept, up to its fault (and FAULT_AFTER after it).
    for name in files(directory):
        header, chunks = read_capture(directory / name)
        times = [t for t, _ in chunks]
        assert times and times[-1] - times[0] <= SECONDS
        assert header['port'] == sim.port and header['address'] == 95


def test_a_stall_capture_replays_into_the_records_published_at_the_time(tmp_path):
    directory = tmp_path / 'faults'
    with PtySimulator(SimulatorConfig(seed=82)) as sim:
        listener = Listener({'imu/raw_data': Imu}, depth=5000)
        node = NodeProcess(dict(node_parameters(sim, directory), time_source='host'))
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', 300, timeout=30)) >= 300, \
                node.output()
            sim.stall(1.0)
            name = wait_for_cause(directory, 'stall', node)
            assert node.stop()[0] == 0
            published = Counter(key(m) for m in listener.received('imu/raw_data'))
    chunks = list(read_capture(directory / name)[1])
    parser = SensorStreamParser(address=95)
    records = [e for _, data in chunks for e in parser.feed(data) if isinstance(e, DataPacket)]
    assert len(records) >= 100
    # Played back as the node read it (its silence cut to 1 s), slowly enough that the
    # node is streaming after its dialogue with a device that answers nothing (~12 s).
    speed = schedule([t for t, _ in chunks], max_gap=1.0)[-1] / 30.0
    replayer = Replayer(chunks, speed=speed, max_gap=1.0, wait_for_host=True)
    replayer.start()
    listener = Listener({'imu/raw_data': Imu}, depth=5000)
    node = NodeProcess({'port': replayer.port, 'address': 95, 'time_source': 'host',
                        'fault_capture_dir': "''"})
    try:
        assert node.wait_for_output('streaming 0xCC', timeout=60), node.output()
        assert replayer.wait(45), 'the playback did not end'
        replayer.drain(5.0)
        time.sleep(0.5)
        assert node.stop()[0] == 0
        replayed = Counter(key(m) for m in listener.received('imu/raw_data'))
    finally:
        node.close()
        listener.close()
        replayer.stop()
    assert sum(replayed.values()) >= len(records) // 4, node.output()
    assert set(replayed) <= set(published), 'a replayed record the node never published'
    assert all(n <= published[v] for v, n in replayed.items()), 'a record published twice'
