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
Replay a capture into a pseudo-terminal, so the driver can run on recorded data.

The driver opens the pty's slave path as if it were the base station's port
and reads the recorded bytes, chunk by chunk as the port once returned them,
at the recorded pace (``--speed 1``), faster (``--speed 10``) or as fast as
the reader takes them (``--speed 0``).

Replay serves data only: there is no sensor behind the pty. What the driver
writes is read and discarded (logged with ``-v``); the one answer given is
the base station's: an ACK byte (0xAA) for each well-formed wireless command
packet and a NACK (0x21) for a malformed one, so that a driver waiting for
the ACK does not stall. Everything else the driver asks (pings, firmware
version, setting continuous mode) goes unanswered and times out; the driver
must carry on reading the stream regardless. A capture of a real session
also holds the ACKs and replies of that session, which arrive at their
recorded times. In a loop the device timer jumps back at each pass.

Here: the pacing of the chunks and the command line. The pty and its link
are replay_pty.py's, the ACK/NACK answers replay_answers.py's.
"""

import argparse
from collections.abc import Iterable, Sequence
import itertools
import logging
import statistics
import sys
import threading
import time
from typing import Any

from .replay_answers import ACK_HOLD, BaseStationAnswers, ReplayStats
from .replay_pty import POLL, ReplayPty
from .. import lifetime
from ..capture.file_format import read_capture
from ..capture.fixtures import FIXTURE_ADDRESS, fixture_chunks

Chunk = tuple[float, bytes]

_LOG = logging.getLogger('i3dmgx2_driver.replay')


def schedule(times: Sequence[float], max_gap: float | None = None) -> list[float]:
    """
    Turn receive times into offsets from the first chunk (s), for pacing.

    Steps backwards (the host clock was set back while recording) count as
    zero; with ``max_gap``, longer silences are shortened to it, so that a
    capture with long pauses can be replayed without waiting them out.
    """
    steps = (max(0.0, b - a) for a, b in itertools.pairwise(times))
    if max_gap is not None:
        steps = (min(step, max_gap) for step in steps)
    return list(itertools.accumulate(steps, initial=0.0))[:len(times)]


class Replayer:
    """
    Play ``(receive_time, bytes)`` chunks into a new pseudo-terminal.

    ``start()`` opens the pty and returns the path to give the driver
    (:attr:`port`): the symlink ``link`` if one was asked for, else a
    symlink in a private temporary directory (so the path is stable and says
    what it is); the pty itself is ``pty.pty_name``. ``speed`` is the pace relative to the
    recording (0: as fast as the reader takes the bytes). ``wireless``
    selects the base station's ACK/NACK answers (a wired sensor sends none).
    With ``wait_for_host`` the playback starts when the host first writes,
    so that nothing is played before the driver is there; with
    ``wait_for_stream`` when it first asks for continuous mode, so that the
    driver, which takes records for samples only from then on, gets every
    record of the capture (its identity dialogue, unanswered, times out first).
    """

    def __init__(self, chunks: Iterable[Chunk], speed: float = 1.0, loop: bool = False,
                 link: str | None = None, wireless: bool = True, max_gap: float | None = None,
                 wait_for_host: bool = False, wait_for_stream: bool = False) -> None:
        if not speed >= 0:
            raise ValueError(f'speed must be >= 0 (0: as fast as possible), got {speed!r}')
        if max_gap is not None and not max_gap >= 0:
            raise ValueError(f'max_gap must be >= 0, got {max_gap!r}')
        self.chunks: list[Chunk] = [(float(t), bytes(d)) for t, d in chunks if d]
        self.speed, self.loop = float(speed), loop
        self.stats = ReplayStats()
        self._offsets = schedule([t for t, _ in self.chunks], max_gap)
        self._stop, self._wake, self._finished = (threading.Event() for _ in range(3))
        self._threads: list[threading.Thread] = []
        #: The pseudo-terminal played into: ``pty_name``, ``pending_output()``.
        self.pty = ReplayPty(link, self._stop)
        self._answers = BaseStationAnswers(self.pty, self.stats, wireless, self._wake, self._stop)
        #: What the playback waits for first (None: nothing).
        self._awaited = self._answers.stream_asked if wait_for_stream else \
            self._answers.host_seen if wait_for_host else None
        self._dropping = False
        #: Path for the driver's ``port`` parameter (None before start).
        self.port: str | None = None

    # Public interface --------------------------------------------------------

    @property
    def finished(self) -> bool:
        """Tell whether the last chunk was played (never so when looping)."""
        return self._finished.is_set()

    def start(self) -> str:
        """Open the pty, start playing and answering; return :attr:`port`."""
        if self._threads:
            raise RuntimeError('replayer already started')
        self.pty.create()
        self.port = self.pty.path
        self._threads = [threading.Thread(target=self._play, name='replay-play', daemon=True),
                         threading.Thread(target=self._answers.listen, name='replay-listen',
                                          daemon=True)]
        for thread in self._threads:
            thread.start()
        _LOG.info('replaying %d chunks into %s (%s), speed %s%s', len(self.chunks), self.port,
                  self.pty.pty_name, self.speed or 'max', ', looping' if self.loop else '')
        return self.port

    def wait(self, timeout: float | None = None) -> bool:
        """Wait for the end of the playback; True if it ended."""
        return self._finished.wait(timeout)

    def drain(self, timeout: float, abort: threading.Event | None = None) -> bool:
        """Wait up to ``timeout`` s for the driver to read what was played."""
        deadline = time.monotonic() + timeout
        abort = abort or self._stop
        while self.pty.pending_output() > 0:
            if time.monotonic() >= deadline or abort.wait(POLL) or self._stop.is_set():
                return False
        return True

    def stop(self) -> None:
        """Stop both threads, close the pty and remove the link; idempotent."""
        self._stop.set()
        self._wake.set()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join()
        self.pty.close()

    def __enter__(self) -> 'Replayer':
        self.start()
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.stop()

    # Playing -----------------------------------------------------------------

    def _play(self) -> None:
        try:
            self._play_passes()
            self._finished.set()
            while not self._stop.is_set():  # keep answering commands until stopped
                self._wake.wait(POLL)
                self._wake.clear()
                self._answers.send(force=True)
        except OSError as exc:
            if not self._stop.is_set():
                _LOG.error('replay stopped: %s', exc)
            self._finished.set()

    def _play_passes(self) -> None:
        if self._awaited is not None:
            while not self._awaited.wait(POLL):
                if self._stop.is_set():
                    return
                self._answers.send(force=True)
        if not self.chunks:
            return
        period = self._loop_period()
        start = time.monotonic()
        base = 0.0
        while not self._stop.is_set():
            self.stats.passes += 1
            for offset, (_, data) in zip(self._offsets, self.chunks, strict=True):
                if self.speed > 0 and not self._sleep_until(start + (base + offset) / self.speed):
                    return
                self._answers.send()
                if self._stop.is_set():
                    return
                self._send_chunk(data)
            if not self.loop:
                return
            base += period

    def _loop_period(self) -> float:
        """Time from one pass's first chunk to the next pass's (s)."""
        steps = [b - a for a, b in itertools.pairwise(self._offsets) if b > a]
        return self._offsets[-1] + (statistics.median(steps) if steps else 0.1)

    def _sleep_until(self, deadline: float) -> bool:
        """Sleep to ``deadline``, answering commands meanwhile; False if stopped."""
        while True:
            self._answers.send()
            remaining = deadline - time.monotonic()
            if remaining <= 0 or self._stop.is_set():
                return not self._stop.is_set()
            self._wake.wait(min(remaining, ACK_HOLD))
            self._wake.clear()

    def _send_chunk(self, data: bytes) -> None:
        sent = self.pty.write(data, paced=self.speed > 0)
        self.stats.chunks_sent += 1
        self.stats.bytes_sent += sent
        self.stats.bytes_dropped += len(data) - sent
        if sent < len(data) and not self._dropping:
            _LOG.warning('nobody is reading %s: dropping data, as a serial line would', self.port)
        self._dropping = sent < len(data)
        self._answers.played(data[:sent])


# Command line -----------------------------------------------------------------


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='replay',
        description='Play a 3DM-GX2 capture (or the real-records fixture) into a '
                    'pseudo-terminal; run the driver with port:=<the printed path>. Replay '
                    "serves data only: the driver's commands get the base station's ACK "
                    'and nothing else, so its requests time out.')
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument('capture', nargs='?', help='capture file (GX2CAP) to play')
    source.add_argument('--fixture', metavar='PATH',
                        help='play the real-records fixture instead of a capture')
    parser.add_argument('--address', type=int, default=FIXTURE_ADDRESS,
                        help="node address of the fixture's packets (default %(default)s)")
    parser.add_argument('--speed', type=float, default=1.0,
                        help='pace relative to the recording: 1 original, 10 ten times '
                             'faster, 0 as fast as the reader takes it (default 1)')
    parser.add_argument('--loop', action='store_true', help='start again at the end')
    parser.add_argument('--link', metavar='PATH',
                        help='symlink to the pty to create (default: in a private temp dir)')
    parser.add_argument('--max-gap', type=float, metavar='S',
                        help='shorten silences longer than S seconds to S')
    parser.add_argument('--wait-for-host', action='store_true',
                        help='start playing when the driver first writes to the port')
    parser.add_argument('--wait-for-stream', action='store_true',
                        help='start playing when the driver first asks for continuous mode '
                             '(after its dialogue): every record of the capture reaches it')
    parser.add_argument('--linger', type=float, default=2.0, metavar='S',
                        help='at the end, wait up to S seconds for the driver to read '
                             'what was played (default %(default)s)')
    parser.add_argument('--bag', metavar='OUT',
                        help='instead of playing, write the messages the node would publish '
                             '(Imu, MagneticField, Temperature; its topics and stamps) as a '
                             'rosbag2 bag with MCAP storage in the new directory OUT (needs '
                             'rosbags: pip install rosbags)')
    parser.add_argument('-v', '--verbose', action='count', default=0,
                        help="log the host's commands (-v) and bytes (-vv) to stderr")
    return parser


def _load(args: argparse.Namespace) -> tuple[list[Chunk], dict[str, Any], str]:
    """Return the chunks to play, the capture's header (the fixture's: its address), the source."""
    if args.fixture:
        return (list(fixture_chunks(args.fixture, address=args.address)),
                {'wireless': True, 'address': args.address}, args.fixture)
    header, chunks = read_capture(args.capture)
    return list(chunks), header, args.capture


def main(argv: Sequence[str] | None = None) -> int:
    """Run the replay command line; return the exit status."""
    args = _parser().parse_args(argv)
    logging.basicConfig(
        level=(logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)],
        format='replay: %(levelname)s: %(message)s', stream=sys.stderr)
    if args.speed < 0:
        print('replay: --speed must be >= 0', file=sys.stderr)
        return 2
    try:
        chunks, header, source = _load(args)
        if args.bag:  # the node's messages in a bag instead (bag_io.py)
            from .bag_io import capture_messages, write_bag
            count = write_bag(args.bag, capture_messages(chunks, header))
            print(f'wrote {count} messages to {args.bag}', flush=True)
            return 0
    except (ImportError, OSError, ValueError) as exc:
        print(f'replay: {exc}', file=sys.stderr)
        return 1
    replayer = Replayer(chunks, speed=args.speed, loop=args.loop, link=args.link,
                        wireless=bool(header.get('wireless', True)), max_gap=args.max_gap,
                        wait_for_host=args.wait_for_host, wait_for_stream=args.wait_for_stream)
    lifetime.die_with_parent()
    # Not a threading.Event: a signal handler may not take a lock (lifetime.py says why).
    stop = lifetime.StopSignal().install()
    try:
        print(f'port: {replayer.start()}', flush=True)
        _LOG.info('source %s: %d chunks, %d bytes', source, len(chunks),
                  sum(len(d) for _, d in chunks))
        while not stop.is_set() and not replayer.wait(0.1):
            pass
        if not stop.is_set() and not replayer.drain(args.linger, stop) and not stop.is_set():
            _LOG.info('%d bytes were not read by anyone', replayer.pty.pending_output())
    except OSError as exc:
        print(f'replay: {exc}', file=sys.stderr)
        return 1
    finally:
        replayer.stop()
        stop.restore()
    _LOG.info('done: %r', replayer.stats)
    return 0


if __name__ == '__main__':
    sys.exit(main())
