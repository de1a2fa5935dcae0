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

from .checksum import checksum16
from .commands import record_of
from .errors import EncodeError

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
        raise EncodeError(f'node address must be in {MIN_ADDRESS}..{MAX_ADDRESS}, got {address!r}')


def _header(flags: int, address: int, payload_size: int) -> bytes:
    return bytes((SOP, flags, 0x00, address >> 8, address & 0xFF, payload_size + 1, 0x00))


def encode_command_packet(address: int, command: bytes) -> bytes:
    """Wrap command bytes in a wireless command packet for ``address``."""
    _check_address(address)
    if not 1 <= len(command) <= MAX_COMMAND_SIZE:
        raise EncodeError(f'a command is 1..{MAX_COMMAND_SIZE} bytes, got {len(command)}')
    body = _header(COMMAND_FLAGS, address, len(command)) + bytes(command)
    return body + checksum16(body[1:]).to_bytes(2, 'big')


def encode_data_packet(address: int, record: bytes, lqi: int, rssi: int) -> bytes:
    """Wrap record bytes (echo and data, no checksum) in a data packet."""
    _check_address(address)
    if not 0 <= lqi <= 255 or not 0 <= rssi <= 255:
        raise EncodeError('LQI and RSSI are single bytes')
    body = _header(DATA_FLAGS, address, len(record)) + bytes(record)
    return body + bytes((lqi, rssi)) + checksum16(body[1:]).to_bytes(2, 'big')


def encode_wired_record(record: bytes) -> bytes:
    """Append the wired checksum (big-endian, of the record itself) to record bytes."""
    return bytes(record) + checksum16(record).to_bytes(2, 'big')
