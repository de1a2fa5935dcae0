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
Round trips through every command and record of the layout table, and the errors.

Commands: encode_command then decode_command, bare and inside a command packet,
and through the sensor-side stream parser. Records: encode_record then
decode_record, inside a wired reply, inside a wireless data packet, and through
the host-side stream parser. Values are float32-exact, so every round trip must
give back the same bits; NaN is compared as NaN and -0.0 keeps its sign.
"""

import math
import struct

from harness.decoders import decode_command_packet, decode_data_packet, decode_wired_record
from hypothesis import given, HealthCheck, settings, strategies as st
from i3dmgx2_driver.codec import (
    ChecksumError, CodecError, Command, CommandPacket, CommandStreamParser, DataPacket,
    decode_command, decode_record, DecodeError, encode_command, encode_command_packet,
    encode_data_packet, encode_record, encode_wired_record, EncodeError, LengthError,
    RawCommand, SensorStreamParser, UnknownCommandError,
)
from i3dmgx2_driver.codec import commands, records
from i3dmgx2_driver.codec.checksum import checksum16, EXACT_SUM_BYTES
from i3dmgx2_driver.codec.layouts import LAYOUTS, RECORD_SIZES
import pytest

CI = settings(max_examples=250, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow])

F32_MAX = struct.unpack('>f', bytes.fromhex('7F7FFFFF'))[0]
F32_TINY = struct.unpack('>f', bytes.fromhex('00000001'))[0]  # smallest subnormal
ADDRESSES = (1, 95, 0x00FF, 0x0100, 65534)

#: Wired reply sizes copied again from docs/protocol.md §6's command table (0: no reply).
PROTOCOL_WIRED_SIZES = {
    0xC1: 31, 0xC2: 31, 0xC3: 31, 0xC4: 8, 0xC5: 43, 0xC6: 43, 0xC7: 19, 0xC8: 67,
    0xC9: 19, 0xCA: 19, 0xCB: 43, 0xCC: 79, 0xCD: 19, 0xCE: 19, 0xCF: 31, 0xD0: 9,
    0xD1: 15, 0xD2: 43, 0xD3: 43, 0xE4: 5, 0xE5: 5, 0xE9: 7, 0xEA: 20, 0xFA: 0, 0xFB: 4,
}

#: Representative and boundary arguments of every command of the table.
COMMAND_CASES = {
    0x02: [(1,), (95,), (65534,)],
    0xC4: [(0x00,), (0xC2,), (0xCC,), (0xFF,)],
    0xC9: [((0.0, 0.0, 0.0),), ((0.015625, -0.5, 1.25),), ((F32_MAX, -F32_MAX, F32_TINY),),
           ((-0.0, math.inf, -math.inf),)],
    0xCA: [((0.0, 0.0, 0.0),), ((-0.001953125, 3.0, -7.5),), ((F32_TINY, -F32_TINY, -0.0),)],
    0xCD: [(0,), (10000,), (15000,), (30000,), (65535,)],
    0xD0: [(0,), (1,), (2,), (0xFFFF,)],
    0xE4: [(0, 0), (0xFCA2, 0x0100), (0xFCA6, 0x80CC), (0xFFFF, 0xFFFF)],
    0xE5: [(0,), (0xFCA2,), (0xFFFF,)],
    0xEA: [(0,), (1,), (2,), (3,), (0xFF,)],
    0xFB: [(0,), (0x04,), (0x3C,), (0xFF,)],
}
for _code, _layout in LAYOUTS.items():
    if not _layout.request:
        COMMAND_CASES.setdefault(_code, [()])
COMMAND_PARAMS = [(code, args) for code, cases in sorted(COMMAND_CASES.items())
                  for args in cases]

#: Codes of commands that have a reply record.
RECORD_CODES = sorted(RECORD_SIZES)


def same(a, b):
    """Compare values bit for bit: NaN equals NaN, 0.0 differs from -0.0, types must match."""
    if isinstance(a, float) or isinstance(b, float):
        if not (isinstance(a, float) and isinstance(b, float)):
            return False
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)
    if isinstance(a, tuple) or isinstance(b, tuple):
        return (isinstance(a, tuple) and isinstance(b, tuple) and len(a) == len(b)
                and all(same(x, y) for x, y in zip(a, b, strict=True)))
    return type(a) is type(b) and a == b


def test_same_helper_can_fail():
    """The comparison helper tells apart what the round trips must keep apart."""
    assert same((1.0, math.nan), (1.0, math.nan))
    assert not same(0.0, -0.0)
    assert not same(1.0, 1)
    assert not same((1.0, 2.0), (1.0, 2.5))
    assert not same(records.EepromWord(1), records.EepromWord(2))


def test_table_matches_protocol_sizes():
    """Every command of docs/protocol.md §6 is in the table with its wired reply size."""
    assert set(LAYOUTS) == set(PROTOCOL_WIRED_SIZES) | {0x02}
    for code, size in PROTOCOL_WIRED_SIZES.items():
        assert LAYOUTS[code].wired_size == size, hex(code)
        assert LAYOUTS[code].record_size == (size - 2 if size else 0), hex(code)


def test_every_command_has_cases():
    """The argument cases cover the whole table, so a new command cannot go untested."""
    assert set(COMMAND_CASES) == set(LAYOUTS)


@pytest.mark.parametrize('code, args', COMMAND_PARAMS,
                         ids=[f'{c:02X}-{i}' for i, (c, _) in enumerate(COMMAND_PARAMS)])
def test_command_round_trip(code, args):
    """encode_command then decode_command gives the command back, bare and framed."""
    data = encode_command(code, *args)
    layout = LAYOUTS[code]
    assert data[0] == code
    assert data[1:1 + len(layout.confirm)] == layout.confirm
    assert len(data) == layout.request_size
    command = decode_command(data)
    assert command.code == code
    assert same(command.args, tuple(args))
    assert encode_command(command.code, *command.args) == data
    for address in ADDRESSES:
        packet = encode_command_packet(address, data)
        assert len(packet) == 7 + len(data) + 2
        assert decode_command_packet(packet) == CommandPacket(address, data)


@pytest.mark.parametrize('code, args', COMMAND_PARAMS,
                         ids=[f'{c:02X}-{i}' for i, (c, _) in enumerate(COMMAND_PARAMS)])
def test_command_through_command_stream_parser(code, args):
    """The sensor-side parser finds each command, wireless as a packet and wired bare."""
    data = encode_command(code, *args)
    wireless = CommandStreamParser()
    assert wireless.feed(encode_command_packet(95, data)) == [CommandPacket(95, data)]
    wired = CommandStreamParser(wireless=False)
    assert wired.feed(data) == [RawCommand(data)]
    assert wireless.stats.good_frames == wired.stats.good_frames == 1


def test_named_builders_match_the_table():
    """The by-name builders are encode_command with the right code and arguments."""
    assert commands.ping(95) == encode_command(0x02, 95)
    assert commands.set_continuous(0xCC) == encode_command(0xC4, 0xCC)
    assert commands.set_continuous(0) == encode_command(0xC4, 0)
    assert commands.stop_continuous() == b'\xfa'
    assert commands.read_eeprom(0xFCA2) == encode_command(0xE5, 0xFCA2)
    assert commands.write_eeprom(0xFCA2, 512) == encode_command(0xE4, 0xFCA2, 512)
    assert commands.capture_gyro_bias(15000) == encode_command(0xCD, 15000)
    assert commands.write_accel_bias([0.5, 0.25, 0.0]) == encode_command(0xC9, (0.5, 0.25, 0.0))
    assert commands.write_gyro_bias((0.5, 0.25, 0.0)) == encode_command(0xCA, (0.5, 0.25, 0.0))
    assert commands.transfer_to_non_volatile(2) == encode_command(0xD0, 2)
    assert commands.device_identifier(3) == encode_command(0xEA, 3)
    assert commands.built_in_test(0x10) == encode_command(0xFB, 0x10)


# ---------------------------------------------------------------- records

def _element_values(code, variant):
    """One element value of a field code for a deterministic variant."""
    ints = {'B': 0xFF, 'H': 0xFFFF, 'I': 0xFFFFFFFF}
    if code == 'f':
        return {'zero': 0.0, 'max': F32_MAX, 'min': -F32_MAX, 'tiny': F32_TINY,
                'special': -0.0, 'typical': -0.7500152587890625, 'nan': math.nan,
                'inf': -math.inf}[variant]
    if code in ints:
        return {'zero': 0, 'max': ints[code], 'min': 0, 'tiny': 1, 'special': ints[code] // 2,
                'typical': 0x5A, 'nan': ints[code] - 1, 'inf': 2}[variant]
    text = {'zero': '\0' * 16, 'max': '\xff' * 16, 'min': ' ' * 16, 'tiny': 'a' * 16,
            'special': '3DM-GX2 \xe9\x01\x7f  123', 'typical': '    3DM-GX2-9795',
            'nan': '1234567890ABCDEF', 'inf': 'Inertia-Link    '}
    return text[variant]


def _record(code, variant):
    """Build the record of ``code`` with every element set by ``variant``."""
    layout = LAYOUTS[code]
    values = []
    for field in layout.reply:
        value = _element_values(field.code, variant)
        values.append(value if field.count == 1 else (value,) * field.count)
    return layout.record_type(*values)


VARIANTS = ('zero', 'max', 'min', 'tiny', 'special', 'typical', 'nan', 'inf')
RECORD_PARAMS = [(code, variant) for code in RECORD_CODES for variant in VARIANTS]
RECORD_IDS = [f'{code:02X}-{variant}' for code, variant in RECORD_PARAMS]


def _check_record_round_trips(record, address=95, lqi=0x7F, rssi=0xC3):
    """Check every path a record can take; return its encoded bytes."""
    data = encode_record(record)
    layout = LAYOUTS[data[0]]
    assert type(record) is layout.record_type
    assert len(data) == layout.record_size
    assert same(decode_record(data), record)
    # Wired: record + sum.
    wired = encode_wired_record(data)
    assert len(wired) == layout.wired_size
    assert int.from_bytes(wired[-2:], 'big') == sum(data) % 65536
    assert same(decode_wired_record(wired), record)
    # Wireless: inside a data packet.
    packet = encode_data_packet(address, data, lqi, rssi)
    assert len(packet) == 7 + layout.record_size + 4
    decoded = decode_data_packet(packet)
    assert (decoded.address, decoded.lqi, decoded.rssi) == (address, lqi, rssi)
    assert same(decoded.record, record)
    # Through the host-side stream parser, both framings, whole and byte by byte.
    for parser, frame, expected in (
            (SensorStreamParser(address=address), packet, (address, lqi, rssi)),
            (SensorStreamParser(wireless=False), wired, (None, None, None))):
        events = parser.feed(frame)
        assert len(events) == 1 and isinstance(events[0], DataPacket)
        assert (events[0].address, events[0].lqi, events[0].rssi) == expected
        assert same(events[0].record, record)
        events = [e for b in frame for e in parser.feed(bytes((b,)))]
        assert len(events) == 1 and same(events[0].record, record)
        assert parser.stats.good_frames == 2 and parser.pending == 0
    return data


@pytest.mark.parametrize('code, variant', RECORD_PARAMS, ids=RECORD_IDS)
def test_record_round_trip(code, variant):
    """Every record type, with zero, extreme, special and typical values, survives every path."""
    record = _record(code, variant)
    data = _check_record_round_trips(record)
    assert encode_record(decode_record(data)) == data


def test_every_record_type_is_covered():
    """Each record class of records.py is the reply of one command of the table."""
    classes = {obj for obj in vars(records).values()
               if isinstance(obj, type) and issubclass(obj, tuple) and obj is not tuple}
    covered = {LAYOUTS[code].record_type for code in RECORD_CODES}
    assert classes - covered == {records.PingReply}  # the ping answer is a bare byte


def test_nan_and_negative_zero_keep_their_bits():
    """A quiet NaN and -0.0 come back with exactly the same bytes."""
    record = records.Magnetometer((math.nan, -0.0, 0.0), 7)
    data = encode_record(record)
    assert data == bytes.fromhex('C7 7FC00000 80000000 00000000 00000007')
    assert encode_record(decode_record(data)) == data
    negative_nan = bytes.fromhex('C7 FFC00000 FFC00000 FFC00000 00000000')
    assert encode_record(decode_record(negative_nan)) == negative_nan


def test_records_are_immutable():
    """Records are named tuples: their fields cannot be reassigned."""
    record = _record(0xCC, 'typical')
    with pytest.raises(AttributeError):
        record.timer = 1


def _field_strategy(field):
    if field.code == 'f':
        element = st.floats(width=32)
    elif field.code == '16s':
        element = st.text(alphabet=st.characters(min_codepoint=0, max_codepoint=255),
                          min_size=16, max_size=16)
    else:
        element = st.integers(0, {'B': 0xFF, 'H': 0xFFFF, 'I': 0xFFFFFFFF}[field.code])
    if field.count == 1:
        return element
    return st.tuples(*[element] * field.count)


@st.composite
def any_record(draw):
    """Any record of the table with arbitrary float32 and integer fields."""
    layout = LAYOUTS[draw(st.sampled_from(RECORD_CODES))]
    return layout.record_type(*[draw(_field_strategy(f)) for f in layout.reply])


@st.composite
def any_command(draw):
    """Any command of the table with arbitrary in-range arguments."""
    layout = LAYOUTS[draw(st.sampled_from(sorted(LAYOUTS)))]
    return layout.code, tuple(draw(_field_strategy(f)) for f in layout.request)


@CI
@given(record=any_record(), address=st.integers(1, 65534), lqi=st.integers(0, 255),
       rssi=st.integers(0, 255))
def test_any_record_round_trips(record, address, lqi, rssi):
    """Property: any float32-exact record survives every encoding and framing."""
    _check_record_round_trips(record, address, lqi, rssi)


@CI
@given(command=any_command(), address=st.integers(1, 65534))
def test_any_command_round_trips(command, address):
    """Property: any in-range command survives encoding and framing."""
    code, args = command
    data = encode_command(code, *args)
    assert same(decode_command(data).args, args)
    assert decode_command_packet(encode_command_packet(address, data)) == CommandPacket(
        address, data)


# ---------------------------------------------------------------- errors

@pytest.mark.parametrize('code', RECORD_CODES, ids=[f'{c:02X}' for c in RECORD_CODES])
def test_record_wrong_size_is_length_error(code):
    """A record one byte short or long raises LengthError, bare, wired and framed."""
    data = encode_record(_record(code, 'typical'))
    for bad in (data[:-1], data + b'\0'):
        with pytest.raises(LengthError):
            decode_record(bad)
        with pytest.raises(LengthError):
            decode_wired_record(encode_wired_record(bad))
        with pytest.raises(LengthError):
            decode_data_packet(encode_data_packet(95, bad, 0, 0))
    packet = bytearray(encode_data_packet(95, data, 0, 0))
    packet[5] += 1  # the length byte no longer matches the packet
    with pytest.raises(LengthError):
        decode_data_packet(bytes(packet))


@pytest.mark.parametrize('code', sorted(LAYOUTS), ids=[f'{c:02X}' for c in sorted(LAYOUTS)])
def test_command_wrong_size_is_length_error(code):
    """Command bytes one short or one long raise LengthError."""
    data = encode_command(code, *COMMAND_CASES[code][0])
    for bad in (data[:-1], data + b'\0'):
        with pytest.raises(LengthError):
            decode_command(bad)
    packet = bytearray(encode_command_packet(95, data))
    packet[5] += 1
    with pytest.raises(LengthError):
        decode_command_packet(bytes(packet))


def test_short_frames_are_length_errors():
    """Frames shorter than any valid one raise LengthError before anything else."""
    with pytest.raises(LengthError):
        decode_command(b'')
    with pytest.raises(LengthError):
        decode_wired_record(b'\xe5\x00')
    with pytest.raises(LengthError):
        decode_data_packet(bytes.fromhex('AA 07 00 00 5F 02 00 E5 00 00 00'))
    with pytest.raises(LengthError):
        decode_command_packet(bytes.fromhex('AA 0B 00 00 5F 02 00 C2 01'))


def test_unknown_bytes_are_unknown_command_errors():
    """Bytes that start no command or no record raise UnknownCommandError."""
    for byte in range(256):
        if byte not in LAYOUTS:
            with pytest.raises(UnknownCommandError):
                decode_command(bytes((byte,)) + b'\0' * 4)
            with pytest.raises(UnknownCommandError):
                encode_command(byte)
        if byte not in RECORD_SIZES:
            with pytest.raises(UnknownCommandError):
                decode_record(bytes((byte,)) + b'\0' * 10)
            with pytest.raises(UnknownCommandError):
                decode_wired_record(bytes((byte, 0, byte)))
    with pytest.raises(UnknownCommandError):
        decode_record(b'')
    # 0x02 (ping) and 0xFA (stop) are commands without a record.
    assert 0x02 in LAYOUTS and 0x02 not in RECORD_SIZES
    assert 0xFA in LAYOUTS and 0xFA not in RECORD_SIZES


def test_bad_checksums_are_checksum_errors():
    """Any single flipped bit in the summed bytes or in the sum raises ChecksumError."""
    data = encode_record(_record(0xC2, 'typical'))
    wired = encode_wired_record(data)
    for index in range(len(wired)):
        for bit in range(8):
            bad = bytearray(wired)
            bad[index] ^= 1 << bit
            with pytest.raises(ChecksumError):
                decode_wired_record(bytes(bad))
    packet = encode_data_packet(0x1234, data, 1, 2)
    # address (3, 4), record (7 .. 7 + 28), checksum (last two); not the LQI and RSSI.
    positions = [3, 4, *range(7, 7 + len(data)), len(packet) - 2, len(packet) - 1]
    for index in positions:
        for bit in range(8):
            bad = bytearray(packet)
            bad[index] ^= 1 << bit
            with pytest.raises(ChecksumError):
                decode_data_packet(bytes(bad))
    command = encode_command_packet(0x1234, commands.write_eeprom(0xFCA2, 0x0100))
    for index in [3, 4, *range(7, len(command))]:
        bad = bytearray(command)
        bad[index] ^= 0x10
        with pytest.raises(ChecksumError):
            decode_command_packet(bytes(bad))


def test_bad_headers_are_decode_errors():
    """A command packet is not a data packet, and the constant header bytes are checked."""
    data_packet = encode_data_packet(95, encode_record(records.EepromWord(5)), 0, 0)
    command_packet = encode_command_packet(95, commands.read_eeprom(0xFCA2))
    with pytest.raises(DecodeError):
        decode_data_packet(command_packet)
    with pytest.raises(DecodeError):
        decode_command_packet(command_packet[:1] + b'\x07' + command_packet[2:])
    for index in (0, 1, 2, 6):
        bad = bytearray(data_packet)
        bad[index] ^= 0x40
        with pytest.raises(DecodeError):
            decode_data_packet(bytes(bad))
        bad = bytearray(command_packet)
        bad[index] ^= 0x40
        with pytest.raises(DecodeError):
            decode_command_packet(bytes(bad))


def test_wrong_confirmation_bytes_are_decode_errors():
    """Bytes with the wrong confirmation are a malformed command: DecodeError."""
    for bad in ('C4 C1 28 CC', 'C9 B7 45 00000000 00000000 00000000', 'CA 12 A4' + ' 00' * 12,
                'CD 29 C1 3A 98', 'D0 C1 2A 00 01', 'E4 C1 29 01 FC A2 01 00', 'E5 01 FC A2',
                'FB C2 29 04'):
        with pytest.raises(DecodeError):
            decode_command(bytes.fromhex(bad))


@pytest.mark.parametrize('call', [
    lambda: commands.read_eeprom(0x10000),
    lambda: commands.read_eeprom(-1),
    lambda: commands.write_eeprom(0x10000, 0),
    lambda: commands.write_eeprom(0xFCA2, 0x10000),
    lambda: commands.write_eeprom(0xFCA2, -1),
    lambda: commands.capture_gyro_bias(65536),
    lambda: commands.transfer_to_non_volatile(-1),
    lambda: commands.device_identifier(256),
    lambda: commands.built_in_test(0x100),
    lambda: commands.set_continuous(0x100),
    lambda: commands.set_continuous(0x01),
    lambda: commands.read_eeprom(True),
    lambda: commands.read_eeprom(0xFCA2 * 1.0),
    lambda: commands.read_eeprom('0xFCA2'),
    lambda: commands.write_accel_bias((1.0, 2.0)),
    lambda: commands.write_accel_bias((1.0, 2.0, 3.0, 4.0)),
    lambda: commands.write_gyro_bias(()),
    lambda: encode_command(0xC9, 1.0),
    lambda: commands.write_gyro_bias((1.0, '2', 3.0)),
    lambda: commands.write_gyro_bias((1.0, None, 3.0)),
    lambda: commands.write_gyro_bias((1.0, True, 3.0)),
    lambda: commands.write_gyro_bias((1e39, 0.0, 0.0)),
    lambda: encode_command(0xC2, 1),
    lambda: encode_command(0xE5),
    lambda: encode_command(0xE4, 0xFCA2),
    lambda: encode_command_packet(0, b'\xc2'),
    lambda: encode_command_packet(65535, b'\xc2'),
    lambda: encode_command_packet(-1, b'\xc2'),
    lambda: encode_command_packet(True, b'\xc2'),
    lambda: encode_command_packet(95.0, b'\xc2'),
    lambda: encode_command_packet(95, b''),
    lambda: encode_command_packet(95, b'\xc2' * 101),
    lambda: encode_data_packet(0, b'\xe5\x00\x00', 0, 0),
    lambda: encode_data_packet(65535, b'\xe5\x00\x00', 0, 0),
    lambda: encode_data_packet(95, b'\xe5\x00\x00', 256, 0),
    lambda: encode_data_packet(95, b'\xe5\x00\x00', 0, -1),
    lambda: encode_record(records.AccelAngRate((0.0, 0.0), (0.0, 0.0, 0.0), 0)),
    lambda: encode_record(records.AccelAngRate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1 << 32)),
    lambda: encode_record(records.AccelAngRate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), -1)),
    lambda: encode_record(records.AccelAngRate(0.0, (0.0, 0.0, 0.0), 0)),
    lambda: encode_record(records.EepromWord(0x10000)),
    lambda: encode_record(records.Temperatures(0, (0, 0, 70000), 0)),
    lambda: encode_record(records.DeviceIdentifier(1, 'too short')),
    lambda: encode_record(records.DeviceIdentifier(1, 'seventeen chars!!')),
    lambda: encode_record(records.PingReply(True)),
    lambda: encode_record((0.0, 0.0, 0.0)),
], ids=lambda _: '')
def test_bad_arguments_are_encode_errors(call):
    """Out-of-range, wrongly typed or wrongly counted arguments raise EncodeError."""
    with pytest.raises(EncodeError):
        call()


def test_error_hierarchy():
    """Every codec error is a CodecError and a ValueError; decode errors are DecodeErrors."""
    for error in (ChecksumError, LengthError, UnknownCommandError):
        assert issubclass(error, DecodeError)
    for error in (DecodeError, EncodeError):
        assert issubclass(error, CodecError)
    assert issubclass(CodecError, ValueError)
    assert not issubclass(EncodeError, DecodeError)


def test_command_accessors():
    """A decoded Command names itself from the table and keeps its arguments in order."""
    command = decode_command(commands.write_eeprom(0xFCA6, 0x80CC))
    assert command == Command(0xE4, (0xFCA6, 0x80CC))
    assert command.name == 'write_eeprom_word'
    assert decode_command(b'\xc2').args == ()


@given(st.binary(max_size=600))
def test_the_checksum_is_the_sum_of_the_bytes_modulo_65536(data):
    # Adler-32's first half below EXACT_SUM_BYTES, sum() above: either way the protocol's sum.
    assert checksum16(data) == sum(data) % 65536
    assert checksum16(bytearray(data)) == checksum16(memoryview(data)) == checksum16(data)


def test_the_checksum_at_the_edge_of_the_exact_sum():
    for size in (EXACT_SUM_BYTES - 1, EXACT_SUM_BYTES, EXACT_SUM_BYTES + 1, 2 * EXACT_SUM_BYTES):
        assert checksum16(b'\xff' * size) == (255 * size) % 65536, size
