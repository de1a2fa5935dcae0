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
Encoders and decoders of commands and records, driven by the layout table.

Commands are what the host sends (command byte, confirmation bytes,
arguments); records are what the sensor answers (echo byte and data, without
the wired checksum, which belongs to the framing). Each direction has an
encoder and a decoder, so that the driver and the simulated sensor share one
implementation and every layout can be tested by a round trip.
"""

from collections.abc import Callable
from functools import partial
import math
from operator import itemgetter
from typing import Any, NamedTuple

from .errors import DecodeError, EncodeError, LengthError, UnknownCommandError
from .layouts import (
    BUILT_IN_TEST, CAPTURE_GYRO_BIAS, DEVICE_IDENTIFIER, Field, field_plan, Layout, LAYOUTS, PING,
    READ_EEPROM, SET_CONTINUOUS, STOP_CONTINUOUS, STREAMABLE, TRANSFER_TO_NON_VOLATILE,
    WRITE_ACCEL_BIAS, WRITE_EEPROM, WRITE_GYRO_BIAS,
)
from .records import DeviceIdentifier

#: The layout of each record type: which command byte a record answers.
LAYOUT_BY_TYPE: dict[type, Layout] = {
    layout.record_type: layout for layout in LAYOUTS.values()
    if layout.record_type is not None and layout.reply is not None
}
_INT_RANGES = {'B': 0xFF, 'H': 0xFFFF, 'I': 0xFFFFFFFF}


class Command(NamedTuple):
    """A decoded host command: its byte and its arguments in table order."""

    code: int
    args: tuple[Any, ...] = ()

    @property
    def name(self) -> str:
        """Name of the command in the layout table."""
        return LAYOUTS[self.code].name


def layout_of(code: int) -> Layout:
    """Return the layout of a command byte, or raise UnknownCommandError."""
    try:
        return LAYOUTS[code]
    except KeyError:
        raise UnknownCommandError(f'unknown command byte 0x{code:02X}') from None


def _flatten(fields: tuple[Field, ...], values: tuple[Any, ...], what: str) -> list:
    if len(values) != len(fields):
        names = ', '.join(f.name for f in fields) or 'no arguments'
        raise EncodeError(f'{what} takes {names}; got {len(values)} values')
    flat = []
    for field, value in zip(fields, values, strict=True):
        try:
            items = (value,) if field.count == 1 else tuple(value)
        except TypeError:
            raise EncodeError(f'{what}: {field.name} needs {field.count} values') from None
        if len(items) != field.count:
            raise EncodeError(f'{what}: {field.name} needs {field.count} values')
        for item in items:
            if (top := _INT_RANGES.get(field.code)) is not None:
                if isinstance(item, bool) or not isinstance(item, int) or not 0 <= item <= top:
                    raise EncodeError(
                        f'{what}: {field.name} must be an integer in 0..{top}, got {item!r}')
            elif field.code == 'f':
                if not isinstance(item, (int, float)) or isinstance(item, bool):
                    raise EncodeError(f'{what}: {field.name} must be a number')
                if math.isfinite(item) and abs(item) > 3.4028234663852886e38:
                    raise EncodeError(f'{what}: {field.name} overflows float32')
            elif field.code == '16s':
                text = item.encode('latin-1') if isinstance(item, str) else bytes(item)
                if len(text) != 16:
                    raise EncodeError(f'{what}: {field.name} must be 16 characters')
                item = text  # noqa: PLW2901 - the packed form replaces the text
            flat.append(item)
    return flat


def encode_command(code: int, *args: Any) -> bytes:
    """Return the command bytes (command byte, confirmation, arguments)."""
    layout = layout_of(code)
    flat = _flatten(layout.request, args, layout.name)
    return bytes((code,)) + layout.confirm + layout.request_struct.pack(*flat)


def decode_command(data: bytes) -> Command:
    """Decode command bytes as the sensor receives them."""
    if not data:
        raise LengthError('empty command')
    layout = layout_of(data[0])
    if len(data) != layout.request_size:
        raise LengthError(f'{layout.name} is {layout.request_size} bytes, got {len(data)}')
    confirm_end = 1 + len(layout.confirm)
    if bytes(data[1:confirm_end]) != layout.confirm:
        raise DecodeError(f'{layout.name}: wrong confirmation bytes')
    values = layout.request_struct.unpack_from(data, confirm_end)
    return Command(layout.code, tuple(values[at] for at in field_plan(layout.request)))


def _builder(layout: Layout) -> Callable[[tuple], Any]:
    """Return what makes ``layout``'s named record of its unpacked fields."""
    if layout.record_type is DeviceIdentifier:
        return lambda v: DeviceIdentifier(v[0], v[1].decode('latin-1'))
    get, make = itemgetter(*layout.plan), layout.record_type._make
    if len(layout.plan) == 1:  # itemgetter of one item returns it, not a tuple
        return lambda v: make((get(v),))
    return lambda v: make(get(v))


