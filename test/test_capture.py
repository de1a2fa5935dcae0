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
The capture format: round trip, crash tolerance, threads, the fixture's timing.

And the node's raw capture: one that cannot write turns itself off with one
log line instead of taking the driver down.
"""

import itertools
import json
import os
import threading
import time
import warnings

from i3dmgx2_driver.capture.file_format import (
    CaptureFormatError, CaptureWriter, CHUNK_HEADER, MAGIC, read_capture, TruncatedCaptureWarning,
)
from i3dmgx2_driver.capture.fixtures import fixture_chunks, FIXTURE_GAP, load_fixture, record_timer
from i3dmgx2_driver.capture.raw_capture import RawCapture
from i3dmgx2_driver.codec import DataPacket, SensorStreamParser
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation, TICKS_PER_SECOND
import pytest


CHUNKS = [
    (1700000000.0, b'\xaa\x07\x00\x5f'),
    (1700000000.25, bytes(range(256))),
    (1700000000.5, b'\n\n\r\n GX2CAP 1\n'),  # bytes that look like text lines
    (1700000001.0, b'\x00' * 70000),
]


def _write(path, chunks=CHUNKS, header=None):
    with CaptureWriter(path, header or {'port': '/dev/ttyUSB0', 'address': 95}) as writer:
        for t, data in chunks:
            writer.write(data, t)
    return path


def _read_all(path):
    header, chunks = read_capture(path)
    return header, list(chunks)


def test_round_trip_keeps_bytes_times_and_header(tmp_path):
    path = _write(tmp_path / 'a.gx2cap', header={
        'port': '/dev/ttyUSB0', 'address': 95, 'notes': 'line one\nline two',
        'operator': {'name': 'ü', 'shift': 2}})
    header, chunks = _read_all(path)
    assert chunks == CHUNKS
    assert header['port'] == '/dev/ttyUSB0' and header['address'] == 95
    assert header['notes'] == 'line one\nline two'
    assert header['operator'] == {'name': 'ü', 'shift': 2}
    for key in ('baud', 'wireless', 'start_time', 'tool_version'):
        assert key in header
    assert header['baud'] == 115200 and header['wireless'] is True


def test_layout_is_magic_json_line_then_chunks(tmp_path):
    path = _write(tmp_path / 'a.gx2cap', chunks=CHUNKS[:1])
    raw = path.read_bytes()
    assert raw.startswith(MAGIC)
    line, rest = raw[len(MAGIC):].split(b'\n', 1)
    assert json.loads(line)['address'] == 95
    t, count = CHUNK_HEADER.unpack(rest[:CHUNK_HEADER.size])
    assert (t, count) == (CHUNKS[0][0], len(CHUNKS[0][1]))
    assert rest[CHUNK_HEADER.size:] == CHUNKS[0][1]


def test_empty_reads_are_not_stored_and_closed_writer_refuses(tmp_path):
    path = tmp_path / 'a.gx2cap'
    writer = CaptureWriter(path, {})
    writer.write(b'', 1.0)
    writer.write(b'x', 2.0)
    writer.close()
    writer.close()  # idempotent
    with pytest.raises(ValueError):
        writer.write(b'y', 3.0)
    assert _read_all(path)[1] == [(2.0, b'x')]


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(ValueError):
        CaptureWriter(tmp_path / 'a', {'bad': float('nan')})
    with pytest.raises(TypeError):
        CaptureWriter(tmp_path / 'b', ['not', 'a', 'dict'])
    with CaptureWriter(tmp_path / 'c', {}) as writer, pytest.raises(ValueError):
        writer.write(b'x', float('inf'))


@pytest.mark.parametrize('cut', [1, 500, 69999])
def test_truncated_last_chunk_yields_its_bytes_and_warns(tmp_path, cut):
    path = _write(tmp_path / 'a.gx2cap')
    path.write_bytes(path.read_bytes()[:-cut])
    _, chunks = read_capture(path)
    with pytest.warns(TruncatedCaptureWarning, match='cut short'):
        got = list(chunks)
    assert got[:3] == CHUNKS[:3]
    assert got[3] == (CHUNKS[3][0], CHUNKS[3][1][:-cut])


@pytest.mark.parametrize('keep', [1, CHUNK_HEADER.size - 1])
def test_capture_cut_inside_a_chunk_header_warns(tmp_path, keep):
    path = _write(tmp_path / 'a.gx2cap', chunks=CHUNKS[:2])
    raw = path.read_bytes()
    path.write_bytes(raw + CHUNK_HEADER.pack(5.0, 10)[:keep])
    with pytest.warns(TruncatedCaptureWarning, match='chunk header'):
        got = list(read_capture(path)[1])
    assert got == CHUNKS[:2]


def test_intact_capture_reads_without_warning(tmp_path):
    path = _write(tmp_path / 'a.gx2cap')
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert _read_all(path)[1] == CHUNKS


def test_wrong_files_are_refused_clearly(tmp_path):
    other = tmp_path / 'run.csv'
    other.write_text('time,ax\n1,2\n')
    with pytest.raises(CaptureFormatError, match='not a capture'):
        read_capture(other)
    newer = tmp_path / 'new.gx2cap'
    newer.write_bytes(b'GX2CAP 2\n{}\n')
    with pytest.raises(CaptureFormatError, match='version 2'):
        read_capture(newer)
    broken = tmp_path / 'broken.gx2cap'
    broken.write_bytes(MAGIC + b'{not json\n')
    with pytest.raises(CaptureFormatError, match='JSON'):
        read_capture(broken)
    huge = tmp_path / 'huge.gx2cap'
    huge.write_bytes(MAGIC + b'{}\n' + CHUNK_HEADER.pack(1.0, 0xFFFFFFFF))
    with pytest.raises(CaptureFormatError, match='corrupted'):
        list(read_capture(huge)[1])


def test_concurrent_writers_never_interleave_chunks(tmp_path):
    path = tmp_path / 'threads.gx2cap'
    threads, per_thread = 8, 400
    with CaptureWriter(path, {}) as writer:
        def work(k):
            for i in range(per_thread):
                # Payload sizes vary so that torn writes would misalign the reader.
                writer.write(bytes([k]) * (1 + (i * 7 + k) % 97) + i.to_bytes(2, 'big'),
                             k * 1000.0 + i)
        pool = [threading.Thread(target=work, args=(k,)) for k in range(threads)]
        for thread in pool:
            thread.start()
        for thread in pool:
            thread.join()
    chunks = _read_all(path)[1]
    assert len(chunks) == threads * per_thread
    seen = {k: [] for k in range(threads)}
    for t, data in chunks:
        k = data[0]
        i = int.from_bytes(data[-2:], 'big')
        assert data[:-2] == bytes([k]) * (1 + (i * 7 + k) % 97)
        assert t == k * 1000.0 + i
        seen[k].append(i)
    assert all(order == list(range(per_thread)) for order in seen.values())


def test_writer_flushes_within_the_interval_without_close(tmp_path):
    path = tmp_path / 'live.gx2cap'
    writer = CaptureWriter(path, {}, flush_interval=0.05)
    try:
        writer.write(b'\xaa\x07', 1.0)
        deadline = time.monotonic() + 5.0
        chunks = []
        while time.monotonic() < deadline and not chunks:
            time.sleep(0.02)
            chunks = _read_all(path)[1]  # what a crash right now would leave
        assert chunks == [(1.0, b'\xaa\x07')]
    finally:
        writer.close()


def test_fixture_chunks_hold_every_record_as_a_data_packet(fixture_path):
    records = [r for s in load_fixture(fixture_path) for r in s.records]
    parser = SensorStreamParser(address=42)
    got = []
    for _, data in fixture_chunks(fixture_path, address=42, start_time=1000.0):
        events = parser.feed(data)
        assert len(events) == 1 and isinstance(events[0], DataPacket)
        got.append(events[0])
    assert len(got) == len(records) == 1900
    assert parser.stats.bytes_skipped == 0 and parser.stats.checksum_failures == 0
    assert all(isinstance(p.record, AccelAngRateMagOrientation) for p in got)
    assert [p.record.timer for p in got] == [record_timer(r) for r in records]
    assert all(0 <= p.lqi <= 255 and 0 <= p.rssi <= 255 for p in got)
    assert len({p.lqi for p in got}) > 1, 'LQI should vary like a real link'


def test_fixture_receive_times_follow_the_timer_across_rollover_and_pauses(fixture_path):
    sets = load_fixture(fixture_path)
    times = [t for t, _ in fixture_chunks(fixture_path, start_time=5000.0)]
    assert times[0] == 5000.0
    assert all(b > a for a, b in itertools.pairwise(times))
    i = 0
    wraps = 0
    for n, fixture_set in enumerate(sets):
        timers = [record_timer(r) for r in fixture_set.records]
        if n:  # the timers of separate captures do not continue: a fixed gap stands in
            assert times[i] - times[i - 1] == pytest.approx(FIXTURE_GAP)
        for k in range(1, len(timers)):
            ticks = timers[k] - timers[k - 1]
            if ticks < 0:
                wraps += 1
                ticks += 1 << 32
            assert times[i + k] - times[i + k - 1] == pytest.approx(
                ticks / TICKS_PER_SECOND, abs=1e-6)
        i += len(timers)
    assert wraps >= 1, 'the fixture has a timer rollover'
    # The longest pause of set1 (168.5 s, over half the timer period) is kept, not
    # taken for a restart.
    assert max(b - a for a, b in itertools.pairwise(times)) == pytest.approx(
        168.513, abs=0.01)


def test_fixture_chunks_are_reproducible(fixture_path):
    assert list(fixture_chunks(fixture_path)) == list(fixture_chunks(fixture_path))


# -- the node's raw capture ---------------------------------------------------

class Log:
    """Collects log lines the way the node's logger would print them."""

    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(('info', text))

    def error(self, text):
        self.lines.append(('error', text))


