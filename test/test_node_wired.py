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
The node with ``wireless:=false`` against the wired simulator, end to end.

The wired sensor takes raw commands and answers wired records; the node must
stream from it and publish every record, exactly, without a base station.
"""

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.slow

G = 9.80665


def test_node_streams_from_a_wired_sensor_left_streaming():
    isolate_ros_domain()
    config = SimulatorConfig(wireless=False, seed=51, streaming_at_start=lay.ACCEL_ANG_RATE,
                             divider=256)
    with PtySimulator(config) as sim, Listener({'imu/raw_data': Imu}) as listener, \
            NodeProcess({'port': sim.port, 'address': 95, 'wireless': False,
                         'frame_convention': 'ned'}) as node:
        assert node.wait_for_output('streaming 0xCC'), node.output()
        messages = listener.wait_for('imu/raw_data', 100, timeout=30)
        code, _ = node.stop()
        assert code == 0, node.output()
        truth = {tuple(a * G for a in t.record.accel): t for t in sim.truth
                 if t.valid and isinstance(t.record, AccelAngRateMagOrientation)}
        matched = [truth.get((m.linear_acceleration.x, m.linear_acceleration.y,
                              m.linear_acceleration.z)) for m in messages]
        assert len(messages) >= 100 and all(t is not None for t in matched)
        indices = [t.index for t in matched]
        assert indices == sorted(set(indices)), 'each record once, in order'
        # The node stopped the 0xC2 stream it found, asked for 0xCC, wrote nothing.
        assert sim.stats.acks == sim.stats.pings == 0
        assert sim.eeprom_writes() == []
        assert [c for _, c in sim.stream_changes][:3] == [lay.ACCEL_ANG_RATE, 0, 0xCC]
        assert all(entry.kind == 'wired' for entry in sim.host_log)
