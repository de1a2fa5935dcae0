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
Temperatures polled in combined mode: published, and the IMU stream untouched.

The simulated sensor sits at about 25 C and warms by 2 C over ten minutes;
its 0xD1 replies are interleaved with the 0xCC stream, and must come out on
imu/temperature only, never as IMU messages, without a gap in the stream.
"""

from diagnostic_msgs.msg import DiagnosticArray
from harness.processes import isolate_ros_domain, Listener, NodeProcess, stamp_seconds
from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu, Temperature

pytestmark = pytest.mark.slow


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


def test_temperature_is_polled_and_published_while_streaming():
    with PtySimulator(SimulatorConfig(seed=61)) as sim:
        listener = Listener({'imu/raw_data': Imu, 'imu/temperature': Temperature,
                             '/diagnostics': DiagnosticArray})
        node = NodeProcess({'port': sim.port, 'address': 95, 'temperature_period': 0.2,
                            'frame_id': 'gx2'})
        with listener, node:
            temps = listener.wait_for('imu/temperature', 8, timeout=30)
            assert len(temps) >= 8, node.output()
            arrays = listener.wait_for('/diagnostics', 2, timeout=10)
            imu = listener.received('imu/raw_data')
            assert node.stop()[0] == 0
        for msg in temps:
            assert 23.0 < msg.temperature < 29.0
            assert msg.variance == 0.0
            assert msg.header.frame_id == 'gx2'
        stamps = [stamp_seconds(m) for m in temps]
        assert stamps == sorted(stamps) and stamps[0] > 1e9
        polls = [c for _, c in sim.commands if c.code == layouts.TEMPERATURES]
        assert len(polls) >= len(temps)
        # Combined mode: the stream ran on, and no 0xD1 reply became an IMU message.
        assert len(imu) >= 100
        stream = {s.name: s for s in arrays[-1].status}['i3dmgx2_driver: stream']
        values = {kv.key: kv.value for kv in stream.values}
        assert values['other records'] == '0'
        assert values['lost (timer gaps)'] == '0'
        device = {s.name: s for s in arrays[-1].status}['i3dmgx2_driver: device']
        celsius = {kv.key: kv.value for kv in device.values}['accel temperature (C)']
        assert 23.0 < float(celsius) < 29.0
