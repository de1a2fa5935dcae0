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
The standard ROS mechanisms, seen from another process as any ROS user sees them.

The node runs as its executable against the simulator; this process looks at
it through rclpy only: the QoS its publishers really have (the graph's
``get_publishers_info_by_topic``, as ``ros2 topic info -v`` shows it), the
stamps against the simulator's true sample times, ``~/is_calibrated`` and
the diagnostic_msgs/SelfTest service.
"""

import statistics
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from diagnostic_msgs.srv import SelfTest
from harness.processes import (
    isolate_ros_domain, LIFECYCLE_COMMAND, LifecycleClient, Listener, NodeProcess,
    stamp_seconds,
)
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.motion import MotionConfig
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField
from std_msgs.msg import Bool
from std_srvs.srv import Trigger
from test_node_messages import match, stream_truth

pytestmark = pytest.mark.slow

NODE = '/i3dmgx2_driver'
OFFSET = 0.25
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Latched:
    """A transient-local subscription to ``~/is_calibrated`` on the listener's node."""

    def __init__(self, listener: Listener, node: str = NODE) -> None:
        self.values: list[bool] = []
        self._node = listener.node
        self._subscription = listener.node.create_subscription(
            Bool, f'{node}/is_calibrated', lambda msg: self.values.append(msg.data), LATCHED)

    def wait(self, count: int, timeout: float = 20.0) -> list[bool]:
        deadline = time.monotonic() + timeout
        while len(self.values) < count and time.monotonic() < deadline:
            time.sleep(0.02)
        return list(self.values)

    def close(self) -> None:
        self._node.destroy_subscription(self._subscription)


def call(listener: Listener, kind: type, name: str, timeout: float = 30.0) -> object:
    """Call a service of the node from the listener's node; return the response."""
    return listener.call(kind, f'{NODE}/{name}', timeout)


