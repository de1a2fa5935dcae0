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
with its faults: silence (stall), loss, the line's rate limit, garbage
before it, a packet of another sensor, a flipped bit, a wrong length byte.
Each is written in random chunks and recorded in the ground truth, written
or lost, and why.
"""

import collections.abc
import heapq
import itertools
import random
import threading
import time
from typing import NamedTuple

from i3dmgx2_driver.codec import layouts as lay

from . import faults as flt
from . import sensor as sns
from .base_station import BaseStation
from .config import SimulatorConfig
from .faults import FaultConfig, Stall
from .ground_truth import GroundTruth
from .pty_port import PtyPort
from .sensor import Reply, SimulatedSensor
from .wired_line import WiredLine

#: Bytes per second of a 115200-baud 8N1 line.
LINE_BYTES_PER_SECOND = 11520
#: Longest sleep of the thread, so that stop() never waits long.
POLL_S = 0.25


class Outgoing(NamedTuple):
    """A record on its way, ordered by when the sensor sent it."""

    send: float
    seq: int
    write_at: float
    reply: Reply
    source: str
    address: int


class Transmitter:
    """
    The sensor's side of the line: its queue of records and the thread that writes them.

    ``lock`` is the simulator's: every method but :meth:`run` is called with
    it held, and :meth:`run` takes it for each step. ``wake`` (a condition on
    it) is notified whenever the queue or the stream changed.
    """

    def __init__(self, config: SimulatorConfig, sensor: SimulatedSensor,
                 foreign: SimulatedSensor, end: BaseStation | WiredLine, port: PtyPort,
                 record: GroundTruth, lock: threading.RLock, wake: threading.Condition,
                 stall: Stall, faults: collections.abc.Callable[[], FaultConfig],
                 fault_rng: random.Random, chunk_rng: random.Random) -> None:
        self._config = config
        self._sensor = sensor
        self._foreign = foreign
        self._end = end
        self._port = port
        self._record = record
        self._lock = lock
        self._wake = wake
        self._stall = stall
        self._faults = faults
        self._fault_rng = fault_rng
        self._chunk_rng = chunk_rng
        self._outbox: list[Outgoing] = []
        self._seq = 0
        #: When the stream's last record leaves the line, by the device's schedule.
        self._stream_line_free_at = 0.0

    def enqueue(self, reply: Reply, source: str, address: int) -> None:
        """Queue a record the sensor sends at ``reply.due``."""
        config = self._config
        faults = self._faults()
        delay = config.latency_s
        if config.wire_baud:
            delay += self._end.frame_size(len(reply.data)) * 10.0 / config.wire_baud
        if faults.jitter_ms > 0:
            delay += self._fault_rng.uniform(0.0, faults.jitter_ms / 1000.0)
        self._seq += 1
        heapq.heappush(self._outbox, Outgoing(reply.due, self._seq, reply.due + delay,
                                              reply, source, address))

    def clear(self) -> None:
        """Forget what is queued (the sensor lost its power)."""
        self._outbox.clear()

    def run(self, stop: threading.Event) -> None:
        """Take streamed cycles and write what is due until ``stop`` is set."""
        sensor = self._sensor
        while not stop.is_set():
            item = None
            with self._lock:
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
                if self._outbox and self._outbox[0].write_at <= now:
                    item = heapq.heappop(self._outbox)
                else:
                    wake = now + POLL_S
                    if next_sample is not None:
                        wake = min(wake, next_sample)
                    if self._outbox:
                        wake = min(wake, self._outbox[0].write_at)
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
        with self._lock:
            config = self._config
            faults = self._faults()
            rng = self._fault_rng
            packet = self._end.frame(reply, item.address, self._sensor)
            fault = None
            if self._stall.covers(item.send):
                fault = flt.FAULT_STALL
            elif faults.drop_probability and rng.random() < faults.drop_probability:
                fault = flt.FAULT_DROPPED
            elif config.limit_to_line_rate and item.source == 'stream' \
                    and item.send < self._stream_line_free_at - 1e-9:
                # The device's UART is still sending the stream's previous record
                # when this one is ready: the device skips it. Judged on the
                # device's own schedule (send times), never on when this thread
                # happened to run. Only the stream's own records count: a reply
                # to a command is interleaved with the stream (docs/protocol.md §4,
                # combined mode) and never costs a record of a stream that fits,
                # such as the first cycle after the 0xC4 that started it.
                fault = flt.FAULT_LINE_RATE
            if fault is not None:
                self._record.add(reply, None, packet, item.address, False, fault, item.source)
                return
            if config.limit_to_line_rate and item.source == 'stream':
                self._stream_line_free_at = (max(item.send, self._stream_line_free_at)
                                             + len(packet) / LINE_BYTES_PER_SECOND)
            if faults.garbage_probability and rng.random() < faults.garbage_probability:
                garbage = self._garbage(faults)
                self._write(garbage)
                self._record.count(garbage_bytes=len(garbage), garbage_bursts=1)
            if faults.foreign_probability and rng.random() < faults.foreign_probability:
                self._transmit_foreign(reply.code, item.send)
            if faults.corrupt_checksum_probability \
                    and rng.random() < faults.corrupt_checksum_probability:
                packet, fault = self._flip_bit(packet), flt.FAULT_CHECKSUM
            elif faults.corrupt_length_probability \
                    and rng.random() < faults.corrupt_length_probability:
                packet, fault = self._bad_length(packet), flt.FAULT_LENGTH
            error, first_write, write_time = self._write(packet)
            valid = fault is None and error is None
            self._record.add(reply, write_time, packet, item.address, valid, fault or error,
                             item.source, first_write)

    def _transmit_foreign(self, code: int, send: float) -> None:
        """Write a well-formed packet of another sensor (wireless only)."""
        foreign = self._foreign
        other = foreign.record_at(code if code in sns.STREAMABLE else lay.ACCEL_ANG_RATE, send)
        packet = BaseStation.frame(other, foreign.address, foreign)
        error, first_write, write_time = self._write(packet)
        self._record.add(other, write_time, packet, foreign.address, False,
                         flt.FAULT_FOREIGN if error is None else error, 'foreign', first_write)

    def _garbage(self, faults: FaultConfig) -> bytes:
        rng = self._fault_rng
        significant = self._end.significant_bytes
        out = bytearray()
        for _ in range(rng.randint(1, faults.garbage_max_bytes)):
            byte = rng.randrange(256)
            while faults.garbage_safe and byte in significant:
                byte = rng.randrange(256)
            out.append(byte)
        return bytes(out)

    def _flip_bit(self, packet: bytes) -> bytes:
        """Flip one bit the checksum covers (record data) or of the checksum itself."""
        rng = self._fault_rng
        data = bytearray(packet)
        data[rng.choice(self._end.checksum_positions(len(data)))] ^= 1 << rng.randrange(8)
        return bytes(data)

    def _bad_length(self, packet: bytes) -> bytes:
        """Change a data packet's length byte (wireless only: wired records have none)."""
        data = bytearray(packet)
        data[5] = (data[5] + self._fault_rng.randint(1, 255)) & 0xFF
        return bytes(data)

    def _split(self, data: bytes) -> list[bytes]:
        low, high = self._config.chunks
        count = min(self._chunk_rng.randint(low, high), len(data))
        if count <= 1:
            return [data]
        cuts = sorted(self._chunk_rng.sample(range(1, len(data)), count - 1))
        return [data[a:b] for a, b in itertools.pairwise([0, *cuts, len(data)])]

    def _write(self, data: bytes) -> tuple[str | None, float | None, float | None]:
        """Write one frame in chunks; return (fault or None, time of its first and last write)."""
        written, first_write, write_time = self._port.write_chunks(self._split(data),
                                                                   self._config.chunk_gap_s)
        if write_time is None:
            return flt.FAULT_UNPLUGGED, None, None
        self._record.written(len(data), written)
        if written < len(data):
            return flt.FAULT_OVERFLOW, None, None
        return None, first_write, write_time
