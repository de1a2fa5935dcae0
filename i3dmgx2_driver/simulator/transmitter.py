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
What the sensor sends, on its way to the host: scheduled, delayed, spoiled, written.

Each record the sensor produces (a streamed cycle, or a reply to a command)
is queued with the time its bytes are due at the host: the radio latency,
the record's time on the serial line (10 bits a byte at ``wire_baud``, the
size of its frame: a data packet wireless, a wired record wired), and any
jitter. One thread takes the sensor's streamed cycles on an absolute grid,
so that no drift accumulates, and writes what is due, first sent first,
with its faults (silence, loss, garbage before it, a packet of another
sensor, a flipped bit, a wrong length byte; each draw made from the fault
generator in a fixed order, so a seeded run repeats exactly) and the line's
rate limit. Each is written in random chunks (``LineWriter``: a real serial
port hands a reader a packet in pieces, so a host parser meets every split;
what a full line could not take is lost and counted) and recorded in the
ground truth, written or lost, and why.

A record is written at its due time to within a few microseconds: the
thread takes it ``WRITE_LEAD_S`` early, makes its frame, sleeps until
``WRITE_SPIN_S`` before the due time and yields the processor in a loop
for the rest. A radio's delay does not depend on the host's scheduler; a
thread that merely slept until the due time wrote 0.2-0.7 ms late, by an
amount that wandered with the machine's load, and that lateness, not the
driver, was most of the noise the stamp benchmarks measured
(docs/timestamps.md). Several sensors behind one base station each have a
transmitter, and their packets take the one serial line in turn
(``SharedLine``): interleaved, never overlapping, at the line's rate.
"""

import heapq
import itertools
import math
import os
import random
import threading
import time
from typing import NamedTuple

from i3dmgx2_driver.codec import layouts as lay, line_budget

from . import faults as flt
from .base_station import BaseStation
from .config import SimulatorConfig
from .faults import FaultConfig, FaultState
from .ground_truth import GroundTruth
from .pty_port import PtyPort
from .sensor import Reply, SimulatedSensor, STREAMABLE
from .wired_line import WiredLine

#: Bytes per second of a 115200-baud 8N1 line.
LINE_BYTES_PER_SECOND = line_budget.line_bytes_per_second(115200)
#: Longest sleep of the thread, so that stop() never waits long.
POLL_S = 0.25
#: How long (s) before its due time a record is taken from the queue and framed.
WRITE_LEAD_S = 0.001
#: The last part (s) of the wait for the due time, spent yielding instead of sleeping
#: (a sleep wakes 50-100 us late: the kernel's timer slack and the wake-up).
WRITE_SPIN_S = 0.0003
#: How far behind (s) the base station's shared line may fall before it drops a
#: packet rather than queue it: several sensors sending more than the line
#: carries lose packets there, as a buffer of a few packets would.
LINE_BUFFER_S = 0.05
#: Time between two packets the sensor sent (s) from which the radio's link is taken to
#: have been away: the first packet after it is held ``radio_hold_s`` (``line_queue``).
GAP_S = 0.1


class LineWriter:
    """Writes frames to the port in random chunks; call with the simulator's lock held."""

    def __init__(self, port: PtyPort, record: GroundTruth, chunks: tuple[int, int],
                 gap_s: float, rng: random.Random) -> None:
        self._port, self._record = port, record
        self._chunks, self._gap_s, self._rng = chunks, gap_s, rng

    def write(self, data: bytes) -> tuple[str | None, float | None, float | None]:
        """Write one frame in chunks; return (fault or None, time of its first and last write)."""
        written, first, last = self._port.write_chunks(self._split(data), self._gap_s)
        if last is None:
            return flt.FAULT_UNPLUGGED, None, None
        self._record.written(len(data), written)
        if written < len(data):
            return flt.FAULT_OVERFLOW, None, None
        return None, first, last

    def _split(self, data: bytes) -> list[bytes]:
        count = min(self._rng.randint(*self._chunks), len(data))
        if count <= 1:
            return [data]
        cuts = sorted(self._rng.sample(range(1, len(data)), count - 1))
        return [data[a:b] for a, b in itertools.pairwise([0, *cuts, len(data)])]


class SharedLine:
    """
    The base station's one serial line, which several sensors' packets take in turn.

    A packet starts on the line when it has arrived over the radio and the
    packet before it, of whichever sensor, has left; its last byte is at the
    host its wire time later. Only a base station with several sensors has
    one (a single sensor's packets keep the timing they always had).
    """

    def __init__(self) -> None:
        #: When the last packet queued for the line has left it (wall clock).
        self.free_at = 0.0


