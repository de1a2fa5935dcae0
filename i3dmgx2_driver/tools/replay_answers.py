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
The one answer a replay gives: the base station's ACK or NACK to each command packet.

There is no sensor behind a replay, but a driver waiting for the base
station's ACK would stall without one: :class:`BaseStationAnswers` reads
what the host writes, answers a well-formed wireless command packet with
an ACK (0xAA) and a malformed one with a NACK (0x21), and leaves everything
else unanswered. An answer waits for the end of the packet being played
(never inside one, where it would corrupt it), but never longer than
:data:`ACK_HOLD`. The playing (replay.py) hands it every chunk it played,
to know where the packets end, and asks it to send what is due. Both count
what they did in one :class:`ReplayStats`.
"""

import dataclasses
import logging
import threading
import time

from .replay_pty import ReplayPty
from ..codec import layouts
from ..codec.framing import ACK, CommandPacket, NACK
from ..codec.parser import (
    CommandStreamParser, HostEvent, RawCommand, RejectedPacket, SensorStreamParser,
)

_LOG = logging.getLogger('i3dmgx2_driver.replay')
#: An ACK waits for the end of the packet being sent, but never longer than this.
ACK_HOLD = 0.5


@dataclasses.dataclass(slots=True)
class ReplayStats:
    """What a replay did, for the log and for tests: the playing's counts and the answers'."""

    acks_sent: int = 0
    bytes_dropped: int = 0
    bytes_sent: int = 0
    chunks_sent: int = 0
    commands: int = 0
    host_bytes: int = 0
    nacks_sent: int = 0
    passes: int = 0


def _asks_for_stream(event: HostEvent) -> bool:
    """Whether the host asks for continuous mode of a record (0xC4 not stopping it)."""
    if not isinstance(event, (CommandPacket, RawCommand)):
        return False
    command = event.command
    layout = layouts.LAYOUTS[layouts.SET_CONTINUOUS]
    if command[:1] != bytes((layouts.SET_CONTINUOUS,)) or len(command) != layout.request_size:
        return False
    streamed, = layout.request_struct.unpack_from(command, 1 + len(layout.confirm))
    return streamed != 0


class BaseStationAnswers:
    """
    Answer the host's command packets on ``pty`` as a base station would (``wireless``).

    ``wake`` is set when an answer is queued, so that the playing thread
    sends it; ``stop`` ends :meth:`listen`. Counts go into ``stats``.
    :attr:`host_seen` is set once the host first wrote, :attr:`stream_asked`
    once it first asked for continuous mode (0xC4 of a record): a driver
    counts records as samples only from then on, so a playback started there
    reaches it whole.
    """

    def __init__(self, pty: ReplayPty, stats: ReplayStats, wireless: bool,
                 wake: threading.Event, stop: threading.Event) -> None:
        self._pty, self._stats, self._wireless, self._wake, self._stop = (
            pty, stats, wireless, wake, stop)
        self.host_seen, self.stream_asked = threading.Event(), threading.Event()
        self._answers: list[bytes] = []
        self._answers_lock = threading.Lock()
        self._answer_due = 0.0
        self._tracker = SensorStreamParser(wireless=True)

    def played(self, data: bytes) -> None:
        """Note bytes played, to know where the packets end."""
        if self._wireless:
            self._tracker.feed(data)

    def send(self, force: bool = False) -> None:
        """Send queued ACK/NACKs between packets, never inside one."""
        # Between packets: at most a lone 0xAA held back (an ACK after it reads the same).
        if not self._answers or (not force and self._tracker.pending > 1
                                 and time.monotonic() < self._answer_due):
            return
        with self._answers_lock:
            answers, self._answers = self._answers, []
        for answer in answers:
            if self._pty.write(answer, paced=False) == len(answer):
                self._stats.acks_sent += answer[0] == ACK
                self._stats.nacks_sent += answer[0] != ACK

    def _queue(self, byte: int) -> None:
        with self._answers_lock:
            if not self._answers:
                self._answer_due = time.monotonic() + ACK_HOLD
            self._answers.append(bytes((byte,)))
        self._wake.set()

    def listen(self) -> None:
        """Read what the host writes until stopped, queueing the answers (own thread)."""
        parser = CommandStreamParser(wireless=self._wireless)
        while not self._stop.is_set():
            try:
                data = self._pty.read()
            except OSError as exc:
                if not self._stop.is_set():
                    _LOG.error('reading the host stopped: %s', exc)
                return
            if not data:
                continue
            self._stats.host_bytes += len(data)
            self.host_seen.set()
            _LOG.debug('host wrote %d bytes: %s', len(data), data.hex(' '))
            for event in parser.feed(data):
                if _asks_for_stream(event):
                    self.stream_asked.set()
                if not self._wireless:
                    continue  # a wired sensor's host gets no base station's answers
                if isinstance(event, CommandPacket):
                    self._stats.commands += 1
                    _LOG.info('host command to node %d: %s (ACK; replay does not answer it)',
                              event.address, event.command.hex(' '))
                    self._queue(ACK)
                elif isinstance(event, RejectedPacket):
                    _LOG.info('host sent a malformed packet (%s): NACK', event.reason)
                    self._queue(NACK)
                else:
                    _LOG.info('host sent %s: not answered (no sensor behind a replay)',
                              event.command.hex(' '))
