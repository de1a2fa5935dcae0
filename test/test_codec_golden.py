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
Golden byte vectors, written out by hand from docs/protocol.md §2-§6.

Every hex literal here was built from the protocol tables by hand, with its
checksum added up in a comment; none was produced by the code under test. A
second, independent check recomputes each sum with ``sum()`` so that a typo in
a literal fails loudly instead of silently agreeing with a codec bug.
"""

import math
import struct

from harness.decoders import decode_command_packet, decode_data_packet, decode_wired_record
from i3dmgx2_driver.codec import (
    Ack, ChecksumError, Command, CommandPacket, CommandStreamParser, DataPacket,
    decode_command, decode_record, encode_command, encode_command_packet, encode_data_packet,
    encode_record, encode_wired_record, layout_of, Nack, RawCommand, SensorStreamParser,
)
from i3dmgx2_driver.codec import commands, records
from packets import packet_of
import pytest


def h(text):
    """Bytes from hex text with spaces (the way docs/protocol.md §3 writes packets)."""
    return bytes.fromhex(text)


ADDRESS = 95  # 0x005F: a sensor whose serial number ends in 95.

# Command packets: AA 0B 00 <addr hi> <addr lo> <len = command bytes + 1> 00 <command> <cs>,
# cs = sum of every byte after the SOP. The header part after the SOP adds up to
# 0x0B + 0x00 + 0x00 + 0x5F + len + 0x00 = 11 + 95 + len = 106 + len.

# 0xC4 C1 29 CC, 4 bytes, len 5: 111 + 0xC4 196 + 0xC1 193 + 0x29 41 + 0xCC 204 = 745 = 0x02E9.
SET_CONTINUOUS_CC = h('AA 0B 00 00 5F 05 00 C4 C1 29 CC 02 E9')
# 0xFA, 1 byte, len 2: 108 + 0xFA 250 = 358 = 0x0166.
STOP_CONTINUOUS = h('AA 0B 00 00 5F 02 00 FA 01 66')
# 0xC2, 1 byte, len 2: 108 + 0xC2 194 = 302 = 0x012E (the manual's polled example).
POLL_C2 = h('AA 0B 00 00 5F 02 00 C2 01 2E')
# 0xE5 00 FC A2, 4 bytes, len 5: 111 + 229 + 0 + 252 + 162 = 754 = 0x02F2.
READ_EEPROM_FCA2 = h('AA 0B 00 00 5F 05 00 E5 00 FC A2 02 F2')
# 0xE4 C1 29 00 FC A2 01 00 (write 0x0100 = 256, i.e. 200 Hz, to 0xFCA2), 8 bytes, len 9:
# 115 + 228 + 193 + 41 + 0 + 252 + 162 + 1 + 0 = 992 = 0x03E0.
WRITE_EEPROM_FCA2 = h('AA 0B 00 00 5F 09 00 E4 C1 29 00 FC A2 01 00 03 E0')
# 0xCD C1 29 3A 98 (15000 ms = 0x3A98), 5 bytes, len 6:
# 112 + 205 + 193 + 41 + 58 + 152 = 761 = 0x02F9.
CAPTURE_GYRO_BIAS_15000 = h('AA 0B 00 00 5F 06 00 CD C1 29 3A 98 02 F9')
# 0xEA 01 (serial number), 2 bytes, len 3: 109 + 234 + 1 = 344 = 0x0158.
DEVICE_IDENTIFIER_1 = h('AA 0B 00 00 5F 03 00 EA 01 01 58')
# 0xFB C1 29 04 (bit 2: magnetometer BIT), 4 bytes, len 5: 111 + 251 + 193 + 41 + 4 = 600.
BUILT_IN_TEST_04 = h('AA 0B 00 00 5F 05 00 FB C1 29 04 02 58')

COMMAND_GOLDEN = [
    # (golden packet, builder output, decoded command)
    (SET_CONTINUOUS_CC, commands.set_continuous(0xCC), Command(0xC4, (0xCC,))),
    (STOP_CONTINUOUS, commands.stop_continuous(), Command(0xFA, ())),
    (POLL_C2, encode_command(0xC2), Command(0xC2, ())),
    (READ_EEPROM_FCA2, commands.read_eeprom(0xFCA2), Command(0xE5, (0xFCA2,))),
    (WRITE_EEPROM_FCA2, commands.write_eeprom(0xFCA2, 0x0100), Command(0xE4, (0xFCA2, 256))),
    (CAPTURE_GYRO_BIAS_15000, commands.capture_gyro_bias(15000), Command(0xCD, (15000,))),
    (DEVICE_IDENTIFIER_1, commands.device_identifier(1), Command(0xEA, (1,))),
    (BUILT_IN_TEST_04, commands.built_in_test(0x04), Command(0xFB, (0x04,))),
]
COMMAND_IDS = ['set_continuous_cc', 'stop', 'poll_c2', 'read_eeprom', 'write_eeprom',
               'capture_gyro_bias', 'device_identifier', 'built_in_test']

# The first record of the real fixture (set 'red'), 77 bytes: echo 0xCC, 18 float32, timer.
# Byte sums of each 4-byte word, added by hand:
#   echo CC 204
#   accel 3F7CC997 539, BC63121F 336, 3CD63C8A 472
#   rate  BAA16A44 521, BCBF83A0 670, BBAA62DC 675
#   mag   FFC00000 447 (x3: NaN) = 1341
#   M     BE1A8A77 473, BD563B92 480, BF7CB69F 656,
#         3F047BEA 424, BF5AE19E 664, BD0A8482 461,
#         BF579E51 517, BF0416F6 463, 3E1FD9B7 493
#   timer 17A9C489 525
# record: 204 + 1347 + 1866 + 1341 + 1593 + 1549 + 1473 + 525 = 9914 = 0x26BA.
FIXTURE_RECORD = h(
    'CC'
    ' 3F7CC997 BC63121F 3CD63C8A'
    ' BAA16A44 BCBF83A0 BBAA62DC'
    ' FFC00000 FFC00000 FFC00000'
    ' BE1A8A77 BD563B92 BF7CB69F 3F047BEA BF5AE19E BD0A8482 BF579E51 BF0416F6 3E1FD9B7'
    ' 17A9C489')
# Data packet: AA 07 00 00 5F 4E(77 + 1) 00 <record> C8(LQI 200) 5A(RSSI 90) <cs>;
# cs = 0x07 + 0x5F + 0x4E + record = 7 + 95 + 78 + 9914 = 10094 = 0x276E (LQI, RSSI excluded).
FIXTURE_DATA_PACKET = h('AA 07 00 00 5F 4E 00') + FIXTURE_RECORD + h('C8 5A 27 6E')
# The same record as a wired reply: record + its own sum, 9914 = 0x26BA.
FIXTURE_WIRED = FIXTURE_RECORD + h('26 BA')

# A 0xC2 record made up by hand: accel (0, 0, -1) g (flat, z down), rate (0.25, -0.125, 0.5)
# rad/s, timer 0x012C0000 = 19,660,800 ticks = 1 s.
# Sum: C2 194 + BF 191 + 80 128 + 3E 62 + 80 128 + BE 190 + 3F 63 + 01 1 + 2C 44 = 1001 = 0x03E9.
C2_RECORD = h('C2 00000000 00000000 BF800000 3E800000 BE000000 3F000000 012C0000')
C2_WIRED = C2_RECORD + h('03 E9')
# The manual's wireless 0xC2 reply: AA 07 00 <addr> 1E 00 C2 <28 data bytes> <LQI> <RSSI> <cs>;
# cs = 7 + 95 + 30 (0x1E) + 1001 = 1133 = 0x046D.
C2_DATA_PACKET = h('AA 07 00 00 5F 1E 00') + C2_RECORD + h('40 20 04 6D')
C2_EXPECTED = records.AccelAngRate((0.0, 0.0, -1.0), (0.25, -0.125, 0.5), 19_660_800)

# Other wired replies, summed by hand.
# 0xE5 reply, word 0x0200 (= 512, the factory rate divisor): E5 229 + 02 2 = 231 = 0x00E7.
EEPROM_WORD_WIRED = h('E5 02 00 00 E7')
# 0xE9 reply, version 2103 = 0x00000837: E9 233 + 08 8 + 37 55 = 296 = 0x0128.
FIRMWARE_WIRED = h('E9 00 00 08 37 01 28')
# 0xC4 reply: now streaming 0xCC, timer 0: C4 196 + CC 204 = 400 = 0x0190.
CONTINUOUS_REPLY_WIRED = h('C4 CC 00 00 00 00 01 90')

# Base-station ping of node 95, sent unframed; the answer is one bare byte.
PING_95 = h('02 00 5F')


def f32(hex_word):
    """Decode one big-endian float32 with struct: the independent reference."""
    return struct.unpack('>f', bytes.fromhex(hex_word))[0]


@pytest.mark.parametrize('golden', [g for g, _, _ in COMMAND_GOLDEN] + [
    FIXTURE_DATA_PACKET, C2_DATA_PACKET], ids=[*COMMAND_IDS, 'data_cc', 'data_c2'])
def test_hand_sums_of_packets(golden):
    """The hand-added checksums equal an independent sum (catches typos in the literals)."""
    if golden[1] == 0x0B:
        summed = golden[1:-2]
    else:
        summed = golden[1:-4]
    assert sum(summed) % 65536 == int.from_bytes(golden[-2:], 'big')
    assert golden[5] == len(summed) - 5  # length byte: payload + 1


def test_hand_sums_of_wired_replies():
    """The hand-added wired checksums equal an independent sum."""
    for golden in (FIXTURE_WIRED, C2_WIRED, EEPROM_WORD_WIRED, FIRMWARE_WIRED,
                   CONTINUOUS_REPLY_WIRED):
        assert sum(golden[:-2]) % 65536 == int.from_bytes(golden[-2:], 'big')


def test_set_continuous_cc_exact_bytes():
    """The full packet that sets continuous 0xCC mode for address 95, byte for byte."""
    command = encode_command(0xC4, 0xCC)
    assert command == h('C4 C1 29 CC')
    assert encode_command_packet(ADDRESS, command) == SET_CONTINUOUS_CC


@pytest.mark.parametrize('golden, built, expected', COMMAND_GOLDEN, ids=COMMAND_IDS)
def test_command_packets_encode(golden, built, expected):
    """The builders produce the wired command bytes, and framing the golden packets."""
    assert built == golden[7:-2]
    assert encode_command_packet(ADDRESS, built) == golden


@pytest.mark.parametrize('golden, built, expected', COMMAND_GOLDEN, ids=COMMAND_IDS)
def test_command_packets_decode(golden, built, expected):
    """Decoding a golden packet gives its address and the command's fields."""
    packet = decode_command_packet(golden)
    assert packet == CommandPacket(ADDRESS, golden[7:-2])
    assert decode_command(packet.command) == expected