class Outgoing(NamedTuple):
    """A record on its way, ordered by when the sensor sent it."""

    send: float
    seq: int
    write_at: float
    reply: Reply
    source: str
    #: Dropped by the base station: its line was too far behind (SharedLine).
    overflow: bool = False


class Transmitter:
    """
    The sensor's side of the line: its queue of records and the thread that writes them.

    ``wake`` is a condition on the simulator's lock: every method but
    :meth:`run` is called with the lock held, and :meth:`run` takes it for
    each step. It is notified whenever the queue or the stream changed.
    ``faults`` are the faults in effect, their draws made from ``rng`` in a
    fixed order, so that a seeded run repeats exactly; ``foreign`` is the
    other sensor whose packets the radio may pick up.
    """

    def __init__(self, config: SimulatorConfig, sensor: SimulatedSensor,
                 end: BaseStation | WiredLine, record: GroundTruth, wake: threading.Condition,
                 faults: FaultState, rng: random.Random, foreign: SimulatedSensor,
                 writer: LineWriter, line: SharedLine | None = None) -> None:
        self._config, self._sensor, self._end, self._record = config, sensor, end, record
        self._wake, self._faults, self._rng, self._foreign = wake, faults, rng, foreign
        self._writer, self._line = writer, line
        self._outbox: list[Outgoing] = []
        self._seq = 0
        #: When the stream's last record leaves the line, by the device's schedule.
        self._stream_line_free_at = 0.0
        #: The base station's serial line (``line_queue``): when its last byte left,
        #: the send time of the last packet it carried, and till when a packet after a
        #: gap is held back (wall clock).
        self._uart_free_at = 0.0
        self._uart_last_send: float | None = None

    def enqueue(self, reply: Reply, source: str) -> None:
        """Queue a record the sensor sends at ``reply.due`` ('stream' or 'reply')."""
        config = self._config
        wire = (line_budget.wire_time(reply.code, config.wire_baud, config.wireless)
                if config.wire_baud else 0.0)
        line, overflow = self._line, False
        if line is None:
            write_at = reply.due + (config.latency_s + wire + self._jitter())
        else:  # several sensors: each packet waits for the line behind the others'
            write_at = ready = reply.due + config.latency_s + self._jitter()
            overflow = line.free_at - ready > LINE_BUFFER_S
            if not overflow:
                write_at = line.free_at = max(ready, line.free_at) + wire
        self._seq += 1
        heapq.heappush(self._outbox,
                       Outgoing(reply.due, self._seq, write_at, reply, source, overflow))

    def clear(self) -> None:
        """Forget what is queued (the sensor lost its power)."""
        self._outbox.clear()

    def run(self, stop: threading.Event) -> None:
        """Take streamed cycles and write what is due until ``stop`` is set."""
        sensor = self._sensor
        while not stop.is_set():
            item = None
            with self._wake:
                now = time.time()
                next_sample = sensor.next_sample_time
                if next_sample is not None and next_sample <= now:
                    if now - next_sample > self._config.max_lag_s:
                        self._record.count(late_skipped=sensor.clock.skip_to(now))
                    else:
                        self.enqueue(sensor.stream_sample(), 'stream')
                    continue
                # The radio is a FIFO: the packet sent first is written first,
                # even when its delay (jitter) makes a later one ready sooner.
                if self._outbox and self._outbox[0].write_at <= now + WRITE_LEAD_S:
                    item = heapq.heappop(self._outbox)
                else:
                    wake = min(now + POLL_S, math.inf if next_sample is None else next_sample,
                               self._outbox[0].write_at - WRITE_LEAD_S if self._outbox
                               else math.inf)
                    self._wake.wait(max(wake - now, 0.0))
                    continue
            self._transmit(item)

    def _transmit(self, item: Outgoing) -> None:
        """
        Write one record with its faults, and record it in the ground truth.

        The lock is held throughout, so that a host that has read a packet and
        then looks at ``truth`` always finds it there, complete.
        """
        reply, address = item.reply, self._sensor.address
        with self._wake:
            packet = self._end.frame(reply, address, self._sensor)
            # With ``limit_to_line_rate`` the device skips a streamed record while its
            # UART still sends the stream's last one, judged on its own schedule (send
            # times), never on when this thread ran. Only the stream's own records
            # count: a reply is interleaved with the stream (docs/protocol.md §4,
            # combined mode) and never costs a record of a stream that fits.
            paced = self._config.limit_to_line_rate and item.source == 'stream'
            fault = self._lost(item.send) or (
                flt.FAULT_LINE_RATE if item.overflow or (
                    paced and item.send < self._stream_line_free_at - 1e-9) else None)
            if fault is not None:
                self._record.add(reply, None, packet, address, False, fault, item.source)
                return
            if paced:
                self._stream_line_free_at = (max(item.send, self._stream_line_free_at)
                                             + len(packet) / LINE_BYTES_PER_SECOND)
            before = self._record.stats.bytes_written
            packet, fault = self._spoil(packet, reply.code, item.send)
            _wait_until(self._through_uart(item, len(packet),
                                           self._record.stats.bytes_written - before)
                        if self._config.line_queue else item.write_at)
            error, first_write, write_time = self._writer.write(packet)
            valid = fault is None and error is None
            self._record.add(reply, write_time, packet, address, valid, fault or error,
                             item.source, first_write)

    def _through_uart(self, item: Outgoing, size: int, before: int) -> float:
        """
        Return when ``item``'s last byte leaves the base station's line (``line_queue``).

        It reached the base station over the radio at its due time less its
        own wire time; it starts on the line once the line is free, after the
        ``before`` bytes (garbage, a foreign packet) written ahead of it, and,
        the first after a gap, ``radio_hold_s`` later. What it waited is the
        queue: it leaves one wire time after the packet ahead of it.
        """
        config, last = self._config, self._uart_last_send
        byte_s = line_budget.BITS_PER_BYTE / config.wire_baud
        ready = item.write_at - size * byte_s
        if last is not None and item.send - last >= GAP_S:
            ready += config.radio_hold_s
        self._uart_last_send = item.send
        self._uart_free_at = max(ready, self._uart_free_at) + (before + size) * byte_s
        return self._uart_free_at

    # -- what the radio and the line do to a packet on its way ------------------------------

    def _jitter(self) -> float:
        """Return the extra delay (s) of a packet on its way."""
        jitter_ms = self._faults.config.jitter_ms
        return self._rng.uniform(0.0, jitter_ms / 1000.0) if jitter_ms > 0 else 0.0

    def _lost(self, send: float) -> str | None:
        """Return why a packet sent at ``send`` never arrives (stall, drop), or None."""
        if self._faults.silent(send):
            return flt.FAULT_STALL
        if (chance := self._faults.config.drop_probability) and self._rng.random() < chance:
            return flt.FAULT_DROPPED
        return None

    def _spoil(self, packet: bytes, code: int, send: float) -> tuple[bytes, str | None]:
        """
        Write what comes before a packet (garbage, a foreign packet); return it as spoiled.

        Returns the packet to write (a bit flipped or its length byte changed,
        or as it was) and that fault (None: intact).
        """
        faults, rng = self._faults.config, self._rng
        if faults.garbage_probability and rng.random() < faults.garbage_probability:
            garbage = self._garbage(faults)
            self._writer.write(garbage)
            self._record.count(garbage_bytes=len(garbage), garbage_bursts=1)
        if faults.foreign_probability and rng.random() < faults.foreign_probability:
            self._transmit_foreign(code, send)
        if (chance := faults.corrupt_checksum_probability) and rng.random() < chance:
            # A bit the checksum covers (record data) or of the checksum itself.
            data = bytearray(packet)
            data[rng.choice(self._end.checksum_positions(len(data)))] ^= 1 << rng.randrange(8)
            return bytes(data), flt.FAULT_CHECKSUM
        if (chance := faults.corrupt_length_probability) and rng.random() < chance:
            # The length byte of a data packet (wireless only: wired records have none).
            data = bytearray(packet)
            data[5] = (data[5] + rng.randint(1, 255)) & 0xFF
            return bytes(data), flt.FAULT_LENGTH
        return packet, None

    def _transmit_foreign(self, code: int, send: float) -> None:
        """Write a well-formed packet of another sensor (wireless only)."""
        foreign = self._foreign
        other = foreign.record_at(code if code in STREAMABLE else lay.ACCEL_ANG_RATE, send)
        packet = BaseStation.frame(other, foreign.address, foreign)
        error, first_write, write_time = self._writer.write(packet)
        self._record.add(other, write_time, packet, foreign.address, False,
                         flt.FAULT_FOREIGN if error is None else error, 'foreign', first_write)

    def _garbage(self, faults: FaultConfig) -> bytes:
        rng, significant, out = self._rng, self._end.significant_bytes, bytearray()
        for _ in range(rng.randint(1, faults.garbage_max_bytes)):
            byte = rng.randrange(256)
            while faults.garbage_safe and byte in significant:
                byte = rng.randrange(256)
            out.append(byte)
        return bytes(out)


def _wait_until(due: float) -> None:
    """Return at ``due`` (time.time()) to within microseconds, not the tens a sleep gives."""
    left = due - time.time()
    if left > WRITE_SPIN_S:
        time.sleep(left - WRITE_SPIN_S)
    while time.time() < due:
        os.sched_yield()  # releases the GIL: the host's reader may run meanwhile
