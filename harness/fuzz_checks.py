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
The fuzzer's properties of the codec, checked on one input at a time.

Shared by the fuzzer (``benchmarks/fuzz_parser.py``, which feeds it inputs)
and the regression test (``test/test_fuzz_regressions.py``, which replays
the inputs kept in ``test/fixtures/fuzz/``). Every input goes through:

* ``SensorStreamParser``: wireless with no address filter and with one,
  wired, each fed in pseudo-random chunks, and once more with ``expect_ping``,
  ``idle`` and ``reset`` calls mixed in;
* ``CommandStreamParser``, wireless and wired;
* ``decode_record``, ``decode_data_packet``, ``decode_wired_record``,
  ``decode_command_packet`` and ``decode_command`` on the whole input and on
  slices starting at every 0xAA (and the start);
* the orientation functions on every record decoded, and the driver's
  ``SampleClock`` on their timers (read one every 10 ms).

Properties (:func:`check_input` raises ``PropertyViolation`` naming the one
broken): the one-shot decoders raise nothing but ``CodecError`` subclasses;
the stream parsers raise nothing at all; their buffer never holds more than
one frame; every ``DataPacket`` a parser emits re-encodes (framing and
checksum rebuilt from the record) to the very bytes found, with a valid
checksum, in the input at the position after the previous event; its
counters add up (bytes in = bytes held + frame bytes + ACK/NACK/ping bytes +
bytes skipped); the result does not depend on how the input was chunked;
the address filter only removes packets (counted as foreign); a quaternion
is unit-norm with w >= 0, or all NaN.

The codec is imported on first use (:func:`load_codec`), or bound by the
caller (:func:`bind`) after importing it under a coverage tool's
instrumentation.
"""

import hashlib
import math
import random

#: The address the filtered parser keeps.
ADDRESS = 95


class PropertyViolation(Exception):
    """An input broke a property; ``name`` says which, for the findings' file name."""

    def __init__(self, name: str, detail: str) -> None:
        super().__init__(f'{name}: {detail}')
        self.name = name


def load_codec():
    """Import the codec (under atheris' instrumentation when it is used)."""
    from i3dmgx2_driver.codec import commands, framing, orientation
    from i3dmgx2_driver.codec import parser as stream
    from i3dmgx2_driver.codec.errors import CodecError
    from i3dmgx2_driver.device import sample_clock
    return commands, framing, orientation, stream, sample_clock, CodecError


commands = framing = orientation = stream = sample_clock = CodecError = None


def bind(modules) -> None:
    """Use these codec modules (``load_codec()``'s) from now on."""
    global commands, framing, orientation, stream, sample_clock, CodecError
    commands, framing, orientation, stream, sample_clock, CodecError = modules


# -- reference encoders: built here from the protocol, not with the codec's encoders ------


def _sum16(data: bytes) -> int:
    return sum(data) & 0xFFFF


def wireless_frame(address: int, record: bytes, lqi: int, rssi: int) -> bytes:
    """Wrap record bytes in a data packet (any 16-bit address), as docs/protocol.md §3 says."""
    body = bytes((0xAA, 0x07, 0x00, address >> 8, address & 0xFF, len(record) + 1, 0x00))
    body += record
    return body + bytes((lqi, rssi)) + _sum16(body[1:]).to_bytes(2, 'big')


def wired_frame(record: bytes) -> bytes:
    """Append the 16-bit sum to record bytes: a wired reply."""
    return record + _sum16(record).to_bytes(2, 'big')


def command_frame(address: int, command: bytes) -> bytes:
    """Wrap command bytes in a command packet (any 16-bit address)."""
    body = bytes((0xAA, 0x0B, 0x00, address >> 8, address & 0xFF, len(command) + 1, 0x00))
    body += command
    return body + _sum16(body[1:]).to_bytes(2, 'big')


