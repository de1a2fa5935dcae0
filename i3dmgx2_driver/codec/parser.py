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
Incremental stream parsers: bytes in, frames out, whatever the chunking.

``SensorStreamParser`` reads what the base station (or a wired sensor) sends
to the host; ``CommandStreamParser`` reads what the host sends to the sensor,
for the simulated sensor. Both keep partial frames between calls, trust a
length byte only after checking it against the size the command table gives
for the frame's echo byte, and on any mismatch move forward exactly one byte,
so that a corrupted length or checksum never swallows the good frames behind
it. Neither raises on bad input: they count what they skipped and why.
"""

from collections.abc import Callable
import struct
from typing import NamedTuple
from zlib import adler32

from .checksum import checksum16, EXACT_SUM_BYTES
from .framing import (
    ACK, COMMAND_FLAGS, CommandPacket, DATA_FLAGS, DATA_TRAILER_SIZE, DataPacket,
    HEADER_SIZE, NACK,
)
from .layouts import LAYOUTS, MAX_RECORD_SIZE, PING
from .records import PingReply

ByteString = bytes | bytearray | memoryview

#: Single bytes the base station answers with (ACK, NACK, ping answers).
_ANSWER_BYTES = frozenset((ACK, NACK, PING))
#: What a frame or an answer may start with where garbage ends (a ping's answer, the last,
#: only while one is awaited); a wired stream has none.
_MARKERS = (b'\xaa', b'\x21', b'\x02')
#: Largest frame either parser ever waits for; bounds the carried-over buffer.
MAX_FRAME_SIZE = HEADER_SIZE + MAX_RECORD_SIZE + DATA_TRAILER_SIZE


class Ack(NamedTuple):
    """The base station accepted a command packet (byte 0xAA)."""

    # A field, so that an Ack never compares equal to a Nack (two empty
    # tuples would): events are compared by value in callers and tests.
    byte: int = ACK


class Nack(NamedTuple):
    """The base station rejected a command packet (byte 0x21)."""

    byte: int = NACK


#: The two base-station answers, as single immutable instances.
ACK_EVENT = Ack()
NACK_EVENT = Nack()

Event = DataPacket | Ack | Nack | PingReply


class ParserStats:
    """Counters of what a parser saw, for diagnostics and tests."""

    __slots__ = ('acks', 'bytes_in', 'bytes_skipped', 'checksum_failures', 'foreign_frames',
                 'good_frames', 'length_failures', 'nacks')

    def __init__(self) -> None:
        for name in self.__slots__:
            setattr(self, name, 0)

    def as_dict(self) -> dict:
        """Return the counters by name."""
        return {name: getattr(self, name) for name in self.__slots__}

    def __repr__(self) -> str:
        fields = ', '.join(f'{k}={v}' for k, v in self.as_dict().items())
        return f'ParserStats({fields})'


#: A data packet's header before the record (SOP, flags, app type, address, length,
#: extra), the record's echo byte, and after the record LQI, RSSI and the sum, as struct
#: codes: with a record's fields between them, one unpack reads a whole packet.
_PACKET_HEAD = '>BBBHBBB'
_PACKET_TAIL = 'BBH'
#: Where a record's first field is in a whole packet's values, and its last after it.
_FIELDS = slice(len(_PACKET_HEAD) - 1, -len(_PACKET_TAIL))
_new = tuple.__new__
#: What :meth:`SensorStreamParser._packet_at` returns for a packet not yet whole, one
#: whose length byte, app type or extra byte is wrong, and one whose sum is wrong.
_WAIT, _BAD_LENGTH, _BAD_SUM = 0, 1, 2


class _Frame(NamedTuple):
    """How the records of one echo byte are read, in a wired frame and in a data packet."""

    #: The record's bytes: its echo byte and fields.
    size: int
    #: The whole data packet's bytes: header, record, LQI, RSSI, sum.
    packet_size: int
    #: ``unpack_from`` of the record's fields (after the echo byte), and of a whole packet.
    unpack: Callable[..., tuple]
    unpack_packet: Callable[..., tuple]


def _frames() -> dict[int, _Frame]:
    """Map each echo byte that has a record to its :class:`_Frame`, from the command table."""
    table = {}
    for code, layout in LAYOUTS.items():
        if layout.reply_struct is None:
            continue
        fields = layout.reply_struct.format.lstrip('>')
        packet = struct.Struct(_PACKET_HEAD + fields + _PACKET_TAIL)
        if packet.size > EXACT_SUM_BYTES:  # pragma: no cover - no record of the protocol is
            raise ValueError(f'0x{code:02X}: a packet too long for the sum in place')
        table[code] = _Frame(layout.record_size, packet.size, layout.reply_struct.unpack_from,
                             packet.unpack_from)
    return table


_FRAMES = _frames()


class SensorStreamParser:
    """
    Turn the byte stream from a base station or wired sensor into events.

    ``wireless`` selects the framing. With an ``address``, wireless packets
    from other nodes are counted and dropped. Call :meth:`expect_ping` before
    a ping so that its one-byte answer is recognised, and :meth:`idle` when
    the line has gone quiet, so that a lone trailing 0xAA is taken as an ACK
    rather than the start of a packet that never comes.
    """

    def __init__(self, address: int | None = None, wireless: bool = True) -> None:
        self.address = address
        self.wireless = wireless
        self.stats = ParserStats()
        #: Bytes held back for the rest of a frame (the reader reads their count).
        self.buffer = self._buf = bytearray()
        self._ping_pending = False
        self._quiet = 0

    def reset(self) -> None:
        """Forget any partial frame (after a reconnect); keep the counters."""
        self.stats.bytes_skipped += len(self._buf)
        self._buf.clear()
        self._ping_pending = False
        self._quiet = 0

    def expect_ping(self) -> None:
        """Take the next lone 0x02 or 0x21 as the answer to a ping."""
        self._ping_pending = True

    def listen_to(self, address: int | None) -> None:
        """Keep the data packets of ``address`` alone from now on (None: every node's)."""
        self.address = address

    def recount_as_foreign(self) -> None:
        """Count a frame already returned as good as foreign: its reader has no one for it."""
        self.stats.good_frames -= 1
        self.stats.foreign_frames += 1

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def idle(self) -> list[Event]:
        """Resolve a lone trailing 0xAA as an ACK once the line is quiet."""
        buf = self._buf
        if self.wireless and len(buf) == 1 and buf[0] == ACK:
            buf.clear()
            self.stats.acks += 1
            return [ACK_EVENT]
        return []

    def feed(self, chunk: ByteString) -> list[Event]:
        """Add bytes from the port; return the complete events, in order."""
        buf = self._buf
        if not buf and not self._quiet and self.wireless and len(chunk) > HEADER_SIZE:
            # What a flowing stream's read brings (the reader waits for a whole packet,
            # device/link.py): one sound packet of this node and nothing carried over.
            # Anything else takes the general path, which counts it.
            values = self._packet_at(chunk, 0, len(chunk))
            if type(values) is tuple and len(chunk) == _FRAMES[chunk[HEADER_SIZE]].packet_size \
                    and (self.address is None or values[3] == self.address):
                stats = self.stats
                stats.bytes_in += len(chunk)
                stats.good_frames += 1
                return [_new(DataPacket, (values[3], values[6], values[_FIELDS], values[-3],
                                          values[-2]))]
        buf += chunk
        self.stats.bytes_in += len(chunk)
        if self.wireless:
            consumed, events = self._parse_wireless(buf)
        else:
            consumed, events = self._parse_wired(buf)
        del buf[:consumed]
        if len(buf) > MAX_FRAME_SIZE:  # pragma: no cover - cannot happen by design
            self.stats.bytes_skipped += len(buf)
            buf.clear()
        return events

    @staticmethod
    def _packet_at(buf: ByteString, i: int, n: int) -> tuple | int:
        """
        Return the values of the data packet at ``buf[i]``, checked; or why there are none.

        The one check of a data packet, each of its bytes from the command
        table: its start and flags, its echo byte's record size in the length
        byte, the app type and extra byte zero, its sum. ``_WAIT``: not whole
        in the ``n`` bytes yet; ``_BAD_LENGTH``, ``_BAD_SUM``: not a packet.
        """
        if n - i <= HEADER_SIZE or buf[i] != ACK or buf[i + 1] != DATA_FLAGS:
            return _WAIT if n - i <= HEADER_SIZE else _BAD_LENGTH
        frame = _FRAMES.get(buf[i + HEADER_SIZE])
        if frame is None or buf[i + 5] != frame.size + 1 or buf[i + 2] or buf[i + 6]:
            return _BAD_LENGTH
        end = i + frame.packet_size
        if end > n:
            return _WAIT
        values = frame.unpack_packet(buf, i)
        # checksum16 written in place (a call less a record): every packet is within
        # EXACT_SUM_BYTES, which the frames' table holds at import.
        if adler32(buf[i + 1:end - DATA_TRAILER_SIZE], 0) & 0xFFFF != values[-1]:
            return _BAD_SUM
        return values

    def _lone_byte(self, byte: int, out: list[Event]) -> bool:
        """Handle a single-byte answer at a frame boundary; True if it was one."""
        stats = self.stats
        if self._ping_pending and byte in (PING, NACK):
            self._ping_pending = False
            out.append(PingReply(byte == PING))
            return True
        if byte == NACK and self.wireless:
            stats.nacks += 1
            out.append(NACK_EVENT)
            return True
        return False

    def _skip_garbage(self, buf: bytearray, i: int, n: int) -> int:
        """Return where the next possible frame starts after position ``i``."""
        nxt = n
        for marker in _MARKERS[:3 if self._ping_pending else 2] if self.wireless else ():
            j = buf.find(marker, i + 1)
            if 0 <= j < nxt:
                nxt = j
        self.stats.bytes_skipped += nxt - i
        return nxt

    def _parse_wireless(self, buf: bytearray):
        out: list[Event] = []
        stats = self.stats
        address = self.address
        n = len(buf)
        i = 0
        # Inside a packet that failed its checksum or its length byte, 0xAA and
        # 0x21 are its bytes, not the base station's answers: report no
        # ACK/NACK there (a valid packet starting inside it is still found).
        quiet_end = self._quiet
        while i < n:
            if buf[i] != ACK:
                if i >= quiet_end and self._lone_byte(buf[i], out):
                    i += 1
                elif i < quiet_end and buf[i] in _ANSWER_BYTES:
                    stats.bytes_skipped += 1
                    i += 1
                else:
                    i = self._skip_garbage(buf, i, n)
                continue
            if n - i < 2:
                break
            if buf[i + 1] != DATA_FLAGS:
                if i < quiet_end:
                    stats.bytes_skipped += 1
                else:
                    stats.acks += 1
                    out.append(ACK_EVENT)
                i += 1
                continue
            values = self._packet_at(buf, i, n)
            if values is _WAIT:
                break
            if values is _BAD_LENGTH:
                stats.length_failures += 1
                stats.bytes_skipped += 1
                frame = _FRAMES.get(buf[i + HEADER_SIZE])
                if frame is not None and not buf[i + 2] and not buf[i + 6]:
                    # Only the length byte is wrong: the packet is as long as
                    # its echo byte says, and its bytes are no answers either.
                    quiet_end = max(quiet_end, i + frame.packet_size)
                i += 1
                continue
            end = i + _FRAMES[buf[i + HEADER_SIZE]].packet_size - DATA_TRAILER_SIZE
            if values is _BAD_SUM:
                stats.checksum_failures += 1
                stats.bytes_skipped += 1
                quiet_end = max(quiet_end, end + DATA_TRAILER_SIZE)
                i += 1
                continue
            node = values[3]
            if address is not None and node != address:
                stats.foreign_frames += 1
            else:
                stats.good_frames += 1
                out.append(_new(DataPacket, (node, values[6], values[_FIELDS], values[-3],
                                             values[-2])))
            i = end + DATA_TRAILER_SIZE
        self._quiet = max(0, quiet_end - i)
        return i, out

    def _parse_wired(self, buf: bytearray):
        out: list[Event] = []
        stats = self.stats
        n = len(buf)
        i = 0
        while i < n:
            code = buf[i]
            entry = _FRAMES.get(code)
            if entry is None:
                if not self._lone_byte(code, out):
                    stats.bytes_skipped += 1
                i += 1
                continue
            end = i + entry.size
            if end + 2 > n:
                break
            if checksum16(buf[i:end]) != ((buf[end] << 8) | buf[end + 1]):
                stats.checksum_failures += 1
                stats.bytes_skipped += 1
                i += 1
                continue
            stats.good_frames += 1
            out.append(_new(DataPacket, (None, code, entry.unpack(buf, i + 1), None, None)))
            i = end + 2
        return i, out


class RejectedPacket(NamedTuple):
    """A command packet the base station must NACK, and why."""

    reason: str


class RawCommand(NamedTuple):
    """An unframed command: a ping to the base station, or a wired command."""

    command: bytes


HostEvent = CommandPacket | RejectedPacket | RawCommand

_MAX_REQUEST_SIZE = max(layout.request_size for layout in LAYOUTS.values())


class CommandStreamParser:
    """
    Turn the bytes a host sends into commands, as a base station sees them.

    Wireless: command packets (checked: header, length against the command
    table, checksum) and unframed pings. Wired: bare command bytes, whose
    size the command table gives. Used by the simulated sensor.

    A bad packet is reported once, as a base station NACKs it once: while
    the parser steps through the rest of the bytes that packet spans, it still
    finds any valid packet there, but it reports no further rejections and
    takes no 0x02 for an unframed ping (a length byte or checksum byte 0x02
    would otherwise start a false ping that swallows the next packet's start).

    ``codes`` narrows the unframed commands a reader knows (default: every
    command of the table): a wired sensor knows no wireless ping, and must not
    take a 0x02 inside a stray packet for the start of one.
    """

    def __init__(self, wireless: bool = True, codes: frozenset[int] | None = None) -> None:
        self.wireless = wireless
        self.codes = frozenset(LAYOUTS) if codes is None else frozenset(codes)
        self.stats = ParserStats()
        self._buf = bytearray()
        # Bytes still to come of the last rejected packet (see the class doc).
        self._quiet = 0

    def feed(self, chunk: ByteString) -> list[HostEvent]:
        """Add bytes from the host; return the complete commands, in order."""
        buf = self._buf
        buf += chunk
        self.stats.bytes_in += len(chunk)
        out: list[HostEvent] = []
        n = len(buf)
        i = 0
        while i < n:
            step = self._frame_at(buf, i, n, out)
            if step == 0:
                break
            i += step
            if self._quiet:
                self._quiet = max(0, self._quiet - step)
        del buf[:i]
        return out

    def _reject(self, out: list[HostEvent], reason: str, extent: int) -> int:
        """Count a bad packet, report it unless inside the last one; skip one byte."""
        self.stats.bytes_skipped += 1
        if not self._quiet:
            out.append(RejectedPacket(reason))
        self._quiet = max(self._quiet, extent)
        return 1

    def _frame_at(self, buf: bytearray, i: int, n: int, out: list[HostEvent]) -> int:
        """Return how many bytes the frame at ``i`` used (0: wait for more)."""
        stats = self.stats
        code = buf[i]
        if self.wireless and code == ACK:
            if n - i < HEADER_SIZE + 1:
                return 0
            layout = LAYOUTS.get(buf[i + HEADER_SIZE])
            size = buf[i + 5] - 1
            if buf[i + 1] != COMMAND_FLAGS or buf[i + 2] or buf[i + 6] or layout is None \
                    or layout.request_size != size:
                stats.length_failures += 1
                # Its extent: the longer of what its length byte says (at most
                # the longest command of the table) and what its command needs.
                size = max(0, min(size, _MAX_REQUEST_SIZE))
                if layout is not None:
                    size = max(size, layout.request_size)
                return self._reject(out, 'bad header or length', HEADER_SIZE + size + 2)
            end = i + HEADER_SIZE + size
            if end + 2 > n:
                return 0
            if checksum16(buf[i + 1:end]) != ((buf[end] << 8) | buf[end + 1]):
                stats.checksum_failures += 1
                return self._reject(out, 'bad checksum', end + 2 - i)
            stats.good_frames += 1
            self._quiet = 0
            out.append(CommandPacket((buf[i + 3] << 8) | buf[i + 4],
                                     bytes(buf[i + HEADER_SIZE:end])))
            return end + 2 - i
        layout = LAYOUTS.get(code) if code in self.codes else None
        if layout is None or (self.wireless and (code != PING or self._quiet)):
            stats.bytes_skipped += 1
            return 1
        if n - i < layout.request_size:
            return 0
        command = bytes(buf[i:i + layout.request_size])
        if command[1:1 + len(layout.confirm)] != layout.confirm:
            stats.bytes_skipped += 1
            return 1
        stats.good_frames += 1
        out.append(RawCommand(command))
        return layout.request_size