def test_command_arguments_in_table_order():
    """Decoded commands carry their arguments in the order the layout table names them."""
    command = decode_command(decode_command_packet(WRITE_EEPROM_FCA2).command)
    assert command.name == 'write_eeprom_word'
    assert command.args == (0xFCA2, 0x0100)
    assert [field.name for field in layout_of(command.code).request] == ['address', 'value']
    command = decode_command(decode_command_packet(CAPTURE_GYRO_BIAS_15000).command)
    assert command.args == (15000,)
    assert decode_command(h('C4 C1 29 CC')).args == (0xCC,)


def test_command_stream_parser_reads_golden_packets():
    """The sensor-side parser finds every golden packet in one back-to-back stream."""
    parser = CommandStreamParser()
    stream = b''.join(g for g, _, _ in COMMAND_GOLDEN) + PING_95
    events = parser.feed(stream)
    assert events == [CommandPacket(ADDRESS, g[7:-2]) for g, _, _ in COMMAND_GOLDEN] + [
        RawCommand(PING_95)]
    assert parser.stats.good_frames == len(COMMAND_GOLDEN) + 1
    assert parser.stats.bytes_skipped == 0


def test_stop_has_no_reply():
    """0xFA is the stop without a reply: no record layout, wired reply size 0."""
    layout = layout_of(0xFA)
    assert layout.wired_size == 0
    assert layout.record_size == 0
    assert layout.reply is None


