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
The command table: for each command byte, the request and reply layouts.

Everything else in the codec is driven by this one table, in both
directions: the driver encodes requests and decodes replies with it, the
simulated sensor decodes requests and encodes replies with it, so the two
cannot disagree about a single byte. test/test_protocol_doc.py holds the
sizes to docs/protocol.md §6.

Each command also carries the least firmware that answers it (``firmware``,
as 0xE9 reports it: 2105 for 2.1.05), from the 3DM-GX2 Data Communications
Protocol manual v1.19, which gives it in each command's own section: 0xCF
needs 2.1.05; 0xD0, 0xD1 and 0xD2 need 2.1.12; 0xD3 needs 2.1.13; every
other command 2.1.00. A sensor answers nothing to a command newer than its
firmware, which looks like a lost packet: so every user of a command asks
this table (through codec/firmware.py) before sending it.
"""

import struct
from typing import NamedTuple

from . import records as r


class Field(NamedTuple):
    """One named field: a struct code for one element and how many there are."""

    name: str
    code: str
    count: int = 1
    #: What the field holds where its name, shared with other records, does not say it
    #: (0xC6's matrix is the last cycle's update, 0xD2's accel and mag are
    #: gyro-stabilised); empty: the name says it. The simulator makes each field from this.
    quantity: str = ''


class Layout(NamedTuple):
    """Request and reply layout of one command (all derived sizes included)."""

    code: int
    name: str
    confirm: bytes
    request: tuple[Field, ...]
    reply: tuple[Field, ...] | None
    record_type: type | None
    request_struct: struct.Struct
    reply_struct: struct.Struct | None
    #: Size of the request: command byte, confirmation bytes and arguments.
    request_size: int
    #: Size of the reply record inside a wireless packet (echo + data).
    record_size: int
    #: Size of the wired reply (record + 2-byte checksum); 0 when no reply.
    wired_size: int
    #: Where each record field sits in the unpacked tuple (index or slice).
    plan: tuple[object, ...]
    #: The least firmware that answers the command, as 0xE9 reports it (2105: 2.1.05).
    firmware: int


_TIMER = Field('timer', 'I')
#: Least firmware of the commands the manual gives no other one for: 2.1.00.
FIRMWARE_BASE = 2100


def _struct(fields: tuple[Field, ...]) -> struct.Struct:
    return struct.Struct('>' + ''.join(f.code * f.count for f in fields))


def field_plan(fields: tuple[Field, ...]) -> tuple[object, ...]:
    """Return where each of ``fields`` sits in their unpacked tuple: an index, or a slice."""
    plan = []
    index = 0
    for field in fields:
        plan.append(index if field.count == 1 else slice(index, index + field.count))
        index += field.count
    return tuple(plan)


def _layout(code: int, name: str, reply: tuple[Field, ...] | None,
            record_type: type | None, confirm: bytes = b'',
            request: tuple[Field, ...] = (), firmware: int = FIRMWARE_BASE) -> Layout:
    request_struct = _struct(request)
    reply_struct = _struct(reply) if reply is not None else None
    record_size = 1 + reply_struct.size if reply_struct is not None else 0
    return Layout(code=code, name=name, confirm=confirm, request=request, reply=reply,
                  record_type=record_type, request_struct=request_struct,
                  reply_struct=reply_struct, request_size=1 + len(confirm) + request_struct.size,
                  record_size=record_size, wired_size=record_size + 2 if record_size else 0,
                  plan=field_plan(reply) if reply is not None else (), firmware=firmware)


_ACCEL = Field('accel', 'f', 3)
_RATE = Field('angular_rate', 'f', 3)
_MAG = Field('mag', 'f', 3)
_MATRIX = Field('matrix', 'f', 9)
_BIAS = Field('bias', 'f', 3)
_EULER = (Field('roll', 'f'), Field('pitch', 'f'), Field('yaw', 'f'))
_DELTA = (Field('delta_angle', 'f', 3), Field('delta_velocity', 'f', 3))
_CONFIRM = b'\xC1\x29'

#: Command codes with a name, for readable call sites.
PING = 0x02
RAW_ACCEL_ANG_RATE = 0xC1
ACCEL_ANG_RATE = 0xC2
DELTA_ANGLE_VELOCITY = 0xC3
SET_CONTINUOUS = 0xC4
ORIENTATION_MATRIX = 0xC5
ORIENTATION_UPDATE_MATRIX = 0xC6
MAGNETOMETER = 0xC7
ACCEL_ANG_RATE_ORIENTATION = 0xC8
WRITE_ACCEL_BIAS = 0xC9
WRITE_GYRO_BIAS = 0xCA
ACCEL_ANG_RATE_MAG = 0xCB
ACCEL_ANG_RATE_MAG_ORIENTATION = 0xCC
CAPTURE_GYRO_BIAS = 0xCD
EULER_ANGLES = 0xCE
EULER_ANGLES_ANG_RATE = 0xCF
TRANSFER_TO_NON_VOLATILE = 0xD0
TEMPERATURES = 0xD1
STABILISED_ACCEL_ANG_RATE_MAG = 0xD2
DELTA_ANGLE_VELOCITY_MAG = 0xD3
WRITE_EEPROM = 0xE4
READ_EEPROM = 0xE5
FIRMWARE_VERSION = 0xE9
DEVICE_IDENTIFIER = 0xEA
STOP_CONTINUOUS = 0xFA
BUILT_IN_TEST = 0xFB

#: Every command of docs/protocol.md §6, by command byte.
LAYOUTS: dict[int, Layout] = {layout.code: layout for layout in (
    # Ping is a base-station exchange: its one-byte answer is neither an
    # echoed record nor checksummed, so it has no record layout here.
    _layout(PING, 'wireless_ping', None, r.PingReply, request=(Field('address', 'H'),)),
    _layout(RAW_ACCEL_ANG_RATE, 'raw_accel_ang_rate',
            (Field('accel_raw', 'f', 3), Field('angular_rate_raw', 'f', 3), _TIMER),
            r.RawAccelAngRate),
    _layout(ACCEL_ANG_RATE, 'accel_ang_rate', (_ACCEL, _RATE, _TIMER), r.AccelAngRate),
    _layout(DELTA_ANGLE_VELOCITY, 'delta_angle_velocity', (*_DELTA, _TIMER), r.DeltaAngleVelocity),
    _layout(SET_CONTINUOUS, 'set_continuous_mode', (Field('command', 'B'), _TIMER),
            r.ContinuousModeReply, _CONFIRM, (Field('command', 'B'),)),
    _layout(ORIENTATION_MATRIX, 'orientation_matrix', (_MATRIX, _TIMER), r.OrientationMatrix),
    _layout(ORIENTATION_UPDATE_MATRIX, 'orientation_update_matrix',
            (Field('matrix', 'f', 9, 'update_matrix'), _TIMER), r.OrientationUpdateMatrix),
    _layout(MAGNETOMETER, 'magnetometer', (_MAG, _TIMER), r.Magnetometer),
    _layout(ACCEL_ANG_RATE_ORIENTATION, 'accel_ang_rate_orientation',
            (_ACCEL, _RATE, _MATRIX, _TIMER), r.AccelAngRateOrientation),
    _layout(WRITE_ACCEL_BIAS, 'write_accel_bias', (_BIAS, _TIMER), r.AccelBias,
            b'\xB7\x44', (_BIAS,)),
    _layout(WRITE_GYRO_BIAS, 'write_gyro_bias', (_BIAS, _TIMER), r.GyroBias,
            b'\x12\xA5', (_BIAS,)),
    _layout(ACCEL_ANG_RATE_MAG, 'accel_ang_rate_mag', (_ACCEL, _RATE, _MAG, _TIMER),
            r.AccelAngRateMag),
    _layout(ACCEL_ANG_RATE_MAG_ORIENTATION, 'accel_ang_rate_mag_orientation',
            (_ACCEL, _RATE, _MAG, _MATRIX, _TIMER), r.AccelAngRateMagOrientation),
    _layout(CAPTURE_GYRO_BIAS, 'capture_gyro_bias', (_BIAS, _TIMER), r.CapturedGyroBias,
            _CONFIRM, (Field('sampling_time_ms', 'H'),)),
    _layout(EULER_ANGLES, 'euler_angles', (*_EULER, _TIMER), r.EulerAngles),
    _layout(EULER_ANGLES_ANG_RATE, 'euler_angles_ang_rate', (*_EULER, _RATE, _TIMER),
            r.EulerAnglesAngRate, firmware=2105),
    _layout(TRANSFER_TO_NON_VOLATILE, 'transfer_to_non_volatile',
            (Field('quantity', 'H'), _TIMER), r.TransferToNonVolatile,
            _CONFIRM, (Field('quantity', 'H'),), firmware=2112),
    _layout(TEMPERATURES, 'temperatures',
            (Field('accel_code', 'H'), Field('gyro_codes', 'H', 3), _TIMER), r.Temperatures,
            firmware=2112),
    _layout(STABILISED_ACCEL_ANG_RATE_MAG, 'stabilised_accel_ang_rate_mag',
            (Field('accel', 'f', 3, 'stabilised_accel'), _RATE,
             Field('mag', 'f', 3, 'stabilised_mag'), _TIMER), r.StabilisedAccelAngRateMag,
            firmware=2112),
    _layout(DELTA_ANGLE_VELOCITY_MAG, 'delta_angle_velocity_mag', (*_DELTA, _MAG, _TIMER),
            r.DeltaAngleVelocityMag, firmware=2113),
    _layout(WRITE_EEPROM, 'write_eeprom_word', (Field('value', 'H'),), r.EepromWritten,
            _CONFIRM + b'\x00', (Field('address', 'H'), Field('value', 'H'))),
    _layout(READ_EEPROM, 'read_eeprom_word', (Field('value', 'H'),), r.EepromWord,
            b'\x00', (Field('address', 'H'),)),
    _layout(FIRMWARE_VERSION, 'firmware_version', (Field('version', 'I'),), r.FirmwareVersion),
    _layout(DEVICE_IDENTIFIER, 'device_identifier',
            (Field('selector', 'B'), Field('text', '16s')), r.DeviceIdentifier,
            request=(Field('selector', 'B'),)),
    _layout(STOP_CONTINUOUS, 'stop_continuous_mode', None, None),
    # docs/protocol.md §11: the manual says 8 bytes but lists echo, config and
    # checksum; we follow the listed fields, 4 bytes wired.
    _layout(BUILT_IN_TEST, 'built_in_test', (Field('config', 'B'),), r.BuiltInTest,
            _CONFIRM, (Field('config', 'B'),)),
)}

#: Commands whose replies are framed records: echo byte -> record size.
RECORD_SIZES: dict[int, int] = {
    code: layout.record_size for code, layout in LAYOUTS.items() if layout.record_size
}
#: Largest record, which bounds every wireless data packet.
MAX_RECORD_SIZE = max(RECORD_SIZES.values())
#: Data records: no request arguments, a timer in the reply. These can be polled
#: and streamed (0xC4); derived from the table, not listed by hand.
STREAMABLE = frozenset(
    code for code, layout in LAYOUTS.items()
    if layout.reply and layout.reply[-1].name == 'timer'
    and not layout.request and not layout.confirm)
