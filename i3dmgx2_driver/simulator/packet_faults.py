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
What the radio and the line do to a packet on its way: lose it, spoil it, or surround it.

Before a packet is written, ``PacketFaults`` decides whether it is lost
(a stall, a drop), then what comes with it: garbage bytes before it, a packet
of another sensor (wireless), a flipped bit, a wrong length byte. Each draw
uses the fault generator in a fixed order, so a seeded run repeats exactly.
"""

import random

from i3dmgx2_driver.codec import layouts as lay

from . import faults as flt
from . import sensor as sns
from .base_station import BaseStation
from .faults import FaultConfig, FaultState
from .ground_truth import GroundTruth
from .line_writer import LineWriter
from .sensor import SimulatedSensor
from .wired_line import WiredLine


class PacketFaults:
    """
    The faults of one packet, drawn from ``rng``; call with the simulator's lock held.

    ``foreign`` is the other sensor whose packets the radio may pick up.
    """

    def __init__(self, faults: FaultState, rng: random.Random, end: BaseStation | WiredLine,
                 foreign: SimulatedSensor, writer: LineWriter, record: GroundTruth) -> None:
        self._faults = faults
        self._rng = rng
        self._end = end
        self.foreign = foreign
        self._writer = writer
        self._record = record

    def jitter(self) -> float:
        """Return the extra delay (s) of a packet on its way."""
        jitter_ms = self._faults.config.jitter_ms
        return self._rng.uniform(0.0, jitter_ms / 1000.0) if jitter_ms > 0 else 0.0

    def lost(self, send: float) -> str | None:
        """Return why a packet sent at ``send`` never arrives (stall, drop), or None."""
        faults = self._faults.config
        if self._faults.silent(send):
            return flt.FAULT_STALL
        if faults.drop_probability and self._rng.random() < faults.drop_probability:
            return flt.FAULT_DROPPED
        return None

    def spoil(self, packet: bytes, code: int, send: float) -> tuple[bytes, str | None]:
        """
        Write what comes before a packet (garbage, a foreign packet); return it as spoiled.

        Returns the packet to write (a bit flipped or its length byte changed,
        or as it was) and that fault (None: intact).
        """
        faults = self._faults.config
        rng = self._rng
        if faults.garbage_probability and rng.random() < faults.garbage_probability:
            garbage = self._garbage(faults)
            self._writer.write(garbage)
            self._record.count(garbage_bytes=len(garbage), garbage_bursts=1)
        if faults.foreign_probability and rng.random() < faults.foreign_probability:
            self._transmit_foreign(code, send)
        if faults.corrupt_checksum_probability \
                and rng.random() < faults.corrupt_checksum_probability:
            # A bit the checksum covers (record data) or of the checksum itself.
            data = bytearray(packet)
            data[rng.choice(self._end.checksum_positions(len(data)))] ^= 1 << rng.randrange(8)
            return bytes(data), flt.FAULT_CHECKSUM
        if faults.corrupt_length_probability \
                and rng.random() < faults.corrupt_length_probability:
            # The length byte of a data packet (wireless only: wired records have none).
            data = bytearray(packet)
            data[5] = (data[5] + rng.randint(1, 255)) & 0xFF
            return bytes(data), flt.FAULT_LENGTH
        return packet, None

    def _transmit_foreign(self, code: int, send: float) -> None:
        """Write a well-formed packet of another sensor (wireless only)."""
        foreign = self.foreign
        other = foreign.record_at(code if code in sns.STREAMABLE else lay.ACCEL_ANG_RATE, send)
        packet = BaseStation.frame(other, foreign.address, foreign)
        error, first_write, write_time = self._writer.write(packet)
        self._record.add(other, write_time, packet, foreign.address, False,
                         flt.FAULT_FOREIGN if error is None else error, 'foreign', first_write)

    def _garbage(self, faults: FaultConfig) -> bytes:
        rng = self._rng
        significant = self._end.significant_bytes
        out = bytearray()
        for _ in range(rng.randint(1, faults.garbage_max_bytes)):
            byte = rng.randrange(256)
            while faults.garbage_safe and byte in significant:
                byte = rng.randrange(256)
            out.append(byte)
        return bytes(out)
