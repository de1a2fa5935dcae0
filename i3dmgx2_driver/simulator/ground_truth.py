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
The ground truth of a simulation: what the sensor sent, what the host did, the counters.

Tests and benchmarks compare what a driver publishes with these records: every
data packet produced (``SentRecord``, written or lost, with why), everything
the host sent (``HostCommand``), the stream the sensor was in over time, and
the counters (``SimulatorStats``). ``GroundTruth`` keeps them all; it has no
lock of its own: the simulator's lock guards it, so that one packet's bytes
and its record appear together. ``TruthQueries`` is its read side: every
answer is a copy taken under the simulator's lock, so a caller can keep it
while the simulation runs on, and every wait wakes on each new entry.
"""

import collections
import collections.abc
import copy
import threading
import time
from typing import Any, NamedTuple

from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.commands import Command

from . import faults as flt
from .sensor import Reply


class SentRecord(NamedTuple):
    """Ground truth of one data packet the sensor produced, written or lost."""

    #: Position in the order of production (0, 1, ...), across every source.
    index: int
    #: Wall-clock time (time.time()) of the sample it carries: its calculation cycle.
    sample_time: float
    #: Wall-clock time just before the write that carried its last byte: no reader
    #: has the whole packet earlier (a read may follow it closely); None if never
    #: written whole.
    write_time: float | None
    #: Raw uint32 timer of the record (None for records without one).
    timer: int | None
    #: The record as the codec decodes it.
    record: Any
    #: The packet bytes as written (corrupted if it was), or as it would have been.
    packet: bytes
    #: Node address in the packet.
    address: int
    #: Whether a correct parser, set to our address, accepts it.
    valid: bool
    #: What went wrong (see faults.FAULT_*), None for a good packet.
    fault: str | None
    #: 'stream', 'reply' (to a polled command) or 'foreign' (another sensor).
    source: str
    #: Wall-clock time just before the write of its first byte (None if never
    #: written whole). Its chunks may be written milliseconds apart when the
    #: writer is descheduled: a host that opens the port (flushing its input)
    #: in between gets only the packet's tail.
    first_write_time: float | None = None


class HostCommand(NamedTuple):
    """
    One thing the host sent, as the base station (or wired sensor) saw it, and what came of it.

    Wireless: every command packet, every rejected one and every ping. Wired:
    every command the sensor recognised in the byte stream (``kind`` 'wired',
    ``address`` None); the bytes it could not take for a command are only
    counted (``SimulatorStats.host_bytes_ignored``).
    """

    time: float
    #: 'packet' (command packet), 'rejected' (NACKed), 'ping' or 'wired'.
    kind: str
    address: int | None
    #: The decoded command, or None if it did not decode.
    command: Command | None
    raw: bytes
    #: 'delivered', 'ignored', 'lost', 'stalled', 'other_address', 'rejected: ...',
    #: 'ping ok', 'ping failed'.
    outcome: str


class SimulatorStats:
    """Counters of what the simulator did, for tests, benchmarks and the CLI."""

    __slots__ = (
        'acks', 'bytes_read', 'bytes_written', 'commands_ignored', 'commands_lost',
        'commands_other_address', 'commands_received', 'corrupted_checksum', 'corrupted_length',
        'dropped', 'foreign', 'garbage_bursts', 'garbage_bytes', 'host_bytes_ignored',
        'late_skipped', 'line_rate_skipped', 'nacks', 'overflow_bytes', 'overflow_packets',
        'packets_written', 'pings', 'port_opens', 'records_sent', 'replies_sent', 'stalled',
        'unplugged_lost', 'unplugs')

    def __init__(self) -> None:
        for name in self.__slots__:
            setattr(self, name, 0)

    def as_dict(self) -> dict[str, int]:
        """Return the counters by name."""
        return {name: getattr(self, name) for name in self.__slots__}

    def __repr__(self) -> str:
        fields_ = ', '.join(f'{k}={v}' for k, v in self.as_dict().items() if v)
        return f'SimulatorStats({fields_})'


#: Counter of each way a data packet can fail.
FAULT_COUNTERS = {
    flt.FAULT_CHECKSUM: 'corrupted_checksum', flt.FAULT_LENGTH: 'corrupted_length',
    flt.FAULT_FOREIGN: 'foreign', flt.FAULT_DROPPED: 'dropped', flt.FAULT_STALL: 'stalled',
    flt.FAULT_UNPLUGGED: 'unplugged_lost', flt.FAULT_OVERFLOW: 'overflow_packets',
    flt.FAULT_LINE_RATE: 'line_rate_skipped'}


class GroundTruth:
    """
    Everything recorded so far; call its methods with the simulator's lock held.

    ``changed`` is notified on every new entry, so that waiters (``wait_until``)
    wake at once.
    """

    def __init__(self, truth_limit: int | None, changed: threading.Condition) -> None:
        #: Data packets produced, in order (none kept when ``truth_limit`` is 0).
        self.truth: collections.deque[SentRecord] = collections.deque(maxlen=truth_limit)
        #: How many data packets were produced (kept or not).
        self.truth_index = 0
        #: (time, command) of every command the sensor received and decoded.
        self.commands: list[tuple[float, Command]] = []
        #: Everything the host sent, with its outcome.
        self.host_log: list[HostCommand] = []
        #: (time, command byte or 0) each time the sensor's stream changed.
        self.stream_changes: list[tuple[float, int]] = []
        self.stats = SimulatorStats()
        self._changed = changed

    def count(self, **counters: int) -> None:
        """Add to counters by name."""
        stats = self.stats
        for name, value in counters.items():
            setattr(stats, name, getattr(stats, name) + value)

    def log(self, entry: HostCommand, **counters: int) -> None:
        """Record one thing the host sent, and count it."""
        self.host_log.append(entry)
        self.count(**counters)
        self._changed.notify_all()

    def note_streaming(self, now: float, code: int) -> None:
        """Record the sensor's stream at ``now`` if it changed."""
        if not self.stream_changes or self.stream_changes[-1][1] != code:
            self.stream_changes.append((now, code))

    def written(self, wanted: int, written: int) -> None:
        """Count bytes written to the host, and those a full line lost."""
        self.count(bytes_written=written, overflow_bytes=max(wanted - written, 0))

    def add(self, reply: Reply, write_time: float | None, packet: bytes, address: int,
            valid: bool, fault: str | None, source: str,
            first_write_time: float | None = None) -> None:
        """Record one data packet and count it."""
        entry = SentRecord(self.truth_index, reply.sample_time, write_time,
                           getattr(reply.record, 'timer', None), reply.record, packet, address,
                           valid, fault, source, first_write_time)
        self.truth_index += 1
        self.truth.append(entry)
        self.count(packets_written=int(write_time is not None),
                   records_sent=int(valid and source == 'stream'),
                   replies_sent=int(valid and source != 'stream'))
        if fault in FAULT_COUNTERS:
            self.count(**{FAULT_COUNTERS[fault]: 1})
        self._changed.notify_all()


