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
The simulator's ground truth, kept compact, with the values the node would publish for it.

A run writes 10^5 records and more: each is kept as a :class:`Sent` with the
exact values the node publishes for it (computed by the node's own message
factory), so that a published message is matched to its record by its values
alone. :class:`TruthCollector` takes them from the simulator as they come, so
that its bounded truth never overflows.
"""

import struct
import threading
from typing import NamedTuple

from i3dmgx2_driver.codec.commands import decode_record
from i3dmgx2_driver.codec.errors import CodecError
from i3dmgx2_driver.codec.framing import HEADER_SIZE
from i3dmgx2_driver.codec.layouts import LAYOUTS
from i3dmgx2_driver.codec.orientation import ENU
from i3dmgx2_driver.codec.streams import STREAMS
from i3dmgx2_driver.ros.conversions import MessageFactory, MessageSettings, STANDARD_GRAVITY
from i3dmgx2_driver.simulator import PtySimulator

_KEY = struct.Struct('<6d')
_QUAT = struct.Struct('<4d')
_MARKS = (0xAA, 0x21)


class Sent(NamedTuple):
    """What the campaign keeps of one truth entry (compact: a run has 10^5 of them)."""

    index: int
    write_time: float | None
    valid: bool
    fault: str | None
    address: int
    source: str
    #: Exact published values (accel ENU m/s^2, rate ENU rad/s) of a 0xCC record, packed.
    key: bytes | None
    #: The values a corrupted 0xCC packet would publish if a parser accepted it.
    bad_key: bytes | None
    quat: bytes | None
    timer: int | None
    sample_time: float
    #: 0xAA and 0x21 bytes in the packet (each can become a spurious parser event).
    marks: int
    size: int
    #: Command byte of the record (None: not a streamable record).
    code: int | None = None


def imu_key(accel, rate) -> bytes:
    """Pack what the node publishes for a record, computed exactly as the node does."""
    g = STANDARD_GRAVITY
    return _KEY.pack(accel[0] * g, -accel[1] * g, -accel[2] * g,
                     rate[0], -rate[1], -rate[2])


#: For each stream's record type: the node's own message factory (ENU) and the record's
#: size in a packet, so that every stream's published values are computed as the node does.
_FACTORIES = {
    stream.record_type: (MessageFactory(MessageSettings('imu_link', ENU, stream=stream)),
                         LAYOUTS[stream.code].record_size, stream.code)
    for stream in STREAMS}


def imu_values(record) -> tuple[bytes, bytes] | None:
    """Return the packed (acceleration, rate) and orientation the node publishes, or None."""
    made = _FACTORIES.get(type(record))
    if made is None:
        return None
    factory = made[0]
    key = _KEY.pack(*factory.linear_acceleration(record), *factory.angular_velocity(record))
    return key, _QUAT.pack(*factory.orientation(record)[0])


def compact(entry) -> Sent:
    """Keep the parts of a SentRecord the checks need."""
    record = entry.record
    key = bad_key = quat = code = None
    values = imu_values(record)
    if values is not None:
        key, quat = values
        code = _FACTORIES[type(record)][2]
        if entry.fault == 'checksum':
            size = _FACTORIES[type(record)][1]
            try:
                bad = imu_values(decode_record(entry.packet[HEADER_SIZE:HEADER_SIZE + size]))
                bad_key = bad[0] if bad is not None else None
            except CodecError:
                bad_key = None
    marks = sum(1 for byte in entry.packet if byte in _MARKS)
    return Sent(entry.index, entry.write_time, entry.valid, entry.fault, entry.address,
                entry.source, key, bad_key, quat, entry.timer, entry.sample_time, marks,
                len(entry.packet), code)


class TruthCollector(threading.Thread):
    """Move the simulator's truth into compact form as it is produced."""

    def __init__(self, sim: PtySimulator) -> None:
        super().__init__(name='soak-truth', daemon=True)
        self.sim = sim
        self.entries: list[Sent] = []
        self.missed = 0
        self._next = 0
        self._halt = threading.Event()
        self._lock = threading.Lock()

    def collect(self) -> None:
        """Take whatever is new in the simulator's truth."""
        with self._lock:
            fresh = [e for e in self.sim.truth if e.index >= self._next]
            for entry in fresh:
                if entry.index != self._next:
                    self.missed += entry.index - self._next
                self.entries.append(compact(entry))
                self._next = entry.index + 1

    def run(self) -> None:
        """Collect twice a second until stopped."""
        while not self._halt.wait(0.5):
            self.collect()

    def stop(self) -> None:
        """Stop and take the rest."""
        self._halt.set()
        self.join(5.0)
        self.collect()
