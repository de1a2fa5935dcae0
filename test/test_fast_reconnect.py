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
Reconnecting to a sensor the driver knows: one serial-number read, then data.

The supervisor runs against the simulated base station and sensor, and the
simulator's host command log shows what the driver asked after the port
came back: the same sensor is asked its serial number and nothing else (and
to stream, when it was power-cycled meanwhile); another sensor on the port
gets the full dialogue and its identity is logged. Then the node, as a
process, says so in its log.
"""

import os
import threading
import time

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.device.status import State
from i3dmgx2_driver.device.supervisor import DeviceSupervisor
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.slow

#: What the full start-up dialogue asks, in order (after the three 0xFA).
FULL_DIALOGUE = [(0x02, 95), (0xC2, None), (0xC2, None), (0xEA, 0), (0xEA, 1), (0xEA, 2),
                 (0xEA, 3), (0xE9, None), (0xE5, 0xFCA2), (0xC4, 0xCC)]


class Recorder:
    """The supervisor's consumer and logger: records' read times and log lines."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.read_times: list[float] = []
        self.lines: list[tuple[str, str]] = []

    def on_record(self, packet, read_time: float, read_mono: float) -> None:
        with self.lock:
            self.read_times.append(read_time)

    def records_since(self, t: float) -> int:
        with self.lock:
            return sum(1 for r in self.read_times if r >= t)

    def _log(self, level: str, message: str) -> None:
        with self.lock:
            self.lines.append((level, message))

    def debug(self, message: str) -> None:
        self._log('debug', message)

    def info(self, message: str) -> None:
        self._log('info', message)

    def warning(self, message: str) -> None:
        self._log('warning', message)

    def error(self, message: str) -> None:
        self._log('error', message)

    def logged(self, text: str) -> list[tuple[str, str]]:
        with self.lock:
            return [line for line in self.lines if text in line[1]]


