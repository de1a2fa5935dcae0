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
A calibration that lasts, without a node: what is stored, what is written, what is refused.

The store (0xD0) of a capture, judged on a fake device: only the last
capture, only when accepted, a refusal (0xFFFF) said; the parameter file a
capture writes reads back as the same bias; the biases the dialogue writes at
start are checked against the sensor's echo, against the simulated sensor
itself and against one that echoes something else; the bias parameters are
refused unless they are three finite numbers.
"""

import threading
from typing import Any

from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.codec.commands import decode_command
from i3dmgx2_driver.codec.records import GyroBias, INVALID_QUANTITY
from i3dmgx2_driver.device.dialogue import float32_vector, SensorDialogue
from i3dmgx2_driver.device.gyro_bias import Calibration, GyroBiasCapture
from i3dmgx2_driver.device.link import DeviceTimeout, EchoMismatch
from i3dmgx2_driver.device.sensor_firmware import SensorFirmware
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.ros.calibration_file import calibration_yaml
from i3dmgx2_driver.ros.parameters import declare_parameters, driver_config, ParameterError
from i3dmgx2_driver.simulator import SimulatedSensor
import pytest
import rclpy
from rclpy.node import Node
import yaml

BIAS = (-0.0033, -0.0217, -0.0052)


class Log:
    """Keeps what is said, by severity."""

    def __init__(self) -> None:
        self.said: list[tuple[str, str]] = []

    def __getattr__(self, level: str) -> Any:
        return lambda message: self.said.append((level, message))


class FakeDialogue:
    """Answers 0xD0 with ``answer`` (or times out), counting the writes as the real one."""

    def __init__(self, answer: int | None, firmware: str = '') -> None:
        self.answer = answer
        self.eeprom_writes = 0
        self.asked: list[int] = []
        self.firmware = SensorFirmware()
        self.firmware.learn(firmware)

    def transfer_to_non_volatile(self, link: object, quantity: int) -> int:
        self.eeprom_writes += 1
        self.asked.append(quantity)
        if self.answer is None:
            raise DeviceTimeout('no reply to 0xD0')
        return quantity if self.answer == 0 else self.answer

    #: Nothing writes it back: no stream restarts here.
    gyro_bias: Any = None


class FakeDevice:
    """Runs an operation on no link; its EEPROM is the fake dialogue's."""

    def __init__(self, answer: int | None = 0, firmware: str = '') -> None:
        self.dialogue = FakeDialogue(answer, firmware)
        self.firmware = self.dialogue.firmware

    def run_paused(self, operation: Any) -> Any:
        return operation(None)


def capture(device: FakeDevice, *outcomes: bool) -> GyroBiasCapture:
    """Return a capture whose attempts came to ``outcomes`` (accepted or not), in order."""
    log = Log()
    made = GyroBiasCapture(device, lambda: None, lambda flag: None, log)
    for accepted in outcomes:
        made.last_capture = Calibration(0.0, accepted, BIAS, 400, 'bias' if accepted else
                                        'the sensor moved: gravity vector changed')
        if accepted:
            made.good_capture = made.last_capture
    return made


def test_an_accepted_capture_is_stored_once_and_said():
    device = FakeDevice()
    made = capture(device, True)
    ok, message = made.store()
    assert ok, message
    assert device.dialogue.asked == [2] and device.dialogue.eeprom_writes == 1
    assert "stored in the sensor's non-volatile memory" in message
    assert '(-0.00330, -0.02170, -0.00520)' in message
    assert made._log.said[-1][1] == message


@pytest.mark.parametrize('firmware, stored', [('2.1.11', False), ('2.1.12', True), ('', True)])
def test_the_store_needs_firmware_2_1_12_and_is_refused_before_it_at_once(firmware, stored):
    device = FakeDevice(firmware=firmware)
    made = capture(device, True)
    ok, message = made.store()
    assert ok is stored, message
    if stored:  # '': the firmware was not read, so the store is asked as before
        assert device.dialogue.asked == [2]
        return
    assert message.startswith('refused: the gyro bias store (0xD0) needs firmware 2.1.12; '
                              'this sensor has 2.1.11. Nothing sent'), message
    assert device.dialogue.asked == [] and device.dialogue.eeprom_writes == 0


def test_nothing_is_stored_without_a_capture_or_after_a_refused_one():
    for outcomes in ((), (False,), (True, False)):
        device = FakeDevice()
        ok, message = capture(device, *outcomes).store()
        assert not ok and message.startswith('refused: '), message
        assert 'Nothing stored' in message
        assert device.dialogue.asked == [], outcomes  # 0xD0 never sent
    # A refused capture after a good one: the device uses the moved bias.
    _, message = capture(FakeDevice(), True, False).store()
    assert 'the last capture was not accepted (the sensor moved' in message


def test_a_refused_store_is_reported_and_a_lost_reply_is_not_taken_for_success():
    device = FakeDevice(INVALID_QUANTITY)
    made = capture(device, True)
    ok, message = made.store()
    assert not ok and 'refused (0xFFFF)' in message and 'did not store' in message
    assert made._log.said[-1][0] == 'error'
    assert device.dialogue.eeprom_writes == 1  # the attempt counts all the same
    device = FakeDevice(None)
    ok, message = capture(device, True).store()
    assert not ok and 'not confirmed' in message and 'may or may not' in message
    assert device.dialogue.asked == [2]  # asked once, never resent blindly


def test_the_calibration_file_reads_back_as_the_same_bias():
    bias = (-0.003300000052154064, 0.1 + 0.2, 1e-9)
    loaded = yaml.safe_load(calibration_yaml('/robot/imu', bias))
    assert loaded == {'/robot/imu': {'ros__parameters': {'gyro_bias': list(bias)}}}


