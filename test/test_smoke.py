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
The driver end to end, short: what a ROS distribution must carry for the driver to work.

The plain and the managed node against the simulator, a subscriber in this
process, a service call, ``/diagnostics``, and a clean stop. The other test
files prove each of these in depth on ROS 2 Jazzy; this one is what
``scripts/smoke.sh`` runs on another distribution (Kilted), in a virtual
environment of its own with only the runtime wheels, pytest and this tree.
It runs in the main suite too, so that it cannot rot unseen.
"""

from diagnostic_msgs.msg import DiagnosticArray
from harness.processes import ADDRESS, LIFECYCLE_COMMAND, LifecycleClient, Listener, NodeProcess
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

pytestmark = [pytest.mark.slow, pytest.mark.smoke]

TOPICS = {'imu/raw_data': Imu, '/diagnostics': DiagnosticArray}


def _diagnostics_name_the_sensor(listener: Listener) -> None:
    """Wait for ``/diagnostics``; assert it holds the driver's statuses."""
    arrays = listener.wait_for('/diagnostics', 1, timeout=15.0)
    assert arrays, 'no /diagnostics'
    names = [status.name for array in arrays for status in array.status]
    assert any('i3dmgx2' in name for name in names), names


def test_the_plain_node_streams_answers_a_service_and_stops_cleanly():
    with (PtySimulator(SimulatorConfig(seed=3)) as sim, Listener(TOPICS) as listener,
          NodeProcess({'port': sim.port, 'address': ADDRESS}) as node):
        got = listener.wait_for('imu/raw_data', 50, timeout=30.0)
        assert len(got) >= 50, node.output()
        assert all(msg.header.frame_id == 'imu_link' for msg in got), node.output()
        # The sample's orientation is a unit quaternion, as the node converts it.
        q = got[-1].orientation
        assert abs(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2 - 1.0) < 1e-6
        _diagnostics_name_the_sensor(listener)
        response = listener.call(Trigger, '/i3dmgx2_driver/self_test', 30.0)
        assert response is not None and response.success, (response, node.output())
        code, _ = node.stop()
        assert code == 0, node.output()


def test_the_managed_node_streams_only_when_active_and_stops_cleanly():
    with (PtySimulator(SimulatorConfig(seed=4)) as sim, Listener(TOPICS) as listener,
          NodeProcess({'port': sim.port, 'address': ADDRESS},
                      command=LIFECYCLE_COMMAND) as node):
        client = LifecycleClient(listener)
        assert client.wait_ready(), node.output()
        assert client.change('configure'), node.output()
        assert not listener.received('imu/raw_data'), 'data before activate'
        assert client.change('activate'), node.output()
        assert len(listener.wait_for('imu/raw_data', 50, timeout=30.0)) >= 50, node.output()
        _diagnostics_name_the_sensor(listener)
        assert client.change('deactivate'), node.output()
        code, _ = node.stop()
        assert code == 0, node.output()