def test_cc_sizes_match_protocol():
    """docs/protocol.md §3's worked size: 77-byte record, length byte 78, 88-byte data packet."""
    assert layout_of(0xCC).record_size == 77
    assert layout_of(0xCC).wired_size == 79
    assert len(FIXTURE_RECORD) == 77
    assert FIXTURE_DATA_PACKET[5] == 78
    assert len(FIXTURE_DATA_PACKET) == 88


def test_fixture_data_packet_encodes():
    """Wrapping the fixture record for node 95 with LQI 200, RSSI 90 gives the golden packet."""
    assert encode_data_packet(ADDRESS, FIXTURE_RECORD, 200, 90) == FIXTURE_DATA_PACKET
    assert encode_wired_record(FIXTURE_RECORD) == FIXTURE_WIRED


def _check_fixture_record(record):
    assert isinstance(record, records.AccelAngRateMagOrientation)
    assert record.accel == (f32('3F7CC997'), f32('BC63121F'), f32('3CD63C8A'))
    assert record.accel[0] == pytest.approx(0.987451, abs=1e-6)
    assert record.angular_rate == (f32('BAA16A44'), f32('BCBF83A0'), f32('BBAA62DC'))
    assert record.angular_rate[2] == pytest.approx(-0.00519977, abs=1e-8)
    assert all(math.isnan(v) for v in record.mag)
    assert record.matrix == tuple(f32(w) for w in (
        'BE1A8A77', 'BD563B92', 'BF7CB69F', '3F047BEA', 'BF5AE19E', 'BD0A8482',
        'BF579E51', 'BF0416F6', '3E1FD9B7'))
    assert record.matrix[2] == pytest.approx(-0.987162, abs=1e-6)
    assert record.timer == 397_001_865  # 0x17A9C489


