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
Known biases from parameters, against the simulator: written at start, echoed, kept.

A node started with ``gyro_bias`` and ``accel_bias`` writes them to the
sensor's RAM (0xCA, 0xC9) before streaming and says it is calibrated from
the start; a capture writes its bias to ``calibration_file``; a second node
started with that file as a parameter file writes the captured bias, to the
bit. A sensor power-cycled while the node runs gets the kept bias back (the
parameter's, then an accepted capture's) without a restart. A bias parameter
that is not three numbers stops the node, named.
"""

import os
import time

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.device.dialogue import float32_vector
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.motion import MotionConfig
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from std_msgs.msg import Bool
from std_srvs.srv import Trigger
import yaml

GYRO = (0.0125, -0.0031, 0.0007)
ACCEL = (0.002, -0.001, 0.0005)
pytestmark = pytest.mark.slow
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def latest_calibrated(listener: Listener, timeout: float = 10.0) -> bool | None:
    """Return the value ``~/is_calibrated`` holds now (transient local: the last one)."""
    values: list[bool] = []
    subscription = listener.node.create_subscription(
        Bool, '/i3dmgx2_driver/is_calibrated', lambda msg: values.append(msg.data), LATCHED)
    try:
        deadline = time.monotonic() + timeout
        while not values and time.monotonic() < deadline:
            time.sleep(0.02)
        return values[-1] if values else None
    finally:
        listener.node.destroy_subscription(subscription)


def written(sim: PtySimulator, code: int) -> list[tuple]:
    return [c.args[0] for _, c in sim.commands if c.code == code]


def test_known_biases_are_written_at_start_and_a_capture_is_kept_for_the_next(tmp_path):
    isolate_ros_domain()
    path = os.path.join(tmp_path, 'calibration.yaml')
    config = SimulatorConfig(seed=52, motion=MotionConfig(static=True))
    with PtySimulator(config) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95, 'gyro_bias_sampling_ms': 400,
                            'gyro_bias': list(GYRO), 'accel_bias': list(ACCEL),
                            'calibration_file': path})
        with listener, node:
            assert listener.wait_for('imu/raw_data', 20, timeout=30), node.output()
            # Written before the stream started, and echoed as written.
            assert written(sim, layouts.WRITE_GYRO_BIAS) == [pytest.approx(GYRO, abs=1e-7)]
            assert written(sim, layouts.WRITE_ACCEL_BIAS) == [pytest.approx(ACCEL, abs=1e-7)]
            first_stream = min(t for t, c in sim.commands if c.code == layouts.SET_CONTINUOUS
                               and c.args[0])
            assert max(t for t, c in sim.commands if c.code in (
                layouts.WRITE_GYRO_BIAS, layouts.WRITE_ACCEL_BIAS)) < first_stream
            with sim.lock:
                assert sim.sensor.biases.gyro == float32_vector(GYRO)
                assert sim.sensor.biases.accel == float32_vector(ACCEL)
            assert 'gyro_bias (0.0125, -0.0031, 0.0007) rad/s written' in node.output()
            assert latest_calibrated(listener) is True
            # A capture writes its bias where the next start finds it.
            response = listener.call(Trigger, '/i3dmgx2_driver/capture_gyro_bias', 30)
            assert response.success, response.message
            assert f'written to {path} (gyro_bias)' in response.message
            with open(path) as handle:
                captured = yaml.safe_load(handle)['/i3dmgx2_driver']['ros__parameters']
            assert captured['gyro_bias'] == pytest.approx(MotionConfig().gyro_bias, abs=0.002)
            assert node.stop()[0] == 0, node.output()
        listener = Listener({'imu/raw_data': Imu})
        again = NodeProcess({'port': sim.port, 'address': 95}, ['--params-file', path])
        with listener, again:
            assert listener.wait_for('imu/raw_data', 20, timeout=30), again.output()
            assert written(sim, layouts.WRITE_GYRO_BIAS)[-1] == \
                float32_vector(captured['gyro_bias'])
            assert latest_calibrated(listener) is True
            assert again.stop()[0] == 0, again.output()


def wait_until(condition, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.02)
    return condition()


def test_a_power_cycle_while_running_gets_the_kept_bias_back_a_capture_included():
    """
    A sensor power-cycled with the port open stalls; the recovery writes the kept bias.

    The parameter's at first; after an accepted capture, the captured one
    (never the parameter's over it); ``~/is_calibrated`` stays true through both.
    """
    isolate_ros_domain()
    config = SimulatorConfig(seed=53, motion=MotionConfig(static=True))
    with PtySimulator(config) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95, 'gyro_bias_sampling_ms': 400,
                            'gyro_bias': list(GYRO), 'accel_bias': list(ACCEL)})
        with listener, node:
            assert listener.wait_for('imu/raw_data', 20, timeout=30), node.output()
            assert len(written(sim, layouts.WRITE_GYRO_BIAS)) == 1
            sim.power_cycle(0.5)  # its RAM loses the bias at power-up
            assert wait_until(lambda: len(written(sim, layouts.WRITE_GYRO_BIAS)) == 2, 20), \
                node.output()
            count = len(listener.received('imu/raw_data')) + 20
            assert len(listener.wait_for('imu/raw_data', count, timeout=20)) >= count, \
                node.output()
            with sim.lock:
                assert sim.sensor.biases.gyro == float32_vector(GYRO)
                assert sim.sensor.biases.accel == float32_vector(ACCEL)
            assert latest_calibrated(listener) is True
            # An accepted capture is the bias kept from now on.
            response = listener.call(Trigger, '/i3dmgx2_driver/capture_gyro_bias', 30)
            assert response.success, response.message
            with sim.lock:
                captured = sim.sensor.biases.gyro
            assert captured != float32_vector(GYRO)
            writes = len(written(sim, layouts.WRITE_GYRO_BIAS))
            sim.power_cycle(0.5)
            assert wait_until(
                lambda: len(written(sim, layouts.WRITE_GYRO_BIAS)) == writes + 1, 20), \
                node.output()
            count = len(listener.received('imu/raw_data')) + 20
            assert len(listener.wait_for('imu/raw_data', count, timeout=20)) >= count, \
                node.output()
            assert written(sim, layouts.WRITE_GYRO_BIAS)[-1] == pytest.approx(captured, abs=0)
            with sim.lock:
                assert sim.sensor.biases.gyro == captured
            assert latest_calibrated(listener) is True
            assert node.stop()[0] == 0, node.output()


def test_a_bias_that_is_not_three_numbers_stops_the_node():
    isolate_ros_domain()
    node = NodeProcess({'port': '/dev/null', 'address': 95, 'gyro_bias': '[0.1, 0.2]'})
    with node:
        assert node.wait_for_output("parameter 'gyro_bias' must be", timeout=20), \
            node.output()
        assert node.stop()[0] != 0
