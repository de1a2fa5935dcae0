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
The incremental stream parsers: chunking, resynchronisation, counters, ACK/NACK.

Property-based tests (hypothesis) build byte streams from a fixed pool of
records (random but reproducible, so shrinking is fast) and check what the
host-side ``SensorStreamParser`` and the sensor-side ``CommandStreamParser``
make of them, however the bytes are cut into chunks and whatever garbage or
bit flips are added; hand-made streams check every counter exactly.
"""

import random
import struct

from hypothesis import given, HealthCheck, settings, strategies as st
from i3dmgx2_driver.codec import (
    Ack, CommandPacket, CommandStreamParser, DataPacket, encode_command_packet,
    encode_data_packet, encode_record, encode_wired_record, Nack, RawCommand, RejectedPacket,
    SensorStreamParser,
)
from i3dmgx2_driver.codec import commands, records
from i3dmgx2_driver.codec.layouts import LAYOUTS, RECORD_SIZES
from i3dmgx2_driver.codec.parser import MAX_FRAME_SIZE
from packets import packet_of
import pytest

CI = settings(max_examples=200, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

ADDRESS = 95
FOREIGN = (96, 0x5F00)
MAX_WIRED_SIZE = max(RECORD_SIZES.values()) + 2


# ---------------------------------------------------------------- the pool

def _random_record(rng, code):
    """Make a record of ``code`` with random float32-exact and integer fields."""
    layout = LAYOUTS[code]

    def element(field_code):
        if field_code == 'f':
            # Any bit pattern but NaN and infinity (exponent all ones), so that every
            # byte value turns up inside records, 0xAA, 0x21 and 0x07 included.
            word = rng.randrange(1 << 32)
            if (word >> 23) & 0xFF == 0xFF:
                word ^= 1 << 30
            return struct.unpack('>f', word.to_bytes(4, 'big'))[0]
        if field_code == '16s':
            return ''.join(rng.choice('0123456789ABCDEF -') for _ in range(16))
        return rng.randrange({'B': 1 << 8, 'H': 1 << 16, 'I': 1 << 32}[field_code])

    values = []
    for field in layout.reply:
        if field.count == 1:
            values.append(element(field.code))
        else:
            values.append(tuple(element(field.code) for _ in range(field.count)))
    return layout.record_type(*values)


_RNG = random.Random(3_000_000_002)
#: Three records of every type, fixed once: the streams are built from these.
POOL = [encode_record(_random_record(_RNG, code)) for code in sorted(RECORD_SIZES)
        for _ in range(3)]


def _random_command(rng, code):
    layout = LAYOUTS[code]
    args = []
    for field in layout.request:
        if field.code == 'f':
            args.append(tuple(float(rng.randrange(-64, 64)) / 8 for _ in range(field.count)))
        else:
            args.append(rng.randrange({'B': 1 << 8, 'H': 1 << 16}[field.code]))
    return commands.encode_command(code, *args)


#: Two commands of every type, as the host sends them.
COMMAND_POOL = [_random_command(_RNG, code) for code in sorted(LAYOUTS) for _ in range(2)]


def key(event):
    """Return a comparable form of an event: records by their bytes, so NaN is equal."""
    if isinstance(event, DataPacket):
        return ('data', event.address, encode_record(event.record), event.lqi, event.rssi)
    return (type(event).__name__, *event)


def data_keys(events):
    """Keys of the DataPacket events only."""
    return [key(e) for e in events if isinstance(e, DataPacket)]


def flip_bit(frame, bit):
    """Flip bit number ``bit`` (modulo the frame's size) of a bytearray; return it."""
    bit %= 8 * len(frame)
    frame[bit // 8] ^= 1 << (bit % 8)
    return bit


def feed_chunks(parser, stream, cuts):
    """Feed ``stream`` cut at ``cuts``; check the buffer bound after every feed."""
    events = []
    start = 0
    for cut in [*sorted(set(cuts)), len(stream)]:
        events += parser.feed(stream[start:cut])
        assert parser.pending < MAX_FRAME_SIZE
        start = cut
    return events


def test_pool_is_adversarial():
    """The pool's record bytes contain the bytes that confuse a resynchronising reader."""
    joined = b''.join(POOL)
    for byte in (0xAA, 0x21, 0x02, 0x07, 0x00):
        assert joined.count(bytes((byte,))) >= 3, hex(byte)
    assert {record[0] for record in POOL} == set(RECORD_SIZES)


def test_ack_and_nack_events_differ():
    """An Ack never equals a Nack (they compare by value, like every event)."""
    assert Ack() != Nack()
    assert Ack() == Ack() and Nack() == Nack()
    assert [Ack()] != [Nack()]
    assert Ack() != records.PingReply(True) and Nack() != records.PingReply(False)


# ---------------------------------------------------------------- strategies

packet_spec = st.tuples(
    st.integers(0, len(POOL) - 1),
    st.sampled_from([ADDRESS, ADDRESS, ADDRESS, *FOREIGN]),
    st.integers(0, 255),
    st.integers(0, 255))
cuts_strategy = st.lists(st.integers(0, 4000), max_size=12)


def _packet(spec, wireless):
    index, address, lqi, rssi = spec
    if wireless:
        return encode_data_packet(address, POOL[index], lqi, rssi)
    return encode_wired_record(POOL[index])


def _expected_key(spec, wireless):
    index, address, lqi, rssi = spec
    if wireless:
        return ('data', address, POOL[index], lqi, rssi)
    return ('data', None, POOL[index], None, None)


# ---------------------------------------------------------------- clean streams

@CI
@given(items=st.lists(st.one_of(packet_spec, st.just('ack'), st.just('nack')), max_size=15),
       cuts=cuts_strategy)
def test_clean_wireless_stream_gives_exactly_what_was_sent(items, cuts):
    """Packets, ACKs and NACKs, any chunking: exactly the sent events, exact counters."""
    stream = b''
    expected = []
    counts = {'good': 0, 'foreign': 0, 'ack': 0, 'nack': 0}
    for item in items:
        if item == 'ack':
            stream += b'\xaa'
            expected.append(key(Ack()))
            counts['ack'] += 1
        elif item == 'nack':
            stream += b'\x21'
            expected.append(key(Nack()))
            counts['nack'] += 1
        else:
            stream += _packet(item, True)
            if item[1] == ADDRESS:
                expected.append(_expected_key(item, True))
                counts['good'] += 1
            else:
                counts['foreign'] += 1
    parser = SensorStreamParser(address=ADDRESS)
    events = feed_chunks(parser, stream, cuts)
    events += parser.idle()  # a trailing ACK is held back until the line is quiet
    assert [key(e) for e in events] == expected
    stats = parser.stats
    assert (stats.good_frames, stats.foreign_frames, stats.acks, stats.nacks) == (
        counts['good'], counts['foreign'], counts['ack'], counts['nack'])
    assert (stats.checksum_failures, stats.length_failures, stats.bytes_skipped) == (0, 0, 0)
    assert stats.bytes_in == len(stream)
    assert parser.pending == 0


@CI
@given(items=st.lists(packet_spec, max_size=15), cuts=cuts_strategy)
def test_clean_wired_stream_gives_exactly_what_was_sent(items, cuts):
    """Wired records back to back, any chunking: exactly the sent records."""
    stream = b''.join(_packet(item, False) for item in items)
    parser = SensorStreamParser(wireless=False)
    events = feed_chunks(parser, stream, cuts)
    assert [key(e) for e in events] == [_expected_key(item, False) for item in items]
    assert parser.stats.good_frames == len(items)
    assert (parser.stats.checksum_failures, parser.stats.bytes_skipped) == (0, 0)
    assert parser.idle() == [] and parser.pending == 0


# ---------------------------------------------------------------- chunking

noisy_item = st.one_of(
    st.tuples(st.just('packet'), packet_spec, st.none()),
    st.tuples(st.just('flipped'), packet_spec, st.integers(0, 8 * 88 - 1)),
    st.tuples(st.just('garbage'), st.binary(max_size=40), st.none()),
    st.tuples(st.just('byte'), st.sampled_from([b'\xaa', b'\x21', b'\x02', b'\xaa\x07']),
              st.none()),
)


def _noisy_stream(items, wireless):
    stream = bytearray()
    for kind, value, flip in items:
        if kind in ('packet', 'flipped'):
            frame = bytearray(_packet(value, wireless))
            if flip is not None:
                flip_bit(frame, flip)
            stream += frame
        else:
            stream += value
    return bytes(stream)


def _twin_parsers(address: int | None, wireless: bool,
                  ping: bool) -> tuple[SensorStreamParser, SensorStreamParser]:
    """Return two parsers alike, one to be fed whole and one in chunks."""
    twins = (SensorStreamParser(address=address, wireless=wireless),
             SensorStreamParser(address=address, wireless=wireless))
    if ping:
        for parser in twins:
            parser.expect_ping()
    return twins


@CI
@given(items=st.lists(noisy_item, max_size=12), cuts=cuts_strategy, wireless=st.booleans(),
       address=st.sampled_from([None, ADDRESS]), ping=st.booleans())
def test_any_chunking_gives_the_same_events(items, cuts, wireless, address, ping):
    """Fed whole or in any chunks, a noisy stream gives the same events and counters."""
    stream = _noisy_stream(items, wireless)
    whole, chunked = _twin_parsers(address, wireless, ping)
    events_whole = whole.feed(stream)
    assert whole.pending < MAX_FRAME_SIZE
    events_chunked = feed_chunks(chunked, stream, cuts)
    assert [key(e) for e in events_chunked] == [key(e) for e in events_whole]
    assert chunked.stats.as_dict() == whole.stats.as_dict()
    assert chunked.pending == whole.pending
    assert [key(e) for e in chunked.idle()] == [key(e) for e in whole.idle()]


@CI
@given(items=st.lists(noisy_item, max_size=12), address=st.sampled_from([None, ADDRESS]),
       ping=st.booleans())
def test_a_packet_read_alone_gives_what_the_stream_read_whole_gives(items, address, ping):
    """
    Each item its own read, as the reader's whole-packet waits bring them (device/link.py).

    A sound packet of the node alone in a read takes the parser's shortcut
    (``_one_packet``); a flipped one, another node's, or a piece of garbage
    must still be counted as the general path counts them.
    """
    whole, alone = _twin_parsers(address, True, ping)
    events_whole = whole.feed(_noisy_stream(items, True))
    events_alone = [event for item in items for event in alone.feed(_noisy_stream([item], True))]
    assert [key(e) for e in events_alone] == [key(e) for e in events_whole]
    assert alone.stats.as_dict() == whole.stats.as_dict()
    assert alone.pending == whole.pending


@CI
@given(data=st.binary(max_size=1500), cuts=cuts_strategy, wireless=st.booleans(),
       ping=st.booleans())
def test_random_bytes_never_raise(data, cuts, wireless, ping):
    """Arbitrary bytes never raise, chunking does not matter, the buffer stays bounded."""
    whole, chunked = _twin_parsers(ADDRESS, wireless, ping)
    events = whole.feed(data)
    assert [key(e) for e in feed_chunks(chunked, data, cuts)] == [key(e) for e in events]
    assert whole.stats.bytes_in == len(data)
    assert whole.pending < MAX_FRAME_SIZE


fragments = st.one_of(
    st.binary(max_size=120),
    st.sampled_from([b'\xaa', b'\xaa\x07', b'\xaa\x07\x00\x00\x5f\x4e\x00\xcc',
                     b'\xaa\x07\x00\x00\x5f\x13\x00\xea', b'\xcc', b'\xc2', b'\xea']),
    st.tuples(st.integers(0, len(POOL) - 1), st.integers(0, 90), st.booleans()).map(
        lambda t: (encode_data_packet(ADDRESS, POOL[t[0]], 1, 2) if t[2]
                   else encode_wired_record(POOL[t[0]]))[:t[1]]),
)


@CI
@given(chunks=st.lists(fragments, max_size=40), wireless=st.booleans())
def test_buffer_stays_bounded(chunks, wireless):
    """Whatever arrives, the parser never holds back a whole frame's worth of bytes."""
    parser = SensorStreamParser(wireless=wireless)
    for chunk in chunks:
        parser.feed(chunk)
        assert parser.pending < MAX_FRAME_SIZE
        if not wireless:
            assert parser.pending < MAX_WIRED_SIZE


# ---------------------------------------------------------------- corruption

corrupt_item = st.tuples(
    packet_spec,
    st.one_of(st.none(), st.none(), st.integers(0, 8 * 88 - 1)),  # at most one bit flip
    st.one_of(st.just(b''), st.just(b''), st.binary(max_size=30)))  # garbage before it


@CI
@given(items=st.lists(corrupt_item, min_size=1, max_size=12), cuts=cuts_strategy)
def test_wireless_garbage_and_bit_flips(items, cuts):
    """
    Garbage and single bit flips never raise and never produce a record not sent.

    Exactly the intact packets come out, in order, plus those whose flip hit the LQI or
    RSSI byte: docs/protocol.md §3 leaves those two out of the checksum, so such a packet is
    accepted with the flipped link byte and its record intact. Every other single flip
    is caught (header, length, or the 16-bit sum, which any one-bit change alters).
    """
    stream = bytearray()
    expected = []
    for spec, flip, garbage in items:
        stream += garbage
        frame = bytearray(_packet(spec, True))
        position = None if flip is None else flip_bit(frame, flip)
        stream += frame
        link_only = position is not None and position // 8 in (len(frame) - 4, len(frame) - 3)
        if spec[1] == ADDRESS and (flip is None or link_only):
            index, address, _, _ = spec
            expected.append(('data', address, POOL[index], frame[-4], frame[-3]))
    stream += bytes(MAX_FRAME_SIZE)  # zeros: lets any half-checked candidate resolve
    parser = SensorStreamParser(address=ADDRESS)
    events = feed_chunks(parser, bytes(stream), cuts)
    assert data_keys(events) == expected
    assert parser.stats.good_frames == len(expected)


@settings(CI, derandomize=True)
@given(items=st.lists(corrupt_item, min_size=1, max_size=12), cuts=cuts_strategy)
def test_wired_garbage_and_bit_flips(items, cuts):
    """
    Wired: garbage and bit flips never raise, and every intact record comes out, in order.

    A wired record has no start byte, only a 16-bit sum, so after a corruption the parser
    tries a frame at every byte that is an echo code; one such try in some 35,000 passes
    the sum by chance (measured on this pool's kind of data). So this property does not
    claim that only sent records come out, and it runs derandomized, on a fixed set of
    examples, to stay reproducible.
    """
    stream = bytearray()
    intact = []
    for spec, flip, garbage in items:
        stream += garbage
        frame = bytearray(_packet(spec, False))
        if flip is not None:
            flip_bit(frame, flip)
        else:
            intact.append(_expected_key(spec, False))
        stream += frame
    stream += bytes(MAX_WIRED_SIZE)
    parser = SensorStreamParser(wireless=False)
    got = data_keys(feed_chunks(parser, bytes(stream), cuts))
    remaining = iter(got)
    assert all(any(k == g for g in remaining) for k in intact), (intact, got)


def test_single_bit_flips_in_a_wired_record_are_all_caught():
    """Every one-bit error in a wired record is rejected and the next record still comes."""
    first, second = POOL[0], POOL[-1]
    wired = encode_wired_record(first)
    for position in range(len(wired) * 8):
        bad = bytearray(wired)
        bad[position // 8] ^= 1 << (position % 8)
        parser = SensorStreamParser(wireless=False)
        events = parser.feed(bytes(bad) + encode_wired_record(second) + bytes(MAX_WIRED_SIZE))
        assert data_keys(events) == [('data', None, second, None, None)], position


@CI
@given(spec=packet_spec, length=st.integers(0, 255),
       following=st.lists(packet_spec, min_size=1, max_size=3))
def test_corrupted_length_byte_does_not_swallow_the_next_frames(spec, length, following):
    """Whatever a packet's length byte is changed to, the good packets after it come out."""
    frame = bytearray(encode_data_packet(ADDRESS, POOL[spec[0]], spec[2], spec[3]))
    if frame[5] == length:
        length ^= 0x80
    frame[5] = length
    good = [(index, ADDRESS, lqi, rssi) for index, _, lqi, rssi in following]
    stream = bytes(frame) + b''.join(_packet(g, True) for g in good)
    parser = SensorStreamParser(address=ADDRESS)
    events = parser.feed(stream + bytes(MAX_FRAME_SIZE))
    assert data_keys(events) == [_expected_key(g, True) for g in good]
    assert parser.stats.length_failures >= 1


def test_length_claiming_a_longer_record_does_not_swallow():
    """A short packet whose echo and length were both changed to 0xCC's waits, fails, resyncs."""
    short = bytearray(encode_data_packet(ADDRESS, encode_record(records.EepromWord(7)), 1, 2))
    short[5], short[7] = 78, 0xCC  # now claims a 77-byte 0xCC record: 88 bytes in all
    cc = next(record for record in POOL if record[0] == 0xCC)
    good = [encode_data_packet(ADDRESS, cc, 3, 4),
            encode_data_packet(ADDRESS, encode_record(records.EepromWord(8)), 5, 6)]
    parser = SensorStreamParser(address=ADDRESS)
    events = parser.feed(bytes(short) + b''.join(good))
    assert [key(e) for e in events] == [
        ('data', ADDRESS, cc, 3, 4), ('data', ADDRESS, bytes.fromhex('E50008'), 5, 6)]
    assert parser.stats.checksum_failures == 1
    assert parser.stats.good_frames == 2


# ---------------------------------------------------------------- ACK and NACK

E5_PACKET = bytes.fromhex('AA 07 00 00 5F 04 00 E5 02 00 10 20 01 51')  # word 0x0200
E5_EVENT = packet_of(ADDRESS, records.EepromWord(0x0200), 0x10, 0x20)


def test_hand_made_packet_sum():
    """E5_PACKET's sum: 07 + 5F + 04 + E5 + 02 = 7 + 95 + 4 + 229 + 2 = 337 = 0x0151."""
    assert sum(E5_PACKET[1:10]) == 0x0151 == int.from_bytes(E5_PACKET[-2:], 'big')


def test_ack_immediately_followed_by_a_data_packet():
    """AA AA 07 ...: the first 0xAA is an ACK because a packet's SOP is followed by 0x07."""
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(b'\xaa' + E5_PACKET) == [Ack(), E5_EVENT]
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(b'\xaa') == []
    assert parser.pending == 1
    assert parser.feed(E5_PACKET) == [Ack(), E5_EVENT]
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(b'\xaa\xaa') == [Ack()]
    assert parser.feed(b'\x07' + E5_PACKET[2:]) == [E5_EVENT]
    assert parser.stats.acks == 1 and parser.stats.good_frames == 1


def test_idle_resolves_a_trailing_lone_ack():
    """A lone trailing 0xAA waits for its next byte until idle() says the line is quiet."""
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(E5_PACKET + b'\xaa') == [E5_EVENT]
    assert parser.pending == 1
    assert parser.idle() == [Ack()]
    assert parser.pending == 0 and parser.stats.acks == 1
    assert parser.idle() == []
    assert parser.feed(b'\xaa\xaa') == [Ack()]
    assert parser.idle() == [Ack()]
    assert parser.stats.acks == 3


def test_idle_leaves_partial_packets_alone():
    """idle() never drops or misreads the start of a packet, nor acts in wired mode."""
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(E5_PACKET[:5]) == []
    assert parser.idle() == []
    assert parser.pending == 5
    assert parser.feed(E5_PACKET[5:]) == [E5_EVENT]
    wired = SensorStreamParser(wireless=False)
    assert wired.feed(b'\xaa') == [] and wired.idle() == []
    assert wired.stats.acks == 0 and wired.stats.bytes_skipped == 1


def test_nack_recognition():
    """0x21 at a frame boundary is a NACK in wireless mode, and garbage in wired mode."""
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(b'\x21' + E5_PACKET + b'\x21\xaa\x21') == [
        Nack(), E5_EVENT, Nack(), Ack(), Nack()]
    assert (parser.stats.nacks, parser.stats.acks) == (3, 1)
    wired = SensorStreamParser(wireless=False)
    assert wired.feed(b'\x21') == []
    assert wired.stats.nacks == 0 and wired.stats.bytes_skipped == 1


def test_foreign_frames_are_counted_and_dropped():
    """With an address, packets from other nodes are counted, not returned."""
    record = encode_record(records.EepromWord(0x0200))
    stream = (encode_data_packet(96, record, 0, 0) + E5_PACKET
              + encode_data_packet(0x5F00, record, 0, 0) + encode_data_packet(1, record, 0, 0))
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(stream) == [E5_EVENT]
    assert (parser.stats.good_frames, parser.stats.foreign_frames) == (1, 3)
    assert parser.stats.bytes_skipped == 0
    anyone = SensorStreamParser()
    assert [e.address for e in anyone.feed(stream)] == [96, ADDRESS, 0x5F00, 1]
    assert anyone.stats.foreign_frames == 0


def test_counters_on_a_hand_made_wireless_stream():
    """Each kind of fault lands in its counter, and bytes_skipped counts every lost byte."""
    bad_sum = E5_PACKET[:-1] + b'\x52'
    bad_length = E5_PACKET[:5] + b'\x05' + E5_PACKET[6:]
    foreign = bytes.fromhex('AA 07 00 00 60 04 00 E5 02 00 10 20 01 52')
    stream = (E5_PACKET            # good
              + b'\x00\x01\x02'    # 3 garbage bytes, skipped up to the next 0xAA
              + bad_sum            # 1 byte at its SOP, then 13 up to the next 0xAA
              + bad_length         # same: 14 bytes
              + foreign            # a good packet from node 0x0060
              + b'\xaa'            # ACK (followed by 0xAA, not 0x07)
              + E5_PACKET          # good
              + b'\x21'            # NACK
              + b'\xaa')           # trailing ACK, resolved by idle()
    parser = SensorStreamParser(address=ADDRESS)
    events = parser.feed(stream) + parser.idle()
    assert events == [E5_EVENT, Ack(), E5_EVENT, Nack(), Ack()]
    assert parser.stats.as_dict() == {
        'good_frames': 2, 'checksum_failures': 1, 'length_failures': 1,
        'bytes_skipped': 3 + 14 + 14, 'foreign_frames': 1, 'acks': 2, 'nacks': 1,
        'bytes_in': len(stream)}
    assert len(stream) == 5 * 14 + 3 + 3


def test_counters_on_a_hand_made_wired_stream():
    """Wired: garbage and a bad sum are skipped byte by byte; a partial record waits."""
    c2 = encode_wired_record(encode_record(records.AccelAngRate(
        (0.0, 0.0, -1.0), (0.25, -0.125, 0.5), 19_660_800)))
    stream = (bytes.fromhex('E5 02 00 00 E7')            # good EEPROM word
              + b'\x00\x01\x02'                          # 3 bytes of garbage
              + bytes.fromhex('E5 02 00 00 E8')          # bad sum: 5 bytes skipped
              + bytes.fromhex('E9 00 00 08 37 01 28')    # good firmware version
              + b'\x21'                                  # not a NACK when wired: skipped
              + c2[:10])                                 # first 10 bytes of a 0xC2 reply
    parser = SensorStreamParser(wireless=False)
    events = parser.feed(stream)
    assert events == [packet_of(None, records.EepromWord(512), None, None),
                      packet_of(None, records.FirmwareVersion(2103), None, None)]
    assert parser.stats.as_dict() == {
        'good_frames': 2, 'checksum_failures': 1, 'length_failures': 0,
        'bytes_skipped': 3 + 5 + 1, 'foreign_frames': 0, 'acks': 0, 'nacks': 0,
        'bytes_in': 31}
    assert parser.pending == 10
    assert parser.idle() == []
    assert [e.record.timer for e in parser.feed(c2[10:])] == [19_660_800]
    assert parser.pending == 0


def test_reset_drops_a_partial_frame_and_the_ping_expectation():
    """reset() counts the held-back bytes as skipped and forgets the pending ping."""
    parser = SensorStreamParser(address=ADDRESS)
    parser.expect_ping()
    assert parser.feed(E5_PACKET[:9]) == []
    parser.reset()
    assert parser.pending == 0
    assert parser.stats.bytes_skipped == 9
    assert parser.feed(b'\x02') == []  # no ping expected any more: garbage
    assert parser.stats.bytes_skipped == 10
    assert parser.feed(E5_PACKET) == [E5_EVENT]


# ---------------------------------------------------------------- ping

def test_ping_reply_needs_expect_ping():
    """0x02 is a ping reply only when one is expected; 0x21 then means 'not OK', not NACK."""
    parser = SensorStreamParser(address=ADDRESS)
    assert parser.feed(b'\x02') == []
    assert parser.stats.bytes_skipped == 1
    parser.expect_ping()
    assert parser.feed(b'\x02') == [records.PingReply(True)]
    assert parser.feed(b'\x02') == []  # one reply per expect_ping()
    parser.expect_ping()
    assert parser.feed(b'\x21') == [records.PingReply(False)]
    assert parser.stats.nacks == 0
    assert parser.feed(b'\x21') == [Nack()]


def test_ping_reply_between_packets():
    """A ping reply among streamed packets comes out in its place."""
    parser = SensorStreamParser(address=ADDRESS)
    parser.expect_ping()
    assert parser.feed(E5_PACKET + b'\x02' + E5_PACKET) == [
        E5_EVENT, records.PingReply(True), E5_EVENT]
    wired = SensorStreamParser(wireless=False)
    wired.expect_ping()
    assert wired.feed(bytes.fromhex('E5 02 00 00 E7 02')) == [
        packet_of(None, records.EepromWord(512), None, None), records.PingReply(True)]


# ---------------------------------------------------------------- the sensor side

def _command_packet(index, address=ADDRESS):
    return encode_command_packet(address, COMMAND_POOL[index])


def test_command_parser_reads_commands_and_pings():
    """Command packets for any node and unframed pings come out in order, chunked or not."""
    stream = b''.join(_command_packet(i, 1 + i) for i in range(len(COMMAND_POOL)))
    stream += commands.ping(ADDRESS) + _command_packet(0)
    expected = [CommandPacket(1 + i, c) for i, c in enumerate(COMMAND_POOL)]
    expected += [RawCommand(commands.ping(ADDRESS)), CommandPacket(ADDRESS, COMMAND_POOL[0])]
    assert CommandStreamParser().feed(stream) == expected
    parser = CommandStreamParser()
    assert [e for b in stream for e in parser.feed(bytes((b,)))] == expected
    assert parser.stats.good_frames == len(expected)
    assert parser.stats.bytes_skipped == 0


def test_command_parser_bad_checksum_is_rejected_once_and_the_retry_kept():
    """A packet with a bad sum is one rejection; the retry right behind it is kept."""
    good = encode_command_packet(ADDRESS, commands.read_eeprom(0xFCA2))  # sum 02 F2
    bad = good[:-1] + b'\xf3'
    parser = CommandStreamParser()
    assert parser.feed(bad + good) == [RejectedPacket('bad checksum'),
                                       CommandPacket(ADDRESS, commands.read_eeprom(0xFCA2))]
    assert parser.stats.checksum_failures == 1
    assert parser.stats.bytes_skipped == len(bad)
    # The stop, sent three times as docs/protocol.md §4 advises, the first one damaged.
    stop = encode_command_packet(ADDRESS, commands.stop_continuous())
    parser = CommandStreamParser()
    assert parser.feed(stop[:-1] + b'\x00' + stop + stop) == [
        RejectedPacket('bad checksum'), CommandPacket(ADDRESS, b'\xfa'),
        CommandPacket(ADDRESS, b'\xfa')]


def test_command_parser_bad_header_or_length_is_rejected():
    """A wrong length byte, flags byte or unknown command is one rejection; the next is kept."""
    good = encode_command_packet(ADDRESS, commands.set_continuous(0xCC))
    for index, value in ((5, 0x02), (5, 0x06), (5, 0xFF), (1, 0x07), (2, 0x01), (6, 0x01),
                         (7, 0xC5), (7, 0x00)):
        bad = bytearray(good)
        bad[index] = value
        parser = CommandStreamParser()
        events = parser.feed(bytes(bad) + good)
        assert events == [RejectedPacket('bad header or length'),
                          CommandPacket(ADDRESS, commands.set_continuous(0xCC))], (index, value)
        assert parser.stats.length_failures >= 1


def test_command_parser_takes_a_ping_after_a_rejected_packet():
    """Past the end of a rejected packet, an unframed ping is recognised again."""
    stop = encode_command_packet(ADDRESS, commands.stop_continuous())
    parser = CommandStreamParser()
    assert parser.feed(stop[:-1] + b'\x00' + commands.ping(7)) == [
        RejectedPacket('bad checksum'), RawCommand(commands.ping(7))]


def test_wired_command_parser():
    """Wired: bare commands back to back; unknown bytes and wrong confirmations skipped."""
    stream = bytes.fromhex('C2 C4C129CC 00 E500FCA2 FA E501FCA2 E4C12900FCA20100 FB C1 29 04')
    parser = CommandStreamParser(wireless=False)
    events = parser.feed(stream)
    assert events == [RawCommand(bytes.fromhex(c)) for c in (
        'C2', 'C4C129CC', 'E500FCA2', 'FA', 'E4C12900FCA20100', 'FBC12904')]
    # Skipped: 00; E5 (wrong confirmation 01), 01, FC (no such command), A2.
    assert parser.stats.bytes_skipped == 5
    assert parser.stats.good_frames == 6


command_item = st.tuples(
    st.integers(0, len(COMMAND_POOL) - 1),
    st.one_of(st.none(), st.integers(8, 8 * 24 - 1)))  # a flip anywhere after the SOP


@CI
@given(items=st.lists(command_item, min_size=1, max_size=12), cuts=cuts_strategy)
def test_command_parser_bit_flips(items, cuts):
    """
    Bit flips after the start byte: every intact packet comes out, nothing false does.

    Each run of damaged packets between two good ones gives at least one and at most
    one-per-packet rejections, and never an unframed ping read out of a damaged packet.
    (A flip of the start byte itself turns the packet into loose bytes, which a base
    station cannot tell from a ping either; it is left out here.)
    """
    stream = bytearray()
    expected = []
    damaged_runs = [0]
    for index, flip in items:
        packet = bytearray(_command_packet(index))
        if flip is not None:
            flip_bit(packet, 8 + (flip - 8) % (8 * len(packet) - 8))
            damaged_runs[-1] += 1
        else:
            expected.append(CommandPacket(ADDRESS, COMMAND_POOL[index]))
            damaged_runs.append(0)
        stream += packet
    parser = CommandStreamParser()
    events = []
    start = 0
    for cut in [*sorted(set(cuts)), len(stream)]:
        events += parser.feed(bytes(stream[start:cut]))
        start = cut
    assert [e for e in events if isinstance(e, CommandPacket)] == expected
    assert not any(isinstance(e, RawCommand) for e in events)
    runs = [0]
    for event in events:
        if isinstance(event, CommandPacket):
            runs.append(0)
        else:
            assert isinstance(event, RejectedPacket)
            runs[-1] += 1
    # The last run may still be waiting for bytes; check the complete ones.
    for got, damaged in zip(runs[:-1], damaged_runs[:-1], strict=True):
        assert (got >= 1) == (damaged >= 1) and got <= damaged, (runs, damaged_runs)


@CI
@given(items=st.lists(st.one_of(
    st.tuples(st.just('packet'), st.integers(0, len(COMMAND_POOL) - 1), st.none()),
    st.tuples(st.just('flipped'), st.integers(0, len(COMMAND_POOL) - 1),
              st.integers(0, 8 * 24 - 1)),
    st.tuples(st.just('garbage'), st.binary(max_size=30), st.none()),
    st.tuples(st.just('ping'), st.integers(0, 0xFFFF), st.none())), max_size=12),
    cuts=cuts_strategy, wireless=st.booleans())
def test_command_parser_chunking(items, cuts, wireless):
    """Whatever the host sent, chunking does not change what the sensor side reads."""
    stream = bytearray()
    for kind, value, flip in items:
        if kind in ('packet', 'flipped'):
            frame = bytearray(_command_packet(value) if wireless else COMMAND_POOL[value])
            if flip is not None:
                flip_bit(frame, flip)
            stream += frame
        elif kind == 'ping':
            stream += commands.ping(max(value, 1))
        else:
            stream += value
    whole = CommandStreamParser(wireless=wireless)
    chunked = CommandStreamParser(wireless=wireless)
    events = whole.feed(bytes(stream))
    got = []
    start = 0
    for cut in [*sorted(set(cuts)), len(stream)]:
        got += chunked.feed(bytes(stream[start:cut]))
        start = cut
    assert got == events
    assert chunked.stats.as_dict() == whole.stats.as_dict()


@pytest.mark.parametrize('wireless', [True, False])
def test_command_parser_random_bytes_never_raise(wireless):
    """A megabyte of seeded random bytes goes through without an exception."""
    rng = random.Random(7)
    data = bytes(rng.randrange(256) for _ in range(1 << 20))
    parser = CommandStreamParser(wireless=wireless)
    for start in range(0, len(data), 4096):
        parser.feed(data[start:start + 4096])
    assert parser.stats.bytes_in == len(data)


def test_answer_bytes_inside_a_corrupted_packet_are_not_acks_or_nacks():
    """0xAA and 0x21 inside a packet that failed its checksum are its data."""
    record = bytearray(encode_record(records.EepromWord(0x21AA)))
    packet = bytearray(encode_data_packet(ADDRESS, bytes(record), 0x21, 0xAA))
    packet[-1] ^= 0x01  # the checksum no longer matches
    stream = bytes(packet) + E5_PACKET + b'\x21'
    for cut in range(1, len(stream)):
        parser = SensorStreamParser(address=ADDRESS)
        events = parser.feed(stream[:cut]) + parser.feed(stream[cut:])
        assert events == [E5_EVENT, Nack()], cut
        assert parser.stats.checksum_failures == 1
        assert parser.stats.acks == 0 and parser.stats.nacks == 1
        assert parser.stats.bytes_skipped == len(packet)