class Link:
    """Answers the bias writes as ``sensor`` does, or echoes ``wrong`` instead."""

    wireless = False

    def __init__(self, sensor: SimulatedSensor, wrong: tuple | None = None,
                 silent: bool = False) -> None:
        self.sensor, self.wrong, self.silent = sensor, wrong, silent
        self.sent: list[Any] = []

    def request(self, data: bytes, code: int, timeout: float, retries: int) -> Any:
        self.sent.append(decode_command(data))
        if self.silent:
            raise DeviceTimeout(f'no reply to 0x{code:02X}')
        [reply] = self.sensor.handle(data, 1.0)
        if self.wrong is not None:
            return GyroBias(self.wrong, reply.record.timer)
        return reply.record


def dialogue(**biases: Any) -> tuple[SensorDialogue, Log]:
    log = Log()
    config = DeviceConfig(port='/dev/null', address=95, **biases)
    return SensorDialogue(config, log, lambda *args: None, threading.Event()), log


def test_the_biases_are_written_to_ram_and_checked_against_the_echo():
    sensor = SimulatedSensor(seed=1)
    talk, log = dialogue(gyro_bias=BIAS, accel_bias=(0.001, 0.0, -0.002))
    link = Link(sensor)
    eeprom = dict(sensor.eeprom)
    talk.write_biases(link)
    assert [c.code for c in link.sent] == [layouts.WRITE_GYRO_BIAS, layouts.WRITE_ACCEL_BIAS]
    assert sensor.biases.gyro == float32_vector(BIAS)
    assert sensor.biases.accel == float32_vector((0.001, 0.0, -0.002))
    # RAM: no EEPROM worn, by the dialogue's count and in the sensor.
    assert talk.eeprom_writes == 0 and sensor.eeprom == eeprom
    assert any('gyro_bias (-0.0033, -0.0217, -0.0052) rad/s written' in m for _, m in log.said)
    # None configured: nothing said to the sensor.
    talk, _ = dialogue()
    link = Link(sensor)
    talk.write_biases(link)
    assert link.sent == [] and sensor.biases.gyro == float32_vector(BIAS)


def test_an_accepted_capture_is_the_bias_written_back_and_said_each_time():
    sensor = SimulatedSensor(seed=1)
    told: list[bool] = []
    config = DeviceConfig(port='/dev/null', address=95, gyro_bias=BIAS)
    talk = SensorDialogue(config, Log(), lambda *args: None, threading.Event(),
                          on_gyro_bias=lambda: told.append(True))
    talk.write_biases(Link(sensor))
    captured = (0.001, -0.002, 0.003)
    talk.gyro_bias = captured
    link = Link(sensor)
    talk.write_biases(link)  # what a stall recovery after a power cycle does
    assert [c.args[0] for c in link.sent] == [pytest.approx(captured, abs=1e-7)]
    assert sensor.biases.gyro == float32_vector(captured)
    assert told == [True, True]
    assert config.gyro_bias == BIAS  # the parameter is not rewritten


def test_an_echo_that_differs_or_none_is_a_clear_error():
    told: list[bool] = []
    talk = SensorDialogue(DeviceConfig(port='/dev/null', address=95, gyro_bias=BIAS), Log(),
                          lambda *args: None, threading.Event(),
                          on_gyro_bias=lambda: told.append(True))
    with pytest.raises(EchoMismatch, match=r'gyro_bias: wrote \(-0.0033, -0.0217, -0.0052\) '
                                           r'rad/s, the sensor echoed \(0, 0, 0\) rad/s'):
        talk.write_biases(Link(SimulatedSensor(seed=1), wrong=(0.0, 0.0, 0.0)))
    assert told == [], 'a bias the sensor does not echo is not said to be in use'
    with pytest.raises(DeviceTimeout, match='gyro_bias: the sensor did not echo'):
        talk.write_biases(Link(SimulatedSensor(seed=1), silent=True))


def test_a_bias_parameter_is_three_finite_numbers_or_nothing():
    for bad in ('[0.1, 0.2]', '[0.1, 0.2, 0.3, 0.4]', '[0.1, .nan, 0.0]'):
        with pytest.raises(ParameterError, match=r"'gyro_bias' must be .* in rad/s"):
            parameters('-p', 'address:=95', '-p', f'gyro_bias:={bad}')


def parameters(*arguments: str) -> dict:
    """Declare the driver's parameters on a node with ``arguments``; return the values."""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node('i3dmgx2_driver', context=context, cli_args=['--ros-args', *arguments])
    try:
        return declare_parameters(node)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_the_bias_parameters_reach_the_dialogue_and_are_one_sensors():
    config = driver_config(parameters('-p', 'address:=95', '-p', 'gyro_bias:=[0.01, 0.0, -0.02]',
                                      '-p', 'accel_bias:=[0, 0, 1]'))
    assert config.device.gyro_bias == (0.01, 0.0, -0.02)
    assert config.device.accel_bias == (0.0, 0.0, 1.0)  # integers stand for doubles
    assert driver_config(parameters('-p', 'address:=95')).device.gyro_bias is None
    with pytest.raises(ParameterError, match=r"'gyro_bias' is one sensor's bias"):
        driver_config(parameters('-p', 'addresses:=[17, 95]', '-p', 'gyro_bias:=[0.01, 0.0, 0.0]'))
    with pytest.raises(ParameterError, match=r"'accel_bias' must be .* in g, got \[0.1\]"):
        driver_config(parameters('-p', 'address:=95', '-p', 'accel_bias:=[0.1]'))