def publisher_qos(listener: Listener, topic: str, node: str = NODE,
                  timeout: float = 10.0) -> QoSProfile:
    """Return the QoS of the driver's one publisher on ``topic``, from the ROS graph."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        infos = [i for i in listener.node.get_publishers_info_by_topic(topic)
                 if i.node_name == node[1:]]
        if infos:
            (info,) = infos
            return info.qos_profile
        time.sleep(0.05)
    raise AssertionError(f'no publisher of the driver on {topic}')


@pytest.fixture(scope='module')
def rig():
    isolate_ros_domain()
    config = SimulatorConfig(seed=71, motion=MotionConfig(static=True))
    with PtySimulator(config) as sim:
        # Best effort: the publisher is made best effort through rclpy's parameter.
        listener = Listener({'imu/raw_data': Imu, 'imu/mag': MagneticField,
                             '/diagnostics': DiagnosticArray}, reliable=False)
        latched = Latched(listener)
        node = NodeProcess({
            'port': sim.port, 'address': 95, 'gyro_bias_sampling_ms': 400,
            'time_offset': OFFSET,
            'qos_overrides./imu/raw_data.publisher.reliability': 'best_effort',
            'qos_overrides./imu/raw_data.publisher.depth': 7})
        with listener, node:
            assert node.wait_for_output('(first record received)', timeout=30), node.output()
            yield sim, listener, node, latched
            latched.close()
            assert node.stop()[0] == 0, node.output()


def test_qos_overrides_parameter_sets_the_publishers_qos(rig):
    _, listener, node, _ = rig
    assert publisher_qos(listener, '/imu/raw_data').reliability == \
        ReliabilityPolicy.BEST_EFFORT
    # The other topics keep the driver's default.
    assert publisher_qos(listener, '/imu/mag').reliability == ReliabilityPolicy.RELIABLE
    assert publisher_qos(listener, f'{NODE}/is_calibrated').durability == \
        DurabilityPolicy.TRANSIENT_LOCAL
    assert len(listener.wait_for('imu/raw_data', 20)) >= 20
    output = node.output()
    assert 'deprecated' not in output and 'unknown parameter' not in output, output


def test_time_offset_is_added_to_every_stamp_and_shown_on_diagnostics(rig):
    sim, listener, node, _ = rig
    listener.clear()
    messages = listener.wait_for('imu/raw_data', 200, timeout=20)
    pairs = [(m, t) for m, t in match(messages, stream_truth(sim), 'enu') if t is not None]
    assert len(pairs) > 150
    errors = [stamp_seconds(m) - t.sample_time for m, t in pairs]
    # Without the offset the stamps are within a millisecond of the true sample
    # times (test_node_stamps.py); with it, that far later, every one of them.
    assert statistics.median(errors) == pytest.approx(OFFSET, abs=0.005)
    assert all(abs(e - OFFSET) < 0.02 for e in errors), (min(errors), max(errors))
    arrays = listener.wait_for('/diagnostics', 2, timeout=10)
    (time_status,) = [s for s in arrays[-1].status if s.name == 'i3dmgx2_driver: time']
    assert {kv.key: kv.value for kv in time_status.values}['time offset (s)'] == '+0.250000'
    assert 'time offset +0.25 s' in node.output()


def test_is_calibrated_is_false_until_a_capture_then_true_and_latched(rig):
    _, listener, _, latched = rig
    assert latched.wait(1) == [False]
    response = call(listener, Trigger, 'capture_gyro_bias')
    assert response.success, response.message
    assert latched.wait(2) == [False, True]
    # A subscriber that comes later gets the last value at once (transient local).
    late = Latched(listener)
    try:
        assert late.wait(1) == [True]
    finally:
        late.close()


def test_self_test_is_served_as_diagnostic_msgs_self_test(rig):
    listener = rig[1]
    response = call(listener, SelfTest, 'diagnostic_self_test')
    assert response.id == SimulatorConfig().serial_number == '3095'
    assert response.passed == b'\x01'
    names = [s.name for s in response.status]
    assert names == [
        'i3dmgx2_driver: accel & angular rate respond (0xC2)',
        'i3dmgx2_driver: magnetometer responds (0xC7)',
        'i3dmgx2_driver: temperatures respond (0xD1)', 'i3dmgx2_driver: gravity at rest',
        'i3dmgx2_driver: magnetometer BIT (0xFB config 0x04)',
        'i3dmgx2_driver: reverse magnetometer BIT (0xFB config 0x08)',
        'i3dmgx2_driver: +accel & rate BIT (0xFB config 0x10)',
        'i3dmgx2_driver: -rate BIT (0xFB config 0x20)',
        'i3dmgx2_driver: built-in test off (0xFB config 0x00)', 'i3dmgx2_driver: data rate']
    for status in response.status:
        assert status.level == DiagnosticStatus.OK, (status.name, status.message)
        assert status.hardware_id == '3095' and status.message
    # The Trigger form stays, from the same steps.
    trigger = call(listener, Trigger, 'self_test')
    assert trigger.success and trigger.message.endswith('10/10 steps passed')


def test_is_calibrated_stays_true_through_a_power_cycle_the_bias_written_back(rig):
    # After the capture above the driver keeps its bias: the power cycle loses it from the
    # sensor's RAM, and the stall's recovery writes it back before the stream restarts.
    sim, listener, node, latched = rig
    assert latched.wait(2)[-1] is True
    with sim.lock:
        captured = sim.sensor.biases.gyro
    sim.power_cycle(off_seconds=0.5, timer_start=0)
    assert node.wait_for_output('timer restarted', timeout=20), node.output()
    listener.clear()
    assert len(listener.wait_for('imu/raw_data', 20, timeout=20)) >= 20, node.output()
    assert latched.wait(3)[-1] is True
    with sim.lock:
        assert sim.sensor.biases.gyro == captured


def test_deprecated_qos_names_still_work_and_name_the_standard_parameter():
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=72)) as sim:
        listener = Listener({'imu/raw_data': Imu}, reliable=False)
        # A name of its own: the graph may still list the last test's node.
        node = NodeProcess({'port': sim.port, 'address': 95,
                            'qos_reliability': 'best_effort', 'qos_depth': 5},
                           extra_args=['-r', '__node:=deprecated_gx2'])
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', 10, timeout=30)) >= 10, node.output()
            assert publisher_qos(listener, '/imu/raw_data', '/deprecated_gx2').reliability == \
                ReliabilityPolicy.BEST_EFFORT
            assert publisher_qos(listener, '/imu/mag', '/deprecated_gx2').reliability == \
                ReliabilityPolicy.BEST_EFFORT
            # The data topics only, as the warning says: /diagnostics keeps its own QoS.
            assert publisher_qos(listener, '/diagnostics', '/deprecated_gx2').reliability == \
                ReliabilityPolicy.RELIABLE
            output = node.output()
            for old, new in (('qos_reliability', 'reliability'), ('qos_depth', 'depth')):
                assert (f"parameter '{old}' is deprecated and will be removed in the next "
                        f"release: use 'qos_overrides./imu/raw_data.publisher.{new}' "
                        f'instead') in output, output
            assert ('Until then it still sets the data topics (imu/raw_data, imu/mag, '
                    'imu/temperature).') in output, output
            assert 'unknown parameter' not in output
            assert node.stop()[0] == 0


def test_managed_node_takes_the_same_qos_parameters_and_latches_is_calibrated():
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=73)) as sim:
        listener = Listener({'imu/raw_data': Imu}, reliable=False)
        node = NodeProcess(
            {'port': sim.port, 'address': 95,
             'qos_overrides./imu/raw_data.publisher.reliability': 'best_effort'},
            # A name of its own: the graph may still list the last test's node.
            extra_args=['-r', '__node:=managed_gx2'], command=LIFECYCLE_COMMAND)
        with listener, node:
            client = LifecycleClient(listener, '/managed_gx2')
            assert client.wait_ready(), node.output()
            assert client.change('configure'), node.output()
            assert publisher_qos(listener, '/imu/raw_data', '/managed_gx2').reliability == \
                ReliabilityPolicy.BEST_EFFORT
            latched = Latched(listener, '/managed_gx2')
            try:
                assert latched.wait(1) == [False]
            finally:
                latched.close()
            assert client.change('activate'), node.output()
            assert len(listener.wait_for('imu/raw_data', 10, timeout=30)) >= 10, node.output()
            assert 'unknown parameter' not in node.output()
            assert node.stop()[0] == 0