def test_raw_capture_writes_reads_as_read(tmp_path):
    path = tmp_path / 'raw.gx2'
    log = Log()
    capture = RawCapture(str(path), log, port='/dev/ttyUSB0', address=95, baud=115200,
                         wireless=True)
    assert capture.active
    capture.on_bytes(b'\xaa\x07\x00', 100.0)
    capture.on_bytes(b'\x00\x5f', 100.5)
    assert '2 reads, 5 bytes' in capture.describe()
    capture.close()
    header, chunks = read_capture(path)
    assert (header['port'], header['address'], header['baud'], header['wireless']) == \
        ('/dev/ttyUSB0', 95, 115200, True)
    assert header['driver_version'] and header['start_time'] > 0
    assert list(chunks) == [(100.0, b'\xaa\x07\x00'), (100.5, b'\x00\x5f')]
    assert not any(level == 'error' for level, _ in log.lines)


def test_raw_capture_that_cannot_open_is_off_and_said_once(tmp_path):
    log = Log()
    capture = RawCapture(str(tmp_path / 'no' / 'such' / 'dir.gx2'), log)
    assert not capture.active
    capture.on_bytes(b'abc', 1.0)
    capture.close()
    errors = [text for level, text in log.lines if level == 'error']
    assert len(errors) == 1 and 'keeps running' in errors[0]
    assert capture.describe().startswith('stopped:')


@pytest.mark.skipif(not os.path.exists('/dev/full'), reason='needs /dev/full')
def test_raw_capture_on_a_full_disk_is_off_and_said_once():
    log = Log()
    capture = RawCapture('/dev/full', log)
    for _ in range(3):
        capture.on_bytes(b'x' * 100_000, 1.0)
    capture.close()
    errors = [text for level, text in log.lines if level == 'error']
    assert len(errors) == 1, log.lines
    assert 'No space left' in errors[0]


def test_raw_capture_failing_mid_stream_stops_once(tmp_path):
    log = Log()
    capture = RawCapture(str(tmp_path / 'raw.gx2'), log)
    capture.on_bytes(b'good', 1.0)
    capture._writer.error = OSError(27, 'File too large')  # as the flusher thread keeps it
    for _ in range(5):
        capture.on_bytes(b'more', 2.0)
    capture.close()
    errors = [text for level, text in log.lines if level == 'error']
    assert len(errors) == 1 and 'File too large' in errors[0]
    assert not capture.active