def test_fixture_data_packet_decodes():
    """Decoding the golden data packet gives its address, link bytes and every field."""
    packet = decode_data_packet(FIXTURE_DATA_PACKET)
    assert (packet.address, packet.lqi, packet.rssi) == (ADDRESS, 200, 90)
    _check_fixture_record(packet.record)
    _check_fixture_record(decode_wired_record(FIXTURE_WIRED))
    _check_fixture_record(decode_record(FIXTURE_RECORD))


def test_fixture_data_packet_through_parsers():
    """The stream parser, wireless and wired, decodes the golden frames the same way."""
    parser = SensorStreamParser(address=ADDRESS)
    events = parser.feed(FIXTURE_DATA_PACKET)
    assert len(events) == 1 and isinstance(events[0], DataPacket)
    assert (events[0].address, events[0].lqi, events[0].rssi) == (ADDRESS, 200, 90)
    _check_fixture_record(events[0].record)
    wired = SensorStreamParser(wireless=False)
    events = wired.feed(FIXTURE_WIRED)
    assert len(events) == 1
    assert (events[0].address, events[0].lqi, events[0].rssi) == (None, None, None)
    _check_fixture_record(events[0].record)


def test_lqi_rssi_are_outside_the_checksum():
    """docs/protocol.md §3: the data packet checksum skips LQI and RSSI, but covers the record."""
    relinked = FIXTURE_DATA_PACKET[:-4] + h('00 FF') + FIXTURE_DATA_PACKET[-2:]
    packet = decode_data_packet(relinked)
    assert (packet.lqi, packet.rssi) == (0, 255)
    damaged = bytearray(FIXTURE_DATA_PACKET)
    damaged[10] ^= 0x01
    with pytest.raises(ChecksumError):
        decode_data_packet(bytes(damaged))


