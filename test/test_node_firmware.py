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
The node against a sensor whose firmware lacks commands: real processes, the simulator.

A stream the firmware lacks stops the plain node with exit 2 and one FATAL
line that names the stream, its record, both firmwares and the streams the
sensor offers; the managed node's configure fails with the same words.
Several sensors are each taken by their own firmware: the old one's
temperature is never polled (one warning, /diagnostics says it is
unavailable, no fault) and its bias store is refused at once, while the
newer one's temperature is polled as always. Every boundary of every gated
command is test_firmware.py's, without processes.
"""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from harness.processes import (
    isolate_ros_domain, LIFECYCLE_COMMAND, LifecycleClient, Listener, NodeProcess,
)
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Temperature
from std_srvs.srv import Trigger

pytestmark = pytest.mark.slow

EULER_WORDS = ('node 17: stream euler (0xCF) needs firmware 2.1.05; this sensor has 2.1.03; '
               'it offers full, inertial_orientation, inertial_mag, inertial')


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


def asked(sim: PtySimulator, address: int, code: int) -> list:
    """Return the commands ``code`` sent to ``address`` (0xC4 counts for the record it asks)."""
    commands = [entry.command for entry in sim.host_log
                if entry.address == address and entry.command is not None]
    return [c for c in commands
            if c.code == code or (c.code == lay.SET_CONTINUOUS and c.args[0] == code)]


def test_a_stream_the_firmware_lacks_exits_2_and_fails_configure_with_the_same_words():
    # Sensor 17 has 2.1.03, sensor 95 everything: the plain node serves 17 alone, the
    # managed node both, and 17's firmware fails its configure whatever 95 answers.
    config = SimulatorConfig(addresses=(17, 95), seed=91, firmware_versions={17: 2103})
    with PtySimulator(config) as sim:
        with NodeProcess({'port': sim.port, 'address': 17, 'stream': 'euler'}) as plain:
            assert plain.wait(timeout=30) == 2, plain.output()
            output = plain.output()
        fatal = [line for line in output.splitlines() if '[FATAL]' in line]
        assert len(fatal) == 1 and EULER_WORDS in fatal[0], output
        assert 'retrying' not in output and 'streaming' not in output
        params = {'port': sim.port, 'addresses': [17, 95], 'stream': 'euler'}
        with Listener({}) as listener, NodeProcess(params, command=LIFECYCLE_COMMAND) as node:
            client = LifecycleClient(listener)
            assert client.wait_ready(), node.output()
            assert not client.change('configure')
            assert client.state() == 'unconfigured'
            assert f'configure failed: {EULER_WORDS}' in node.output(), node.output()
            assert node.stop()[0] == 0
        assert asked(sim, 17, lay.EULER_ANGLES_ANG_RATE) == [], 'never asked for'


def test_several_sensors_each_by_its_own_firmware():
    config = SimulatorConfig(addresses=(17, 95), seed=92, firmware_versions={17: 2103})
    with PtySimulator(config) as sim:
        listener = Listener({'imu_95/temperature': Temperature, 'imu_17/temperature': Temperature,
                             '/diagnostics': DiagnosticArray})
        node = NodeProcess({'port': sim.port, 'addresses': [17, 95], 'stream': 'inertial',
                            'temperature_period': 0.3})
        with listener, node:
            assert len(listener.wait_for('imu_95/temperature', 3, timeout=30)) >= 3, \
                node.output()
            store = listener.call(Trigger, '/i3dmgx2_driver/imu_17/store_gyro_bias')
            listener.clear()
            arrays = listener.wait_for('/diagnostics', 4, timeout=10)
            assert node.stop()[0] == 0
            output = node.output()
        assert not store.success
        assert store.message.startswith('refused: the gyro bias store (0xD0) needs firmware '
                                        '2.1.12; this sensor has 2.1.03. Nothing sent')
        assert listener.received('imu_17/temperature') == []
        warned = [line for line in output.splitlines() if 'temperature is not polled' in line]
        assert len(warned) == 1, output
        assert 'the temperature poll (0xD1) needs firmware 2.1.12; this sensor has 2.1.03' \
            in warned[0]
        devices = {s.name: s for a in arrays for s in a.status if s.name.endswith('device')}
        old = devices['i3dmgx2_driver: imu_17: device']
        assert old.level == DiagnosticStatus.OK, old.message
        assert {kv.key: kv.value for kv in old.values}['accel temperature (C)'] == (
            'unavailable on this firmware: the temperature poll (0xD1) needs firmware 2.1.12; '
            'this sensor has 2.1.03')
        new = {kv.key: kv.value for kv in devices['i3dmgx2_driver: imu_95: device'].values}
        assert 20.0 < float(new['accel temperature (C)']) < 30.0
        assert asked(sim, 17, lay.TEMPERATURES) == [] and asked(sim, 17, 0xD0) == []
        assert len(asked(sim, 95, lay.TEMPERATURES)) >= 3