#: The named record of each echo byte's unpacked fields (replies and tools; a streamed
#: record goes on as its fields, framing.DataPacket).
_RECORDS = {code: _builder(layout) for code, layout in LAYOUTS.items()
            if layout.reply_struct is not None}


def record_of(code: int, values: tuple) -> Any:
    """Return the named record of echo byte ``code`` whose unpacked fields are ``values``."""
    return _RECORDS[code](values)


def decode_record(data: bytes) -> Any:
    """
    Decode a record (echo byte and data, no checksum) into its record type.

    The caller has already matched the size to the echo byte when the record
    came out of the stream parser; a mismatch here raises LengthError.
    """
    layout = LAYOUTS.get(data[0]) if data else None
    if layout is None or layout.reply_struct is None:
        raise UnknownCommandError(
            f'no record starts with 0x{data[0]:02X}' if data else 'empty record')
    if len(data) != layout.record_size:
        raise LengthError(f'{layout.name} record is {layout.record_size} bytes, got {len(data)}')
    return record_of(layout.code, layout.reply_struct.unpack_from(data, 1))


def encode_record(record: Any) -> bytes:
    """Encode a record as the sensor sends it (echo byte and data)."""
    layout = LAYOUT_BY_TYPE.get(type(record))
    if layout is None:
        raise EncodeError(f'{type(record).__name__} is not a record of the protocol')
    flat = _flatten(layout.reply, tuple(record), layout.name)
    return bytes((layout.code,)) + layout.reply_struct.pack(*flat)


# Builders for the commands the driver uses by name: they read better at the
# call site than encode_command with a bare code, and check their arguments.

def set_continuous(command: int) -> bytes:
    """
    Return the 0xC4 request to stream ``command`` (0 stops streaming).

    Only a data record streams (layouts.STREAMABLE): asking for another
    command (an EEPROM write, 0xFA) would be sent, and never answered.
    """
    if command and command not in STREAMABLE:
        valid = ', '.join(f'0x{code:02X}' for code in sorted(STREAMABLE))
        raise EncodeError(f'0x{command:02X} is not a record the sensor can stream; '
                          f'streamable records: {valid} (0 stops streaming)')
    return encode_command(SET_CONTINUOUS, command)


# The requests that take their arguments as the table lists them, nothing checked beyond it:
# ping(address), the base station's (sent unframed); stop_continuous(), 0xFA, which needs
# no reply; read_eeprom(address); write_eeprom(address, value); capture_gyro_bias(ms), for
# which the sensor must stay still; write_accel_bias((x, y, z)) in g and
# write_gyro_bias((x, y, z)) in rad/s; transfer_to_non_volatile(quantity) (1: accel bias,
# 2: gyro bias); device_identifier(selector) (0 model number, 1 serial, 2 name, 3 options);
# built_in_test(config bits).
ping = partial(encode_command, PING)
stop_continuous = partial(encode_command, STOP_CONTINUOUS)
read_eeprom = partial(encode_command, READ_EEPROM)
write_eeprom = partial(encode_command, WRITE_EEPROM)
capture_gyro_bias = partial(encode_command, CAPTURE_GYRO_BIAS)
write_accel_bias = partial(encode_command, WRITE_ACCEL_BIAS)
write_gyro_bias = partial(encode_command, WRITE_GYRO_BIAS)
transfer_to_non_volatile = partial(encode_command, TRANSFER_TO_NON_VOLATILE)
device_identifier = partial(encode_command, DEVICE_IDENTIFIER)
built_in_test = partial(encode_command, BUILT_IN_TEST)