def same(a, b) -> bool:
    """Tell whether a and b are equal, taking NaN as equal to NaN, through tuples."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, tuple) and isinstance(b, tuple):
        return type(a) is type(b) and len(a) == len(b) and all(
            same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


# -- the properties ---------------------------------------------------------------------------


def chunks_of(data: bytes, seed: int) -> list[bytes]:
    """Split ``data`` into pseudo-random chunks of 1..40 bytes (some empty)."""
    rng = random.Random(seed)
    out = []
    i = 0
    while i < len(data):
        step = rng.choice((0, 1, 1, 2, 3, 7, 13, 40))
        out.append(data[i:i + step])
        i += step
    return out


def _frame_for(event, wireless: bool) -> bytes:
    record = commands.encode_record(event.record)
    if wireless:
        return wireless_frame(event.address, record, event.lqi, event.rssi)
    return wired_frame(record)


def _find_frame(data: bytes, start: int, limit: int, event, wireless: bool) -> int:
    """Where the frame of ``event`` sits in ``data[start:limit]``; -1 if nowhere."""
    from harness import decoders  # with the codec, after any instrumentation
    frame = _frame_for(event, wireless)
    at = data.find(frame, start, limit)
    if at >= 0:
        return at
    # A NaN's payload may not survive float32 -> float -> float32: then find the
    # frame by decoding instead, which must give the same record.
    size = len(frame)
    for at in range(start, limit - size + 1):
        piece = data[at:at + size]
        if piece[:1] != frame[:1]:
            continue
        try:
            if wireless:
                decoded = decoders.decode_data_packet(piece)
                link = (decoded.address == event.address and decoded.lqi == event.lqi
                        and decoded.rssi == event.rssi)
                record = decoded.record
            else:
                record = decoders.decode_wired_record(piece)
                link = True
        except CodecError:
            continue
        if link and same(record, event.record):
            return at
    return -1


def run_sensor_parser(data: bytes, chunks: list[bytes], wireless: bool,
                      address: int | None, pings: bool = False) -> tuple[list, dict]:
    """
    Feed ``chunks`` to a SensorStreamParser and check every property on the way.

    With ``pings``, ``expect_ping``, ``idle`` and (rarely) ``reset`` are called
    between chunks.
    Returns the events and the final counters.
    """
    parser = stream.SensorStreamParser(address=address, wireless=wireless)
    events = []
    fed = 0
    cursor = 0
    frame_bytes = lone = 0
    rng = random.Random(len(data))
    for chunk in chunks:
        if pings and rng.random() < 0.2:
            parser.expect_ping()
        if pings and rng.random() < 0.03:
            parser.reset()  # a reconnect: what was held is dropped (and counted as skipped)
            cursor = fed
        try:
            new = parser.feed(chunk)
            fed += len(chunk)
            if pings and rng.random() < 0.3:
                new += parser.idle()
        except Exception as exc:  # any exception is the finding
            raise PropertyViolation('sensor_parser_raised',
                                    f'{type(exc).__name__}: {exc}') from exc
        if parser.pending > stream.MAX_FRAME_SIZE:
            raise PropertyViolation('sensor_parser_buffer_unbounded',
                                    f'{parser.pending} bytes held')
        consumed = fed - parser.pending
        for event in new:
            if isinstance(event, framing.DataPacket):
                if not wireless and event.address is not None:
                    raise PropertyViolation('wired_packet_with_address', repr(event))
                if address is not None and event.address != address:
                    raise PropertyViolation('filtered_packet_passed', repr(event))
                at = _find_frame(data, cursor, consumed, event, wireless)
                if at < 0:
                    raise PropertyViolation(
                        'invalid_frame_accepted',
                        f'{event!r} is not a valid frame in the input after byte {cursor}')
                size = len(_frame_for(event, wireless))
                cursor = at + size
                frame_bytes += size
            else:
                lone += 1
                cursor += 1
        events += new
    stats = parser.stats.as_dict()
    if stats['bytes_in'] != fed:
        raise PropertyViolation('bytes_in_wrong', f'{stats["bytes_in"]} != {fed}')
    if stats['good_frames'] != sum(isinstance(e, framing.DataPacket) for e in events):
        raise PropertyViolation('good_frames_wrong', repr(stats))
    if stats['acks'] != sum(isinstance(e, stream.Ack) for e in events) \
            or stats['nacks'] != sum(isinstance(e, stream.Nack) for e in events):
        raise PropertyViolation('ack_nack_count_wrong', repr(stats))
    if address is None:
        accounted = parser.pending + frame_bytes + lone + stats['bytes_skipped']
        if accounted != fed or stats['foreign_frames']:
            raise PropertyViolation(
                'byte_accounting_wrong',
                f'held {parser.pending} + frames {frame_bytes} + one-byte events {lone} '
                f'+ skipped {stats["bytes_skipped"]} != fed {fed}; {stats}')
    return events, stats


def check_sensor_parsers(data: bytes, seed: int) -> list:
    """Run every SensorStreamParser configuration; return the records decoded."""
    records = []
    chunks = chunks_of(data, seed)
    for wireless in (True, False):
        whole, whole_stats = run_sensor_parser(data, [data], wireless, None)
        split, split_stats = run_sensor_parser(data, chunks, wireless, None)
        if not same(tuple(whole), tuple(split)) or whole_stats != split_stats:
            raise PropertyViolation(
                'chunking_changes_result',
                f'wireless={wireless}: whole {whole_stats} vs chunked {split_stats}')
        records += [e.record for e in whole if isinstance(e, framing.DataPacket)]
        run_sensor_parser(data, chunks, wireless, None, pings=True)
        if wireless:
            kept, kept_stats = run_sensor_parser(data, chunks, True, ADDRESS)
            wanted = [e for e in whole if not isinstance(e, framing.DataPacket)
                      or e.address == ADDRESS]
            foreign = sum(1 for e in whole if isinstance(e, framing.DataPacket)
                          and e.address != ADDRESS)
            if not same(tuple(kept), tuple(wanted)) or kept_stats['foreign_frames'] != foreign:
                raise PropertyViolation(
                    'address_filter_wrong',
                    f'{len(kept)} events kept of {len(whole)}, {kept_stats["foreign_frames"]} '
                    f'foreign counted, {foreign} expected')
    return records


def check_command_parsers(data: bytes, seed: int) -> None:
    """Run the CommandStreamParser both ways; check what it finds is in the input."""
    for wireless in (True, False):
        parser = stream.CommandStreamParser(wireless=wireless)
        fed = 0
        cursor = 0
        for chunk in chunks_of(data, seed + 1):
            try:
                events = parser.feed(chunk)
            except Exception as exc:  # any exception is the finding
                raise PropertyViolation('command_parser_raised',
                                        f'{type(exc).__name__}: {exc}') from exc
            fed += len(chunk)
            held = len(parser._buf)
            if held > framing.HEADER_SIZE + framing.MAX_COMMAND_SIZE + 2:
                raise PropertyViolation('command_parser_buffer_unbounded', f'{held} bytes')
            for event in events:
                if isinstance(event, framing.CommandPacket):
                    frame = command_frame(event.address, event.command)
                elif isinstance(event, stream.RawCommand):
                    frame = event.command
                    try:
                        commands.decode_command(frame)
                    except CodecError as exc:
                        raise PropertyViolation('raw_command_undecodable', repr(event)) \
                            from exc
                else:
                    continue
                at = data.find(frame, cursor, fed - held)
                if at < 0:
                    raise PropertyViolation('invalid_command_accepted',
                                            f'{event!r} not in the input after {cursor}')
                cursor = at + len(frame)


def _one_shot(name: str, function, piece: bytes):
    try:
        return function(piece)
    except CodecError:
        return None
    except Exception as exc:  # anything but a CodecError is the finding
        raise PropertyViolation(f'{name}_raised_{type(exc).__name__}',
                                f'{exc} on {piece[:16].hex()}...') from exc


def check_one_shot(data: bytes) -> list:
    """Run the one-shot decoders on the input and its slices; return what decoded."""
    from harness import decoders  # with the codec, after any instrumentation
    records = []
    codes = commands.LAYOUTS
    starts = {0, *[i for i, byte in enumerate(data) if byte == 0xAA][:16],
              *[i for i, byte in enumerate(data) if byte in codes][:16]}
    for start in sorted(starts):
        tail = data[start:]
        sizes = {len(tail), 1, 2, 3, 12, 88}
        layout = codes.get(tail[0]) if tail else None
        if layout is not None:
            sizes |= {layout.request_size, layout.record_size, layout.wired_size}
        for size in sorted(sizes):
            piece = tail[:size]
            records += [
                _one_shot('decode_record', commands.decode_record, piece),
                getattr(_one_shot('decode_data_packet', decoders.decode_data_packet, piece),
                        'record', None),
                _one_shot('decode_wired_record', decoders.decode_wired_record, piece)]
            _one_shot('decode_command_packet', decoders.decode_command_packet, piece)
            _one_shot('decode_command', commands.decode_command, piece)
        # Whatever length the frame's own length byte claims.
        if len(tail) >= 6:
            claimed = tail[:framing.HEADER_SIZE + tail[5] - 1 + framing.DATA_TRAILER_SIZE]
            packet = _one_shot('decode_data_packet', decoders.decode_data_packet, claimed)
            records.append(getattr(packet, 'record', None))
            claimed = tail[:framing.HEADER_SIZE + tail[5] - 1 + 2]
            _one_shot('decode_command_packet', decoders.decode_command_packet, claimed)
    return [record for record in records if record is not None]


def check_records(records: list) -> None:
    """Orientation functions and the driver's sample clock on decoded (garbage) records."""
    clock = sample_clock.SampleClock(offset=lambda: 0.0)
    last = None
    for index, record in enumerate(records):
        matrix = getattr(record, 'matrix', None)
        try:
            if matrix is not None:
                for convention in orientation.CONVENTIONS:
                    q = orientation.orientation(matrix, convention)
                    finite = all(math.isfinite(c) for c in q)
                    if finite:
                        norm = math.sqrt(sum(c * c for c in q))
                        if abs(norm - 1.0) > 1e-9 or q.w < 0.0:
                            raise PropertyViolation('quaternion_not_unit',
                                                    f'{q} from {matrix}')
                    elif not all(math.isnan(c) for c in q):
                        raise PropertyViolation('quaternion_partly_nan', f'{q} from {matrix}')
                orientation.euler_from_matrix(matrix)
                orientation.matrix_from_quaternion(orientation.shepperd(matrix))
            for name in ('accel', 'angular_rate', 'mag'):
                vector = getattr(record, name, None)
                if vector is not None:
                    for convention in orientation.CONVENTIONS:
                        orientation.body_vector(vector, convention)
            ticks = getattr(record, 'timer', None)
            if ticks is not None:
                clock.stamp(ticks, index * 0.01)
                if last is not None and not clock.restarted and clock.ticks < last:
                    raise PropertyViolation('timer_went_backwards', f'{last} -> {clock.ticks}')
                last = clock.ticks
        except PropertyViolation:
            raise
        except Exception as exc:  # any exception is the finding
            raise PropertyViolation(f'orientation_raised_{type(exc).__name__}',
                                    f'{exc} on {record!r}') from exc


def check_input(data: bytes) -> None:
    """Check every property on one input; raise PropertyViolation if one breaks."""
    if commands is None:
        bind(load_codec())
    seed = int.from_bytes(hashlib.blake2b(data, digest_size=4).digest(), 'big')
    records = check_sensor_parsers(data, seed)
    check_command_parsers(data, seed)
    records += check_one_shot(data)
    check_records(records)
