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
The node's services, called through rclpy from this process, against the simulator.

One simulated sensor at rest and one node serve the module (the node is
started with ``capture_gyro_bias_on_start`` so that path is covered too).
The simulator's true gyro bias is known, so the captured one can be checked
against it; ``set_moving`` shakes the sensor to see a capture refused. A
store (``~/store_gyro_bias``, 0xD0) follows only an accepted capture, survives
the simulator's power cycle, and a memory that refuses it is reported.
"""

import re
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.motion import MotionConfig
import pytest
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

TRUE_BIAS = MotionConfig().gyro_bias
SAMPLING_MS = 400
SERVICE = '/i3dmgx2_driver/'

pytestmark = pytest.mark.slow
VECTOR = re.compile(r'\((-?\d+\.\d+), (-?\d+\.\d+), (-?\d+\.\d+)\) rad/s')


@pytest.fixture(scope='module')
def rig():
    isolate_ros_domain()
    config = SimulatorConfig(seed=51, motion=MotionConfig(static=True))
    with PtySimulator(config) as sim:
        listener = Listener({'imu/raw_data': Imu, '/diagnostics': DiagnosticArray})
        node = NodeProcess({'port': sim.port, 'address': 95,
                            'gyro_bias_sampling_ms': SAMPLING_MS,
                            'capture_gyro_bias_on_start': True})
        with listener, node:
            assert node.wait_for_output('gyro bias captured over', timeout=30), node.output()
            yield sim, listener, node
            assert node.stop()[0] == 0, node.output()


def call(listener, name, timeout=30.0):
    """Call a Trigger service of the node; return the response."""
    return listener.call(Trigger, SERVICE + name, timeout)


def bias_in(message):
    match = VECTOR.search(message)
    assert match, message
    return tuple(float(x) for x in match.groups())


def assert_streaming(listener, count=50, timeout=15.0):
    """Check that the IMU stream runs: ``count`` new messages arrive."""
    before = len(listener.received('imu/raw_data'))
    got = listener.wait_for('imu/raw_data', before + count, timeout=timeout)
    assert len(got) >= before + count, 'the stream did not resume'


def test_capture_on_start_happened(rig):
    sim, listener, node = rig
    assert 'capturing the gyro bias over 400 ms' in node.output()
    sent = [c for _, c in sim.commands if c.code == layouts.CAPTURE_GYRO_BIAS]
    assert sent and sent[0].args == (SAMPLING_MS,)
    assert_streaming(listener)


def test_capture_returns_the_true_bias_and_streaming_resumes(rig):
    sim, listener, _ = rig
    captures = len([c for _, c in sim.commands if c.code == layouts.CAPTURE_GYRO_BIAS])
    response = call(listener, 'capture_gyro_bias')
    assert response.success, response.message
    assert f'over {SAMPLING_MS} ms' in response.message
    assert bias_in(response.message) == pytest.approx(TRUE_BIAS, abs=0.002)
    assert len([c for _, c in sim.commands if c.code == layouts.CAPTURE_GYRO_BIAS]) == \
        captures + 1
    assert_streaming(listener)
    # Diagnostics report it, and the pause was not counted as lost records.
    listener.clear()
    arrays = listener.wait_for('/diagnostics', 2, timeout=10)
    status = {s.name: s for s in arrays[-1].status}
    calibration = {kv.key: kv.value for kv in status['i3dmgx2_driver: calibration'].values}
    assert calibration['gyro bias captured'] == 'yes'
    assert bias_in(calibration['gyro bias (rad/s)'] + ' rad/s') == \
        pytest.approx(TRUE_BIAS, abs=0.002)
    stream = {kv.key: kv.value for kv in status['i3dmgx2_driver: stream'].values}
    assert stream['lost (timer gaps)'] == '0'


def test_capture_refused_while_moving(rig):
    sim, listener, _ = rig
    sim.set_moving(True)
    try:
        response = call(listener, 'capture_gyro_bias')
    finally:
        sim.set_moving(False)
    assert not response.success, response.message
    assert 'refused: the sensor moved' in response.message
    assert 'capture again with the sensor still' in response.message
    assert_streaming(listener)


def stores(sim):
    return [c.args for _, c in sim.commands if c.code == layouts.TRANSFER_TO_NON_VOLATILE]


def test_a_moved_capture_is_never_stored(rig):
    # After test_capture_refused_while_moving: the device holds the moved bias.
    sim, listener, _ = rig
    before = stores(sim)
    response = call(listener, 'store_gyro_bias')
    assert not response.success
    assert response.message.startswith('refused: the last capture was not accepted')
    assert stores(sim) == before


def test_a_stored_capture_survives_a_power_cycle_and_counts_as_an_eeprom_write(rig):
    sim, listener, node = rig
    captured = call(listener, 'capture_gyro_bias')
    assert captured.success, captured.message
    response = call(listener, 'store_gyro_bias')
    assert response.success, response.message
    assert "stored in the sensor's non-volatile memory" in response.message
    assert stores(sim)[-1] == (2,)
    assert node.wait_for_output('one EEPROM write', timeout=5), node.output()
    with sim.lock:
        in_use = sim.sensor.biases.gyro
    assert in_use == pytest.approx(bias_in(captured.message), abs=1e-5)
    listener.clear()
    arrays = listener.wait_for('/diagnostics', 2, timeout=10)
    device = {s.name: s for s in arrays[-1].status}['i3dmgx2_driver: device']
    assert {kv.key: kv.value for kv in device.values}['EEPROM writes'] == '1'
    sim.power_cycle(0.2)
    time.sleep(0.5)
    with sim.lock:
        assert sim.sensor.biases.gyro == in_use  # loaded from non-volatile memory
    assert_streaming(listener, timeout=30.0)


def test_a_refused_store_is_reported(rig):
    sim, listener, _ = rig
    captured = call(listener, 'capture_gyro_bias')
    assert captured.success, captured.message
    sim.sensor.settings.refuse_bias_store = True
    try:
        response = call(listener, 'store_gyro_bias')
    finally:
        sim.sensor.settings.refuse_bias_store = False
    assert not response.success
    assert 'gyro bias store refused (0xFFFF)' in response.message
    assert_streaming(listener)


def test_self_test_passes_and_reports_each_step(rig):
    sim, listener, _ = rig
    response = call(listener, 'self_test')
    assert response.success, response.message
    lines = response.message.splitlines()
    for step in ('accel & angular rate respond (0xC2)', 'magnetometer responds (0xC7)',
                 'temperatures respond (0xD1)', 'gravity at rest',
                 'magnetometer BIT (0xFB config 0x04)',
                 'reverse magnetometer BIT (0xFB config 0x08)',
                 '+accel & rate BIT (0xFB config 0x10)', '-rate BIT (0xFB config 0x20)',
                 'built-in test off (0xFB config 0x00)', 'data rate'):
        assert any(line.startswith(f'PASS {step}:') for line in lines), (step, lines)
    assert lines[-1] == 'self test passed: 10/10 steps passed'
    bits = [c.args[0] for _, c in sim.commands if c.code == layouts.BUILT_IN_TEST]
    assert bits[-5:] == [0x04, 0x08, 0x10, 0x20, 0x00]
    assert_streaming(listener)


def set_parameter(listener, name, value, timeout=10.0):
    """Set an integer parameter of the node through its parameter service."""
    client = listener.node.create_client(SetParameters, SERVICE + 'set_parameters')
    try:
        assert client.wait_for_service(timeout_sec=timeout)
        request = SetParameters.Request(
            parameters=[Parameter(name, value=value).to_parameter_msg()])
        future = client.call_async(request)
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.02)
        return future.result().results[0]
    finally:
        listener.node.destroy_client(client)


def test_sampling_time_is_checked_at_run_time(rig):
    listener = rig[1]
    assert not set_parameter(listener, 'gyro_bias_sampling_ms', 50).successful
    assert not set_parameter(listener, 'gyro_bias_sampling_ms', 40000).successful
    assert set_parameter(listener, 'gyro_bias_sampling_ms', SAMPLING_MS).successful


def test_long_capture_keeps_diagnostics_alive_and_a_signal_stops_it(rig):
    # Last in the module: it stops the node.
    _, listener, node = rig
    assert set_parameter(listener, 'gyro_bias_sampling_ms', 20000).successful
    client = listener.node.create_client(Trigger, SERVICE + 'capture_gyro_bias')
    assert client.wait_for_service(timeout_sec=10)
    future = client.call_async(Trigger.Request())
    listener.clear()
    deadline = time.monotonic() + 15
    paused = None
    while paused is None and time.monotonic() < deadline:
        for array in listener.received('/diagnostics'):
            stream = {s.name: s for s in array.status}['i3dmgx2_driver: stream']
            if 'paused for gyro bias capture' in stream.message:
                paused = stream
        time.sleep(0.05)
    assert paused is not None, 'no diagnostics during the capture'
    assert paused.level == DiagnosticStatus.WARN
    assert not future.done()
    code, took = node.stop()
    assert code == 0, node.output()
    assert took < 5.0, f'a signal during a capture took {took:.1f} s'