def test_wired_c2_reply():
    """A hand-made wired 0xC2 reply decodes to its fields and encodes back byte for byte."""
    assert len(C2_WIRED) == 31 == layout_of(0xC2).wired_size
    record = decode_wired_record(C2_WIRED)
    assert record == C2_EXPECTED
    assert record.timer / records.TICKS_PER_SECOND == 1.0
    assert encode_wired_record(encode_record(C2_EXPECTED)) == C2_WIRED


def test_wireless_c2_reply():
    """The manual's packetized 0xC2 reply: length byte 0x1E, echo 0xC2 (not 0xC1)."""
    assert encode_data_packet(ADDRESS, C2_RECORD, 0x40, 0x20) == C2_DATA_PACKET
    assert decode_data_packet(C2_DATA_PACKET) == packet_of(ADDRESS, C2_EXPECTED, 0x40, 0x20)
    assert C2_DATA_PACKET[5] == 0x1E and C2_DATA_PACKET[7] == 0xC2


def test_other_wired_replies():
    """EEPROM word, firmware version and continuous-mode replies decode to their fields."""
    assert decode_wired_record(EEPROM_WORD_WIRED) == records.EepromWord(512)
    firmware = decode_wired_record(FIRMWARE_WIRED)
    assert firmware == records.FirmwareVersion(2103)
    assert firmware.text == '2.1.03'
    assert decode_wired_record(CONTINUOUS_REPLY_WIRED) == records.ContinuousModeReply(0xCC, 0)
    for golden in (EEPROM_WORD_WIRED, FIRMWARE_WIRED, CONTINUOUS_REPLY_WIRED):
        assert encode_wired_record(encode_record(decode_wired_record(golden))) == golden


def test_ack_then_reply_as_the_manual_shows():
    """Host polls 0xC2; the base station ACKs with AA, then the sensor's packet follows."""
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(h('AA') + C2_DATA_PACKET) == [
        Ack(), packet_of(ADDRESS, C2_EXPECTED, 0x40, 0x20)]
    assert parser.feed(h('21')) == [Nack()]
    assert (parser.stats.acks, parser.stats.nacks, parser.stats.good_frames) == (1, 1, 1)


def test_base_station_ping():
    """Ping of node 95: 02 00 5F unframed; the answer 02 is link OK, 21 is not OK."""
    assert commands.ping(ADDRESS) == PING_95
    assert decode_command(PING_95) == Command(0x02, (ADDRESS,))
    assert CommandStreamParser().feed(PING_95) == [RawCommand(PING_95)]
    parser = SensorStreamParser(address=ADDRESS)
    parser.expect_ping()
    assert parser.feed(h('02')) == [records.PingReply(True)]
    parser.expect_ping()
    assert parser.feed(h('21')) == [records.PingReply(False)]
    assert parser.stats.nacks == 0


def test_temperature_formula():
    """°C = (code * 3.3 / 4096 - 0.5) * 100: code 1024 is 32.5 °C, 0 is -50, 4096 is 280."""
    temperatures = records.Temperatures(1024, (0, 4096, 1024), 0)
    assert temperatures.accel_celsius == pytest.approx(32.5)
    assert [records.code_to_celsius(code) for code in temperatures.gyro_codes] \
        == pytest.approx([-50.0, 280.0, 32.5])