def wait_until(condition, timeout: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return condition()


def asked(sim: PtySimulator, since: float) -> list[tuple[int, int | None]]:
    """(command code, first argument) of every command the driver sent since ``since``."""
    out = []
    for entry in sim.host_log:
        if entry.time >= since and entry.command is not None:
            args = entry.command.args
            out.append((entry.command.code, args[0] if args else None))
    return out


def streaming_supervisor(port: str, recorder: Recorder, **config) -> DeviceSupervisor:
    config = {'port': port, 'address': 95, 'reconnect_interval': 0.3, **config}
    supervisor = DeviceSupervisor(DeviceConfig(**config), on_record=recorder.on_record,
                                  log=recorder)
    supervisor.start()
    assert wait_until(lambda: supervisor.status().state == State.STREAMING
                      and recorder.records_since(0.0) >= 20), recorder.lines
    assert supervisor.status().last_start == 'full'
    return supervisor


def test_the_same_sensor_is_asked_its_serial_number_and_nothing_else():
    recorder = Recorder()
    with PtySimulator(SimulatorConfig(seed=51)) as sim:
        supervisor = streaming_supervisor(sim.port, recorder)
        try:
            sim.unplug()  # the wireless sensor streams on meanwhile
            time.sleep(0.5)
            back = time.time()
            assert sim.replug()
            assert wait_until(lambda: supervisor.status().resumes == 1 and
                              recorder.records_since(back) >= 50), recorder.lines
            assert supervisor.status().last_start == 'resumed'
            assert asked(sim, back) == [(layouts.DEVICE_IDENTIFIER, 1)]
            assert supervisor.status().info.serial_number == '3095'
            assert len(recorder.logged('same sensor (serial 3095)')) == 1
            assert len(recorder.logged('device: model')) == 1  # identity logged once only
        finally:
            supervisor.stop()


def test_a_power_cycled_sensor_is_asked_to_stream_again():
    recorder = Recorder()
    with PtySimulator(SimulatorConfig(seed=52)) as sim:
        supervisor = streaming_supervisor(sim.port, recorder)
        try:
            sim.unplug()
            sim.power_cycle()  # it comes back in polled mode
            time.sleep(0.5)
            back = time.time()
            assert sim.replug()
            assert wait_until(lambda: recorder.records_since(back) >= 50), recorder.lines
            assert asked(sim, back) == [(layouts.DEVICE_IDENTIFIER, 1),
                                        (layouts.SET_CONTINUOUS, 0xCC)]
            assert supervisor.status().resumes == 1
        finally:
            supervisor.stop()


@pytest.mark.parametrize('streaming', [False, True], ids=['polled', 'already-streaming'])
def test_another_sensor_on_the_port_gets_the_full_dialogue(tmp_path, streaming):
    port = os.path.join(tmp_path, 'ttyGX2')
    recorder = Recorder()
    first = PtySimulator(SimulatorConfig(seed=53, symlink=port))
    first.start()
    supervisor = None
    try:
        supervisor = streaming_supervisor(port, recorder)
        first.stop()  # unplugged; another base station and sensor, same address, appear
        with PtySimulator(SimulatorConfig(seed=54, symlink=port, serial_number='4711',
                                          streaming_at_start=streaming)) as second:
            assert wait_until(lambda: supervisor.status().info is not None
                              and supervisor.status().info.serial_number == '4711'
                              and supervisor.status().state == State.STREAMING), recorder.lines
            assert wait_until(lambda: len(second.truth) > 0 and recorder.records_since(
                second.truth[0].sample_time) >= 30)
            sent = asked(second, 0.0)
            assert sent[0] == (layouts.DEVICE_IDENTIFIER, 1)
            assert [c for c in sent[1:] if c[0] != layouts.STOP_CONTINUOUS] == FULL_DIALOGUE
            assert supervisor.status().last_start == 'full'
            assert supervisor.status().resumes == 0
            warning = recorder.logged('another sensor answers as node 95')
            assert warning == [('warning', 'another sensor answers as node 95: serial 4711, '
                                           'not 3095; identifying it in full')]
            identities = recorder.logged('device: model')
            assert len(identities) == 2 and 'serial 4711' in identities[1][1]
    finally:
        if supervisor is not None:
            supervisor.stop()
        first.stop()


def test_without_fast_reconnect_every_connection_gets_the_full_dialogue():
    recorder = Recorder()
    with PtySimulator(SimulatorConfig(seed=55)) as sim:
        supervisor = streaming_supervisor(sim.port, recorder, fast_reconnect=False)
        try:
            sim.unplug()
            time.sleep(0.5)
            back = time.time()
            assert sim.replug()
            assert wait_until(lambda: recorder.records_since(back) >= 50), recorder.lines
            sent = [c for c in asked(sim, back) if c[0] != layouts.STOP_CONTINUOUS]
            assert sent == FULL_DIALOGUE
            assert supervisor.status().resumes == 0
        finally:
            supervisor.stop()


def test_a_port_that_comes_back_is_reopened_before_the_reconnect_interval():
    recorder = Recorder()
    with PtySimulator(SimulatorConfig(seed=56)) as sim:
        # A long interval: a retry on the interval alone would not come within the test.
        supervisor = streaming_supervisor(sim.port, recorder, reconnect_interval=60.0)
        try:
            sim.unplug()
            assert wait_until(lambda: supervisor.status().state == State.DISCONNECTED)
            time.sleep(0.5)
            back = time.time()
            assert sim.replug()
            assert wait_until(lambda: recorder.records_since(back) >= 20,
                              timeout=30.0), recorder.lines
            assert supervisor.status().reconnects == 1
        finally:
            supervisor.stop()


def test_the_node_resumes_a_known_sensor_and_logs_it():
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=57)) as sim:
        node = NodeProcess({'port': sim.port, 'address': 95, 'reconnect_interval': 0.3})
        with Listener({'imu/raw_data': Imu}) as listener, node:
            assert len(listener.wait_for('imu/raw_data', 30, timeout=30)) >= 30, node.output()
            sim.unplug()
            time.sleep(0.5)
            back = time.time()
            assert sim.replug()
            listener.clear()
            assert len(listener.wait_for('imu/raw_data', 50, timeout=30)) >= 50, node.output()
            assert asked(sim, back) == [(layouts.DEVICE_IDENTIFIER, 1)]
            output = node.output()
            assert output.count('same sensor (serial 3095), identity and data rate not '
                                'asked again') == 1, output
            assert output.count('device: model') == 1
            assert node.stop()[0] == 0
