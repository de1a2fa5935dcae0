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
Framing: wired records and the wireless (ASPP) command and data packets.

A framing only wraps bytes; what the bytes mean is the job of the command
table. The sums follow docs/protocol.md §2-§3 to the byte: a wired record sums itself,
a command packet sums all but its start byte, a data packet all but its
start byte, LQI and RSSI.
"""

from typing import Any, NamedTuple

from .checksum import append_checksum, checksum16
from .commands import decode_record, record_of
from .errors import ChecksumError, DecodeError, EncodeError, LengthError
from .layouts import LAYOUTS

#: Start of every wireless packet; the base station's ACK is the same byte.
SOP = 0xAA
#: The base station accepted a command packet and sent it over the air.
ACK = 0xAA
#: The base station rejected a command packet (malformed, bad checksum).
NACK = 0x21
#: Delivery flags of packets from the host to the sensor.
COMMAND_FLAGS = 0x0B
#: Delivery flags of packets from the sensor to the host.
DATA_FLAGS = 0x07
#: Bytes before the payload: SOP, flags, app type, address (2), length, extra.
HEADER_SIZE = 7
#: Bytes after a data packet's record: LQI, RSSI, checksum (2).
DATA_TRAILER_SIZE = 4
#: Lowest and highest node address a sensor can have.
MIN_ADDRESS = 1
MAX_ADDRESS = 65534
#: Longest command the base station accepts (docs/protocol.md §3: 1..100 bytes).
MAX_COMMAND_SIZE = 100


class DataPacket(NamedTuple):
    """
    A record as it arrived, flat: its sensor, its echo byte, its fields, its radio link.

    ``values`` are the record's fields as its layout unpacks them, in the
    layout's order (``LAYOUTS[code].plan`` says where each sits; a streamed
    record's timer is the last): the record path reads them where they lie,
    with no named record made. :attr:`record` names them, for replies and
    tools. ``address``, ``lqi`` and ``rssi`` are None for a wired frame.
    """

    address: int | None
    code: int
    values: tuple
    lqi: int | None
    rssi: int | None

    @property
    def record(self) -> Any:
        """Return the fields named, as their record type of codec/records.py."""
        return record_of(self.code, self.values)


class CommandPacket(NamedTuple):
    """A command as the sensor receives it through the base station."""

    address: int
    command: bytes


def _check_address(address: int) -> None:
    if isinstance(address, bool) or not isinstance(address, int) \
            or not MIN_ADDRESS <= address <= MAX_ADDRESS:
        raise EncodeError(
            f'node address must be in {MIN_ADDRESS}..{MAX_ADDRESS}, got {address!r}')


def _header(flags: int, address: int, payload_size: int) -> bytes:
    return bytes((SOP, flags, 0x00, address >> 8, address & 0xFF, payload_size + 1, 0x00))


def encode_command_packet(address: int, command: bytes) -> bytes:
    """Wrap command bytes in a wireless command packet for ``address``."""
    _check_address(address)
    if not 1 <= len(command) <= MAX_COMMAND_SIZE:
        raise EncodeError(f'a command is 1..{MAX_COMMAND_SIZE} bytes, got {len(command)}')
    body = _header(COMMAND_FLAGS, address, len(command)) + bytes(command)
    return body + checksum16(body[1:]).to_bytes(2, 'big')


def decode_command_packet(packet: bytes) -> CommandPacket:
    """Unwrap a wireless command packet (what the base station checks)."""
    if len(packet) < HEADER_SIZE + 3:
        raise LengthError(f'a command packet is at least 10 bytes, got {len(packet)}')
    if packet[0] != SOP or packet[1] != COMMAND_FLAGS or packet[2] != 0 or packet[6] != 0:
        raise DecodeError('not a command packet header')
    size = packet[5] - 1
    if len(packet) != HEADER_SIZE + size + 2:
        raise LengthError(f'length byte says {size} command bytes, packet has '
                          f'{len(packet) - HEADER_SIZE - 2}')
    if checksum16(packet[1:-2]) != int.from_bytes(packet[-2:], 'big'):
        raise ChecksumError('command packet checksum mismatch')
    return CommandPacket((packet[3] << 8) | packet[4], bytes(packet[HEADER_SIZE:-2]))


def encode_data_packet(address: int, record: bytes, lqi: int, rssi: int) -> bytes:
    """Wrap record bytes (echo and data, no checksum) in a data packet."""
    _check_address(address)
    if not 0 <= lqi <= 255 or not 0 <= rssi <= 255:
        raise EncodeError('LQI and RSSI are single bytes')
    body = _header(DATA_FLAGS, address, len(record)) + bytes(record)
    return body + bytes((lqi, rssi)) + checksum16(body[1:]).to_bytes(2, 'big')


def decode_data_packet(packet: bytes) -> DataPacket:
    """Unwrap and decode one complete wireless data packet."""
    if len(packet) < HEADER_SIZE + 1 + DATA_TRAILER_SIZE:
        raise LengthError(f'a data packet is at least 12 bytes, got {len(packet)}')
    if packet[0] != SOP or packet[1] != DATA_FLAGS or packet[2] != 0 or packet[6] != 0:
        raise DecodeError('not a data packet header')
    size = packet[5] - 1
    if len(packet) != HEADER_SIZE + size + DATA_TRAILER_SIZE:
        raise LengthError(f'length byte says {size} record bytes, packet has '
                          f'{len(packet) - HEADER_SIZE - DATA_TRAILER_SIZE}')
    end = HEADER_SIZE + size
    if checksum16(packet[1:end]) != int.from_bytes(packet[end + 2:end + 4], 'big'):
        raise ChecksumError('data packet checksum mismatch')
    record = bytes(packet[HEADER_SIZE:end])
    decode_record(record)  # raises for an unknown echo byte or a wrong size
    return DataPacket((packet[3] << 8) | packet[4], record[0],
                      LAYOUTS[record[0]].reply_struct.unpack_from(record, 1),
                      packet[end], packet[end + 1])


def encode_wired_record(record: bytes) -> bytes:
    """Append the wired checksum to record bytes."""
    return append_checksum(record)


def decode_wired_record(data: bytes) -> Any:
    """Check the checksum of a wired reply and decode its record."""
    if len(data) < 3:
        raise LengthError(f'a wired record is at least 3 bytes, got {len(data)}')
    if checksum16(data[:-2]) != int.from_bytes(data[-2:], 'big'):
        raise ChecksumError('wired record checksum mismatch')
    return decode_record(bytes(data[:-2]))
