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
The reader wakes once a packet while the stream flows, and for any byte while an answer is due.

A port hands a packet over in pieces (a USB adapter one transfer a
millisecond); ``SerialPort.wake_for`` makes a wait end only once a whole
packet is in, and the reader asks for it only while every link streams, the
parser is in step and no request waits (device/link.py). What must not
change: a request's answer, an ACK of one byte or a reply shorter than a
record, is read at once even while the stream is slow.
"""

import os
import threading
import time
import tty

from i3dmgx2_driver.codec import layouts, line_budget
from i3dmgx2_driver.device import timeouts
from i3dmgx2_driver.device.identity import read_firmware
from i3dmgx2_driver.device.link import DeviceLink, LinkOptions
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.device.sensor_steps import SensorSteps
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest

pytestmark = pytest.mark.slow

STREAM = layouts.ACCEL_ANG_RATE_MAG_ORIENTATION
#: The streamed packet, as the reader is told it (the codec's table).
PACKET = line_budget.packet_size(STREAM, wireless=True)
#: A USB adapter in low-latency mode at 115200 baud: about 11 bytes a millisecond.
USB_PIECES = {'chunks': (8, 8), 'chunk_gap_s': 0.001}


@pytest.fixture
def pty_port():
    master, slave = os.openpty()
    tty.setraw(slave)
    port = SerialPort(os.ttyname(slave), low_latency=False)
    yield master, port
    port.close()
    os.close(master)
    os.close(slave)


def _write_in_pieces(master: int, data: bytes, piece: int) -> threading.Thread:
    def write() -> None:
        for start in range(0, len(data), piece):
            os.write(master, data[start:start + piece])
            time.sleep(0.002)
    thread = threading.Thread(target=write)
    thread.start()
    return thread


def test_a_wait_for_a_packet_returns_it_whole_from_its_pieces(pty_port):
    master, port = pty_port
    packet = bytes(range(PACKET))
    port.wake_for(PACKET)
    writer = _write_in_pieces(master, packet, 11)
    data = port.read_some(2.0)
    writer.join()
    assert data == packet  # one read, though the port had it in eight pieces
    port.wake_for(1)
    writer = _write_in_pieces(master, packet, 44)
    first = port.read_some(2.0)
    writer.join()
    assert 0 < len(first) < PACKET  # any byte ends the wait again


def test_two_packets_queued_are_read_together(pty_port):
    # A read of a terminal gives 64 bytes at most while VMIN is above that: the rest is
    # read at once, not left for a wake that comes only with the next packet.
    master, port = pty_port
    port.wake_for(PACKET)
    os.write(master, bytes(2 * PACKET + 5))
    assert len(port.read_some(1.0)) == 2 * PACKET + 5


def test_a_byte_is_read_at_once_when_the_wait_is_lowered_meanwhile(pty_port):
    master, port = pty_port
    port.wake_for(PACKET)
    os.write(master, b'\xaa')  # an ACK, alone
    assert port.read_some(0.1) == b''  # a packet's wait does not end for one byte
    lowered = threading.Timer(0.05, port.wake_for, (1,))
    lowered.start()
    assert port.read_some(5.0) == b'\xaa'  # another thread's lowering ends it
    lowered.join()


class _Counted:
    """The reads of a link's port that returned bytes, and its records."""

    def __init__(self, sim: PtySimulator, read_timeout: float = 0.05) -> None:
        self.reads = self.records = 0
        port = SerialPort(sim.port, low_latency=False)
        read = port.read_some

        def counted(timeout: float) -> bytes:
            data = read(timeout)
            self.reads += bool(data)
            return data

        port.read_some = counted  # type: ignore[method-assign]  # bound when the reader starts
        self.link = DeviceLink(port, 95, self._on_record, LinkOptions(select_timeout=read_timeout))
        self.steps = SensorSteps()
        self.steps.quiet(self.link)
        self.link.start()

    def _on_record(self, packet, read_time, read_mono) -> None:
        self.records += 1

    def next_record(self, timeout: float) -> None:
        """Return once a record more has arrived."""
        records, deadline = self.records, time.monotonic() + timeout
        while self.records == records and time.monotonic() < deadline:
            time.sleep(0.001)
        assert self.records > records

    def stream_for(self, seconds: float) -> tuple[int, int]:
        """Return the reads with bytes and the records over ``seconds`` of streaming."""
        reads, records = self.reads, self.records
        time.sleep(seconds)
        return self.reads - reads, self.records - records

    def close(self) -> None:
        self.link.stop()
        self.link.port.close()


def test_the_reader_wakes_once_a_record_however_the_port_cuts_it():
    with PtySimulator(SimulatorConfig(seed=7, **USB_PIECES)) as sim:
        counted = _Counted(sim)
        try:
            assert counted.steps.start_stream(counted.link, STREAM, 0.01)
            reads, records = counted.stream_for(1.0)
            assert records >= 50
            # Eight pieces a packet: woken for each, the reader would read eight times.
            assert reads <= 1.2 * records, (reads, records)
            counted.steps.stop_until_quiet(counted.link, 0.01)
            reads, records = counted.stream_for(0.2)
            assert records == 0
        finally:
            counted.close()


def test_an_answer_shorter_than_a_record_is_read_at_once_while_the_stream_is_slow():
    # At 1 Hz, with reads that wait longer than that, a reply left waiting for a whole
    # packet would come with the next record, up to a second later: after the request's
    # timeout. Each request is sent just after a record, when the wait is for a packet.
    with PtySimulator(SimulatorConfig(seed=8, rate_hz=1.0, **USB_PIECES)) as sim:
        counted = _Counted(sim, read_timeout=2.0)
        try:
            assert counted.steps.start_stream(counted.link, STREAM, 1.0)
            for _ in range(2):
                counted.next_record(3.0)
                asked = time.monotonic()
                assert read_firmware(counted.link, timeouts.REQUEST_TIMEOUT, 1)
                assert time.monotonic() - asked < timeouts.REQUEST_TIMEOUT
        finally:
            counted.close()
