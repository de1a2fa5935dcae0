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
Replay into a pseudo-terminal, read back with pyserial as the driver would.

Timing asserts are loose on purpose: they check that pacing happens, not how
precisely a loaded CI machine keeps it.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time
import tty

from i3dmgx2_driver.capture.file_format import CaptureWriter
from i3dmgx2_driver.codec import (
    Ack, DataPacket, encode_command, encode_command_packet, encode_data_packet,
    encode_record, Nack, SensorStreamParser,
)
from i3dmgx2_driver.codec.commands import set_continuous
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.tools.replay import Replayer, schedule
from i3dmgx2_driver.tools.replay_pty import unread_bytes
import pytest
import serial

REPO = Path(__file__).resolve().parents[1]
ADDRESS = 95
COUNT = 20
STEP = 0.05  # recorded spacing of the packets (s)


def _record(i):
    """Make an 0xCC record whose timer is its sequence number, so order shows."""
    m = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    return encode_record(AccelAngRateMagOrientation(
        (0.01 * i, 0.0, -1.0), (0.0, 0.001 * i, 0.0), (float('nan'),) * 3, m, i))


def _chunks(count=COUNT, step=STEP, start=1000.0):
    """Packets as a port returns them: some whole, some split, some joined."""
    stream = b''.join(encode_data_packet(ADDRESS, _record(i), 200, 180) for i in range(count))
    size = len(stream) // count
    cuts = sorted({k * size + (size // 3 if k % 3 == 1 else 0) for k in range(1, count)}
                  - {size * 4})  # one read holds two packets
    pieces = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    return [(start + k * step * count / len(pieces), p) for k, p in enumerate(pieces)]


def _open(port):
    return serial.Serial(port, 115200, timeout=0.05)


def _read_until(ser, done, timeout=10.0, parser=None):
    """
    Read until ``done(events)`` (or timeout); return events, arrival times, parser.

    Each read returns what has arrived, as the driver's does, rather than
    waiting out the serial timeout for more: a replay that closes the pty
    once everything was read would otherwise hang up inside a read that
    already holds the last packets, and pyserial drops them with its error.
    """
    parser = parser or SensorStreamParser(address=ADDRESS)
    events, arrivals = [], []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not done(events):
        data = ser.read(max(1, ser.in_waiting))
        new = parser.feed(data) if data else parser.idle()
        now = time.monotonic()
        events += new
        arrivals += [now] * len(new)
    return events, arrivals, parser


def _count(events, kind):
    return sum(isinstance(e, kind) for e in events)


def _read_packets(ser, count, timeout=10.0, parser=None):
    """Read until ``count`` data packets came (or timeout)."""
    return _read_until(ser, lambda events: _count(events, DataPacket) >= count, timeout, parser)


def _command():
    return encode_command_packet(ADDRESS, encode_command(0xCC))


def test_schedule_paces_from_the_first_chunk_and_caps_gaps():
    assert schedule([10.0, 10.5, 10.4, 40.0]) == [0.0, 0.5, 0.5, 30.1]
    assert schedule([10.0, 10.5, 40.0], max_gap=2.0) == [0.0, 0.5, 2.5]
    assert schedule([]) == []


@pytest.mark.slow
def test_unread_bytes_sees_what_was_just_written():
    """
    The replay waits for its reader by this count before it closes the pty.

    Plain FIONREAD read 0 right after a write to the master most of the time
    (the bytes were still in the tty's flip buffer), so a drain() called
    just after the last write could end, and the pty close, before the
    reader had those bytes.
    """
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        for _ in range(2000):
            os.write(master, b'\xaa' * 88)
            assert unread_bytes(slave) > 0
            got = b''
            while len(got) < 88:
                got += os.read(slave, 4096)
            assert unread_bytes(slave) == 0
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.slow
def test_replay_delivers_exactly_the_packets_in_order():
    chunks = _chunks()
    with Replayer(chunks, speed=0, wait_for_host=True) as replayer:
        link = replayer.port
        assert os.path.islink(link)
        assert os.path.realpath(replayer.port) == replayer.pty.pty_name
        with _open(replayer.port) as ser:
            ser.write(_command())  # the driver speaks first; playback starts
            events, _, parser = _read_packets(ser, COUNT)
        assert replayer.wait(5.0)
    packets = [e for e in events if isinstance(e, DataPacket)]
    assert [p.record.timer for p in packets] == list(range(COUNT))
    assert [encode_record(p.record) for p in packets] == [_record(i) for i in range(COUNT)]
    assert all(p.address == ADDRESS and (p.lqi, p.rssi) == (200, 180) for p in packets)
    assert parser.stats.bytes_skipped == 0 and parser.stats.checksum_failures == 0
    assert sum(isinstance(e, Ack) for e in events) == 1
    assert replayer.stats.chunks_sent == len(chunks)
    assert replayer.stats.bytes_dropped == 0
    assert not os.path.lexists(link), 'the link is removed at stop'


@pytest.mark.slow
@pytest.mark.parametrize('wireless', [True, False])
def test_wait_for_stream_starts_the_playback_at_the_request_for_a_stream(wireless):
    chunks = _chunks(count=5)
    wrap = ((lambda command: encode_command_packet(ADDRESS, command)) if wireless
            else (lambda command: command))
    with Replayer(chunks, speed=0, wireless=wireless, wait_for_stream=True) as replayer, \
            _open(replayer.port) as ser:
        # The dialogue before the stream (a poll, a stop of the stream) plays nothing.
        ser.write(wrap(encode_command(0xCC)) + wrap(set_continuous(0)))
        events, _, _ = _read_until(ser, lambda ev: _count(ev, DataPacket), 1.0)
        assert _count(events, DataPacket) == 0 and not replayer.finished
        ser.write(wrap(set_continuous(0xCC)))
        events, _, _ = _read_packets(ser, 5)
        assert [e.record.timer for e in events if isinstance(e, DataPacket)] == list(range(5))
        assert replayer.wait(5.0)


@pytest.mark.slow
def test_speed_paces_the_playback_loosely():
    chunks = _chunks(count=12, step=0.1)  # 1.2 s as recorded
    with Replayer(chunks, speed=2.0, wait_for_host=True) as replayer, \
            _open(replayer.port) as ser:
        ser.write(_command())
        start = time.monotonic()
        events, arrivals, _ = _read_packets(ser, 12)
    data_times = [t for e, t in zip(events, arrivals, strict=True) if isinstance(e, DataPacket)]
    assert len(data_times) == 12
    elapsed = data_times[-1] - start
    # 1.1 s between first and last chunk at speed 2 is 0.55 s; allow for a slow machine.
    assert 0.35 < elapsed < 5.0
    with Replayer(chunks, speed=0, wait_for_host=True) as replayer, \
            _open(replayer.port) as ser:
        ser.write(_command())
        start = time.monotonic()
        events, arrivals, _ = _read_packets(ser, 12)
    assert sum(isinstance(e, DataPacket) for e in events) == 12
    assert arrivals[-1] - start < elapsed


@pytest.mark.slow
def test_command_packets_get_an_ack_even_in_a_pause_and_malformed_ones_a_nack():
    chunks = [(0.0, encode_data_packet(ADDRESS, _record(0), 1, 2)),
              (30.0, encode_data_packet(ADDRESS, _record(1), 1, 2))]
    with Replayer(chunks, speed=1.0, wait_for_host=True) as replayer:
        with _open(replayer.port) as ser:
            parser = SensorStreamParser(address=ADDRESS)
            ser.write(_command())  # starts the playback: the first packet and the ACK
            events, _, _ = _read_until(
                ser, lambda ev: _count(ev, DataPacket) and _count(ev, Ack), 5.0, parser)
            assert _count(events, DataPacket) == 1 and _count(events, Ack) == 1
            # Now in the recorded 30 s pause: only answers can arrive, and promptly.
            bad = bytearray(_command())
            bad[-1] ^= 0xFF  # checksum
            ser.write(bytes(bad))
            events, _, _ = _read_until(ser, lambda ev: ev, 3.0, parser)
            assert [type(e) for e in events] == [Nack]
            ser.write(_command())
            events, _, _ = _read_until(ser, lambda ev: ev, 3.0, parser)
            assert [type(e) for e in events] == [Ack]
        assert replayer.stats.commands == 2
        assert replayer.stats.acks_sent == 2 and replayer.stats.nacks_sent == 1
        assert not replayer.finished


@pytest.mark.slow
def test_loop_plays_the_capture_again():
    chunks = _chunks(count=5)
    with Replayer(chunks, speed=0, loop=True, wait_for_host=True) as replayer:
        with _open(replayer.port) as ser:
            ser.write(_command())
            events, _, parser = _read_packets(ser, 12)
        assert replayer.stats.passes >= 3
        assert not replayer.finished
    timers = [e.record.timer for e in events if isinstance(e, DataPacket)]
    assert timers[:12] == [0, 1, 2, 3, 4] * 2 + [0, 1]
    assert parser.stats.bytes_skipped == 0


@pytest.mark.slow
def test_link_option_names_the_port_and_is_removed(tmp_path):
    link = tmp_path / 'ttyGX2'
    with Replayer(_chunks(count=2), speed=0, link=str(link)) as replayer:
        assert replayer.port == str(link)
        assert link.is_symlink() and os.readlink(link) == replayer.pty.pty_name
    assert not link.exists() and not link.is_symlink()
    regular = tmp_path / 'file'
    regular.write_text('keep me')
    with pytest.raises(FileExistsError):
        Replayer([], link=str(regular)).start()
    assert regular.read_text() == 'keep me'


def _write_capture(path, chunks):
    with CaptureWriter(path, {'port': '/dev/ttyUSB0', 'address': ADDRESS}) as writer:
        for t, data in chunks:
            writer.write(data, t)
    return path


def _start_cli(*args):
    env = dict(os.environ)
    env['PYTHONPATH'] = str(REPO) + (os.pathsep + env['PYTHONPATH']
                                     if env.get('PYTHONPATH') else '')
    proc = subprocess.Popen(
        [sys.executable, '-m', 'i3dmgx2_driver.tools.replay', *args], cwd=REPO, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith('port: '), line + proc.stderr.read()
    return proc, line[len('port: '):].strip()


@pytest.mark.slow
def test_cli_prints_the_port_serves_the_capture_and_exits_0(tmp_path):
    capture = _write_capture(tmp_path / 'small.gx2cap', _chunks())
    proc, port = _start_cli(str(capture), '--speed', '0', '--wait-for-host', '--linger', '5')
    try:
        with _open(port) as ser:
            ser.write(_command())
            events, _, _ = _read_packets(ser, COUNT)
        assert [e.record.timer for e in events if isinstance(e, DataPacket)] == \
            list(range(COUNT))
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert not os.path.lexists(port), 'the temporary link is removed on exit'


@pytest.mark.slow
def test_cli_exits_0_at_the_end_with_nobody_reading(tmp_path):
    capture = _write_capture(tmp_path / 'small.gx2cap', _chunks(count=3))
    proc, _ = _start_cli(str(capture), '--speed', '0', '--linger', '0.2')
    assert proc.wait(timeout=10) == 0


@pytest.mark.slow
def test_cli_exits_0_on_sigterm_while_looping(tmp_path):
    capture = _write_capture(tmp_path / 'small.gx2cap', _chunks(count=3))
    proc, port = _start_cli(str(capture), '--speed', '1', '--loop')
    time.sleep(0.3)
    assert proc.poll() is None
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=10) == 0
    assert not os.path.lexists(port)


@pytest.mark.slow
def test_cli_reports_a_missing_capture():
    result = subprocess.run(
        [sys.executable, '-m', 'i3dmgx2_driver.tools.replay', '/nonexistent.gx2cap'],
        cwd=REPO, capture_output=True, text=True, timeout=30, check=False,
        env={**os.environ, 'PYTHONPATH': str(REPO)})
    assert result.returncode == 1
    assert 'nonexistent' in result.stderr
