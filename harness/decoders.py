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
One-shot decoders of one whole frame, each error named: what the stream parser is held to.

The driver reads frames only through ``SensorStreamParser``, which finds
them in a stream and never raises; these take one complete frame and raise
the codec's errors for what is wrong with it, for the golden vectors, the
round trips and the fuzz harness (fuzz_checks.py).
"""

from typing import Any

from i3dmgx2_driver.codec.checksum import checksum16
from i3dmgx2_driver.codec.commands import decode_record
from i3dmgx2_driver.codec.errors import ChecksumError, DecodeError, LengthError
from i3dmgx2_driver.codec.framing import (
    COMMAND_FLAGS, CommandPacket, DATA_FLAGS, DATA_TRAILER_SIZE, DataPacket, HEADER_SIZE, SOP,
)
from i3dmgx2_driver.codec.layouts import LAYOUTS


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


def decode_wired_record(data: bytes) -> Any:
    """Check the checksum of a wired reply and decode its record."""
    if len(data) < 3:
        raise LengthError(f'a wired record is at least 3 bytes, got {len(data)}')
    if checksum16(data[:-2]) != int.from_bytes(data[-2:], 'big'):
        raise ChecksumError('wired record checksum mismatch')
    return decode_record(bytes(data[:-2]))
