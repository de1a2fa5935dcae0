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
Parameters, bad and good.

Bad values stop the node with a message naming the parameter and its valid
range; good ones do what they say (data rate, params file, namespace and
remapping, QoS).
"""

import itertools
import os

from harness.processes import isolate_ros_domain, Listener, NodeProcess, REPO
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.slow


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


@pytest.mark.parametrize('params, expected', [
    ({}, "parameter 'address' is required: set it with -p address:=<value> (1..65534)"),
    ({'address': 0}, "parameter 'address' must be 1..65534, got 0"),
    ({'address': 65535}, "parameter 'address' must be 1..65534, got 65535"),
    ({'address': 'abc'}, "parameter 'address' must be 1..65534, written as an integer"),
    ({'address': 95, 'frame_convention': 'xyz'},
     "parameter 'frame_convention' must be one of 'enu', 'ned', got 'xyz'"),
    ({'address': 95, 'time_source': 'gps'},
     "parameter 'time_source' must be one of 'device', 'host', got 'gps'"),
    ({'address': 95, 'qos_reliability': 'sometimes'},
     "parameter 'qos_reliability' must be one of 'reliable', 'best_effort'"),
    ({'address': 95, 'data_rate': 0.5},
     "parameter 'data_rate' must be 0 (leave the device as it is) or 1..301.2 Hz, got 0.5"),
    ({'address': 95, 'data_rate': 400.0},
     "parameter 'data_rate' must be 0 (leave the device as it is) or 1..301.2 Hz, got 400.0"),
    # As typed: rcl reads 400 as an integer.
    ({'address': 95, 'data_rate': 400}, 'Hz, got 400\n'),
    ({'address': 95, 'qos_depth': 0}, "parameter 'qos_depth' must be 1..1000, got 0"),
    ({'address': 95, 'baud': 1200}, "parameter 'baud' must be 9600..921600, got 1200"),
    # An integer stands for a double (300 for 300.0), within the range still.
    ({'address': 95, 'read_timeout': 100}, "parameter 'read_timeout' must be 0.1..60, got 100"),
    # But a double where an integer is wanted is refused.
    ({'address': 95.0}, "parameter 'address' must be 1..65534, written as an integer"),
    ({'address': 95, 'stream': 'fast'},
     "parameter 'stream' must be one of 'full', 'inertial_orientation', 'inertial_mag', "
     "'inertial', 'euler', 'stabilised', or a command byte: 0xCC, 0xC8, 0xCB, 0xC2, 0xCF, "
     "0xD2, got 'fast'"),
    # rcl reads 0xC5 as the integer 197: the message shows the byte as typed.
    ({'address': 95, 'stream': '0xC5'}, "parameter 'stream' must be one of 'full'"),
    ({'address': 95, 'stream': '0xC5'}, "got '0xC5'"),
    ({'address': 95, 'orientation_stddev': -1.0},
     "parameter 'orientation_stddev' must be 0..10, got -1.0"),
    ({'address': 95, 'time_offset': 11.0}, "parameter 'time_offset' must be -10..10, got 11.0"),
    # rclpy's QoS parameters: a bad one stops the node like ours, no traceback.
    ({'address': 95, 'qos_overrides./imu/raw_data.publisher.reliability': 'sometimes'},
     "parameter 'qos_overrides./imu/raw_data.publisher.reliability' must be one of "
     "'system_default', 'reliable', 'best_effort', 'best_available', got 'sometimes'"),
    ({'address': 95, 'qos_overrides./imu/raw_data.publisher.depth': -3},
     "parameter 'qos_overrides./imu/raw_data.publisher.depth' must be 0..2147483647 "
     '(0: the system default), got -3'),
    ({'address': 95, 'frame_id': "''"}, "parameter 'frame_id' must be a non-empty string"),
], ids=lambda v: str(v)[:40])
def test_bad_parameter_stops_node_with_message(params, expected):
    node = NodeProcess(params)
    with node:
        assert node.wait(timeout=30) == 2
        assert expected in node.output(), node.output()
        assert 'Traceback' not in node.output(), node.output()


def test_params_file_is_read():
    with PtySimulator(SimulatorConfig(seed=31)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        # -p after --params-file wins (the file's key is /**, like -p's).
        node = NodeProcess(
            {}, extra_args=['--params-file', os.path.join(REPO, 'config', 'i3dmgx2.yaml'),
                            '-p', f'port:={sim.port}', '-p', 'address:=95',
                            '-p', 'frame_id:=from_cli'])
        with listener, node:
            got = listener.wait_for('imu/raw_data', 10, timeout=30)
            assert len(got) >= 10, node.output()
            assert got[0].header.frame_id == 'from_cli'
            assert node.stop()[0] == 0


def test_params_file_without_address_is_refused():
    node = NodeProcess({}, extra_args=[
        '--params-file', os.path.join(REPO, 'config', 'i3dmgx2.yaml')])
    with node:
        assert node.wait(timeout=30) == 2
        assert "parameter 'address' is required" in node.output()


def test_namespace_moves_every_topic():
    with PtySimulator(SimulatorConfig(seed=32)) as sim:
        listener = Listener({'/robot1/imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95},
                           extra_args=['-r', '__ns:=/robot1'])
        with listener, node:
            assert len(listener.wait_for('/robot1/imu/raw_data', 10, timeout=30)) >= 10, \
                node.output()
            assert node.stop()[0] == 0


def test_best_effort_qos_reaches_best_effort_subscriber():
    with PtySimulator(SimulatorConfig(seed=33)) as sim:
        listener = Listener({'imu/raw_data': Imu}, reliable=False)
        node = NodeProcess({'port': sim.port, 'address': 95,
                            'qos_reliability': 'best_effort', 'qos_depth': 5})
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', 10, timeout=30)) >= 10, \
                node.output()
            assert node.stop()[0] == 0


def eeprom_writes(sim):
    return [c for _, c in sim.commands if c.code == 0xE4]


def test_data_rate_written_verified_and_persisted():
    with PtySimulator(SimulatorConfig(seed=34)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95, 'data_rate': 50.0})
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', 20, timeout=30)) >= 20
            writes = eeprom_writes(sim)
            assert [c.args for c in writes] == [(0xFCA2, 1024)]
            reads = [c for _, c in sim.commands if c.code == 0xE5]
            assert len(reads) >= 2  # before and after the write
            assert 'persists across power cycles' in node.output()
            assert '50.0 Hz' in node.output()
            assert sim.sensor.eeprom[0xFCA2] == 1024
            # Spacing of the device timer: 384 ticks per divider unit (+ clock error).
            timers = [t.timer for t in sim.truth[-10:] if t.source == 'stream']
            steps = {(b - a) % 2**32 for a, b in itertools.pairwise(timers)}
            assert all(abs(s - 384 * 1024) < 50 for s in steps)
            assert node.stop()[0] == 0
        # The same rate again: nothing written.
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95, 'data_rate': 50.0})
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', 5, timeout=30)) >= 5
            assert len(eeprom_writes(sim)) == 1
            assert node.stop()[0] == 0
