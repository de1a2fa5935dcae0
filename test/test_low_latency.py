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
Issue #6, low latency: the port's low-latency mode, and reads that return at once.

The serial class is faked (``SerialPort(serial_factory=...)``) to see what
is asked of pyserial: low-latency mode is requested when ``low_latency`` is
on, not otherwise, and a port that refuses it (as a pseudo-terminal does)
leaves a state string, not an error. Then the real thing: a pty opens fine
with ``low_latency=True`` and says it was refused; ``read_some`` hands over
the end of a packet as soon as it is written, not when a read size is full;
and the node process logs the low-latency state once, however often it
connects.
"""

import os
import threading
import time
import tty
from typing import ClassVar

from i3dmgx2_driver.codec.framing import encode_data_packet
from i3dmgx2_driver.codec.parser import SensorStreamParser
from i3dmgx2_driver.device import port as port_module
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.simulator import PtySimulator
import pytest
import serial


class FakeSerial:
    """Stands in for serial.Serial: notes every low-latency request."""

    instances: ClassVar[list['FakeSerial']] = []
    #: What set_low_latency_mode does: None accepts, an exception instance is raised.
    refusal: ClassVar[Exception | None] = None

    def __init__(self, **kwargs) -> None:
        self.kwargs = kwargs
        self.low_latency_calls: list[bool] = []
        self.closed = False
        FakeSerial.instances.append(self)

    def set_low_latency_mode(self, low_latency_settings: bool) -> None:
        self.low_latency_calls.append(low_latency_settings)
        if self.refusal is not None:
            raise self.refusal

    def fileno(self) -> int:
        raise OSError('no descriptor: a fake')

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def fake_serial():
    FakeSerial.instances = []
    FakeSerial.refusal = None
    yield FakeSerial
    FakeSerial.refusal = None


def test_low_latency_is_requested_and_on_when_the_port_accepts(fake_serial):
    port = SerialPort('/dev/ttyFAKE0', low_latency=True, serial_factory=fake_serial)
    (serial_object,) = fake_serial.instances
    assert serial_object.low_latency_calls == [True]
    assert port.low_latency_state == 'on'
    assert serial_object.kwargs['port'] == '/dev/ttyFAKE0'
    assert serial_object.kwargs['exclusive'] is True


def test_low_latency_is_not_requested_when_off(fake_serial):
    port = SerialPort('/dev/ttyFAKE0', low_latency=False, serial_factory=fake_serial)
    (serial_object,) = fake_serial.instances
    assert serial_object.low_latency_calls == []
    assert port.low_latency_state == 'off'


@pytest.mark.parametrize('refusal', [
    ValueError('Failed to update ASYNC_LOW_LATENCY flag to low_latency_settings: '
               'Inappropriate ioctl for device'),
    OSError(25, 'Inappropriate ioctl for device'),
    serial.SerialException('cannot'),
])
def test_a_port_that_refuses_gives_a_state_not_an_error(fake_serial, refusal):
    fake_serial.refusal = refusal
    port = SerialPort('/dev/ttyFAKE0', low_latency=True, serial_factory=fake_serial)
    assert fake_serial.instances[0].low_latency_calls == [True]
    assert port.low_latency_state != 'on'
    assert 'refused' in port.low_latency_state
    assert type(refusal).__name__ in port.low_latency_state


@pytest.mark.parametrize('refusal', [NotImplementedError(), AttributeError()])
def test_a_platform_without_it_says_so(fake_serial, refusal):
    fake_serial.refusal = refusal
    port = SerialPort('/dev/ttyFAKE0', low_latency=True, serial_factory=fake_serial)
    assert port.low_latency_state == 'not supported on this platform'


@pytest.mark.slow
def test_a_pseudo_terminal_opens_with_low_latency_asked_and_says_it_was_refused():
    with PtySimulator(seed=1) as sim:
        port = SerialPort(sim.port, low_latency=True)
        try:
            assert port.low_latency_state != 'on'
            assert port.low_latency_state.startswith(('refused', 'not supported'))
            # Still a working port: the simulator hears what is written.
            before = sim.stats.bytes_read
            port.write(b'\x02\x00\x5f')  # a wireless ping for node 95
            assert sim.wait_until(lambda: sim.stats.bytes_read > before, timeout=5.0)
        finally:
            port.close()


@pytest.fixture
def pty_pair():
    master, slave = os.openpty()
    tty.setraw(slave)
    yield master, os.ttyname(slave)
    for fd in (master, slave):
        try:
            os.close(fd)
        except OSError:
            pass


def _packet() -> bytes:
    record = bytes([0xCC]) + bytes(range(1, 77))  # echo byte and 76 data bytes
    return encode_data_packet(95, record, 200, 100)


@pytest.mark.slow
def test_read_some_returns_the_end_of_a_packet_as_soon_as_it_is_written(pty_pair):
    master, path = pty_pair
    packet = _packet()
    first, second = packet[:50], packet[50:]
    port = SerialPort(path, low_latency=True)
    try:
        os.write(master, first)
        got = b''
        while len(got) < len(first):
            got += port.read_some(timeout=5.0)
        assert got == first
        assert len(packet) < port_module.READ_SIZE  # a read does not wait to fill its size

        writer = threading.Timer(0.3, os.write, args=(master, second))
        writer.start()
        try:
            # Blocks until the second chunk arrives, then returns it whole: nothing
            # waits for more bytes, a read size or the timeout.
            rest = port.read_some(timeout=30.0)
        finally:
            writer.join()
        assert rest == second
        events = SensorStreamParser(address=95).feed(got + rest)
        assert len(events) == 1
        assert events[0].record.timer is not None
    finally:
        port.close()


@pytest.mark.slow
def test_read_some_times_out_with_nothing(pty_pair):
    _, path = pty_pair
    port = SerialPort(path, low_latency=False)
    try:
        assert port.read_some(timeout=0.05) == b''
    finally:
        port.close()


@pytest.mark.slow
def test_the_node_logs_the_low_latency_state_once():
    from harness.processes import isolate_ros_domain, NodeProcess

    isolate_ros_domain()
    with PtySimulator(seed=2) as sim:
        node = NodeProcess({'port': sim.port, 'address': 95, 'reconnect_interval': 0.2,
                            'read_timeout': 0.5})
        with node:
            assert node.wait_for_output('streaming 0xCC', timeout=30.0), node.output()
            connections = sim.stats.port_opens
            sim.unplug(seconds=0.5)
            assert sim.wait_until(lambda: sim.stats.port_opens > connections, timeout=20.0)
            deadline = time.monotonic() + 20.0
            while node.output().count('streaming 0xCC') < 2 and time.monotonic() < deadline:
                time.sleep(0.05)
            output = node.output()
            assert output.count('streaming 0xCC') >= 2, output
            lines = [line for line in output.splitlines() if 'low-latency mode' in line]
            assert len(lines) == 1, output
            assert f'{sim.port}: low-latency mode refused by the port' in lines[0] \
                or 'not supported' in lines[0], lines[0]
            code, _ = node.stop()
            assert code == 0