def _copied(name: str, copy_of: collections.abc.Callable[[Any], Any] = list) -> Any:
    """Return a property: a copy (``copy_of``) of the ground truth's ``name``, under the lock."""
    def get(self: 'TruthQueries') -> Any:
        with self._changed:
            return copy_of(getattr(self._record, name))
    return property(get)


class TruthQueries:
    """
    The ground truth as copies, and waits until it shows something; thread-safe.

    The simulator's observation surface: its users are the tests, the harness and
    the benchmarks (the package itself reads only ``stats``, for the command
    line), so that they all ask the ground truth one way and none reads it
    unlocked. ``changed`` is a condition on the simulator's lock, notified on
    every new entry.
    """

    def __init__(self, record: GroundTruth, changed: threading.Condition) -> None:
        self._record, self._changed = record, changed

    #: Every data packet produced so far, in order (a copy).
    truth: list[SentRecord] = _copied('truth')
    #: (time, command) of every command the sensor received (a copy).
    commands: list[tuple[float, Command]] = _copied('commands')
    #: Everything the host sent, with what became of it (a copy).
    host_log: list[HostCommand] = _copied('host_log')
    #: (time, command byte or 0) each time the sensor's stream changed (a copy).
    #: The first entry is the power-up state. A start, stop or change of
    #: stream (0xC4, 0xFA, power cycle, unplugging a wired sensor) adds one;
    #: asking for the record already streamed adds none. A test proves that
    #: an interrupted stream was restarted by finding a 0 followed by a code.
    stream_changes: list[tuple[float, int]] = _copied('stream_changes')
    #: A snapshot of the counters, which later counting does not change.
    stats: SimulatorStats = _copied('stats', copy.copy)

    def commands_of(self, *codes: int) -> list[tuple[float, Command]]:
        """(time, command) of the commands with these command bytes the sensor received."""
        with self._changed:
            return [entry for entry in self._record.commands if entry[1].code in codes]

    def eeprom_writes(self) -> list[tuple[float, Command]]:
        """
        Every EEPROM write (0xE4) the sensor received, whether or not it stored it.

        Empty proves that nothing was written to the EEPROM. (A write the radio
        lost never reached the sensor; ``host_log`` still shows it was sent.)
        """
        return self.commands_of(lay.WRITE_EEPROM)

    def wait_until(self, condition: collections.abc.Callable[[], bool],
                   timeout: float = 5.0) -> bool:
        """Wait until ``condition()`` is true (checked on every change); return it."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while not (met := condition()) and (remaining := deadline - time.monotonic()) > 0:
                self._changed.wait(min(remaining, 0.05))
            return bool(met)
