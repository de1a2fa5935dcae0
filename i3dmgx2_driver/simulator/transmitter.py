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
with its faults (``packet_faults``: silence, loss, garbage before it, a
packet of another sensor, a flipped bit, a wrong length byte) and the
line's rate limit. Each is written in random chunks (``line_writer``) and
recorded in the ground truth, written or lost, and why.

A record is written at its due time to within a few microseconds: the
thread takes it ``WRITE_LEAD_S`` early, makes its frame, sleeps until
``WRITE_SPIN_S`` before the due time and yields the processor in a loop
for the rest. A radio's delay does not depend on the host's scheduler; a
thread that merely slept until the due time wrote 0.2-0.7 ms late, by an
amount that wandered with the machine's load, and that lateness, not the
driver, was most of the noise the stamp benchmarks measured
(docs/timestamps.md).
Several sensors
behind one base station each have a transmitter, and their packets take the
one serial line in turn (``SharedLine``): interleaved, never overlapping,
at the line's rate.
"""

import heapq
import os
import threading
import time
from typing import NamedTuple

from . import faults as flt
from .base_station import BaseStation
from .config import SimulatorConfig
from .ground_truth import GroundTruth
from .line_writer import LineWriter
from .packet_faults import PacketFaults
from .sensor import Reply, SimulatedSensor
from .wired_line import WiredLine

#: Bytes per second of a 115200-baud 8N1 line.
LINE_BYTES_PER_SECOND = 11520
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
    address: int
    #: Dropped by the base station: its line was too far behind (SharedLine).
    overflow: bool = False


class Transmitter:
    """
    The sensor's side of the line: its queue of records and the thread that writes them.

    ``wake`` is a condition on the simulator's lock: every method but
    :meth:`run` is called with the lock held, and :meth:`run` takes it for
    each step. It is notified whenever the queue or the stream changed.
    """

    def __init__(self, config: SimulatorConfig, sensor: SimulatedSensor,
                 end: BaseStation | WiredLine, record: GroundTruth, wake: threading.Condition,
                 faults: PacketFaults, writer: LineWriter,
                 line: SharedLine | None = None) -> None:
        self._config = config
        self._line = line
        self._sensor = sensor
        self._end = end
        self._record = record
        self._wake = wake
        self._faults = faults
        self._writer = writer
        self._outbox: list[Outgoing] = []
        self._seq = 0
        #: When the stream's last record leaves the line, by the device's schedule.
        self._stream_line_free_at = 0.0
        #: The base station's serial line (``line_queue``): when its last byte left,
        #: the send time of the last packet it carried, and till when a packet after a
        #: gap is held back (wall clock).
        self._uart_free_at = 0.0
        self._uart_last_send: float | None = None

    def enqueue(self, reply: Reply, source: str, address: int) -> None:
        """Queue a record the sensor sends at ``reply.due``."""
        config = self._config
        delay = config.latency_s
        wire = (self._end.frame_size(len(reply.data)) * 10.0 / config.wire_baud
                if config.wire_baud else 0.0)
        line = self._line
        overflow = False
        if line is None:
            write_at = reply.due + (delay + wire + self._faults.jitter())
        else:
            # Several sensors: each packet waits for the line behind the others'.
            ready = reply.due + delay + self._faults.jitter()
            overflow = line.free_at - ready > LINE_BUFFER_S
            if overflow:
                write_at = ready
            else:
                write_at = max(ready, line.free_at) + wire
                line.free_at = write_at
        self._seq += 1
        heapq.heappush(self._outbox, Outgoing(reply.due, self._seq, write_at,
                                              reply, source, address, overflow))

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
                        self._record.count(late_skipped=sensor.skip_to(now))
                    else:
                        self.enqueue(sensor.stream_sample(), 'stream', sensor.address)
                    continue
                # The radio is a FIFO: the packet sent first is written first,
                # even when its delay (jitter) makes a later one ready sooner.
                if self._outbox and self._outbox[0].write_at <= now + WRITE_LEAD_S:
                    item = heapq.heappop(self._outbox)
                else:
                    wake = now + POLL_S
                    if next_sample is not None:
                        wake = min(wake, next_sample)
                    if self._outbox:
                        wake = min(wake, self._outbox[0].write_at - WRITE_LEAD_S)
                    self._wake.wait(max(wake - now, 0.0))
                    continue
            self._transmit(item)

    def _transmit(self, item: Outgoing) -> None:
        """
        Write one record with its faults, and record it in the ground truth.

        The lock is held throughout, so that a host that has read a packet and
        then looks at ``truth`` always finds it there, complete.
        """
        reply = item.reply
        with self._wake:
            packet = self._end.frame(reply, item.address, self._sensor)
            # With ``limit_to_line_rate`` the device skips a streamed record while its
            # UART still sends the stream's last one, judged on its own schedule (send
            # times), never on when this thread ran. Only the stream's own records
            # count: a reply is interleaved with the stream (docs/protocol.md §4,
            # combined mode) and never costs a record of a stream that fits.
            paced = self._config.limit_to_line_rate and item.source == 'stream'
            fault = self._faults.lost(item.send) or (
                flt.FAULT_LINE_RATE if item.overflow or (
                    paced and item.send < self._stream_line_free_at - 1e-9) else None)
            if fault is not None:
                self._record.add(reply, None, packet, item.address, False, fault, item.source)
                return
            if paced:
                self._stream_line_free_at = (max(item.send, self._stream_line_free_at)
                                             + len(packet) / LINE_BYTES_PER_SECOND)
            before = self._record.stats.bytes_written
            packet, fault = self._faults.spoil(packet, reply.code, item.send)
            if self._config.line_queue:
                write_at = self._through_uart(item, len(packet),
                                              self._record.stats.bytes_written - before)
            else:
                write_at = item.write_at
            _wait_until(write_at)
            error, first_write, write_time = self._writer.write(packet)
            valid = fault is None and error is None
            self._record.add(reply, write_time, packet, item.address, valid, fault or error,
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
        config = self._config
        byte_s = 10.0 / config.wire_baud
        ready = item.write_at - size * byte_s
        last = self._uart_last_send
        if last is not None and item.send - last >= GAP_S:
            ready += config.radio_hold_s
        self._uart_last_send = item.send
        done = max(ready, self._uart_free_at) + (before + size) * byte_s
        self._uart_free_at = done
        return done


def _wait_until(due: float) -> None:
    """Return at ``due`` (time.time()) to within microseconds, not the tens a sleep gives."""
    left = due - time.time()
    if left > WRITE_SPIN_S:
        time.sleep(left - WRITE_SPIN_S)
    while time.time() < due:
        os.sched_yield()  # releases the GIL: the host's reader may run meanwhile
