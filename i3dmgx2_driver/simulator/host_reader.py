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
The simulator's reader thread: the host's bytes, and the actions scheduled on it.

It waits on the port (select with a timeout, never a busy poll) and on a
wake-up pipe. The port runs in packet mode: a status byte tells when the
host (re)opened it, which the firmware quirks and the tests care about;
data go through the line end's parser to the base station or the wired
sensor. Between reads it runs the actions that are due (unplug, replug,
power up after a power cycle), one at a time, never in the middle of a
command.
"""

import collections.abc
import contextlib
import heapq
import os
import select
import threading
import time

from .base_station import BaseStation
from .ground_truth import GroundTruth
from .pty_port import PtyPort, TIOCPKT_DATA, TIOCPKT_FLUSHREAD
from .transmitter import POLL_S
from .wired_line import WiredLine
from ..lifetime import close_quietly

_READ_SIZE = 4096


class HostReader:
    """
    Reads the host's bytes and runs the scheduled actions, on one thread.

    ``changed`` is a condition on the simulator's lock: each event is
    handled whole under it, answer written included, so that the ground truth
    already shows a command when the host sees its ACK. ``port_opened`` tells
    every sensor's inbox that the host opened the port (or flushed its input).
    """

    def __init__(self, port: PtyPort, end: BaseStation | WiredLine, record: GroundTruth,
                 port_opened: collections.abc.Callable[[], None],
                 changed: threading.Condition) -> None:
        self._port, self._end, self._record = port, end, record
        self._port_opened, self._changed = port_opened, changed
        self._parser = end.new_parser()
        self._actions: list[tuple[float, int, collections.abc.Callable[[], None]]] = []
        self._seq = 0
        self._wake_r, self._wake_w = -1, -1

    def open_pipe(self) -> None:
        """Make the wake-up pipe (before the thread starts)."""
        self._wake_r, self._wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)

    def close_pipe(self) -> None:
        """Close the wake-up pipe (after the thread ended)."""
        close_quietly(self._wake_r, self._wake_w)

    def plug_in(self) -> None:
        """Plug the port in, and start reading the host afresh."""
        self._port.plug_in()
        with self._changed:
            self._parser = self._end.new_parser()
            self._port_opened()

    def wake(self) -> None:
        """Wake the thread up (a new action, or stop)."""
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b'!')

    def post(self, delay: float, action: collections.abc.Callable[[], None]) -> None:
        """Run ``action`` on the reader thread after ``delay`` seconds."""
        with self._changed:
            self._seq += 1
            heapq.heappush(self._actions, (time.monotonic() + delay, self._seq, action))
        self.wake()

    def run(self, stop: threading.Event) -> None:
        """Read the host and run the actions until ``stop`` is set."""
        while not stop.is_set():
            timeout = self._run_actions()
            master = self._port.master
            watch = [self._wake_r] if master is None else [master, self._wake_r]
            try:
                ready, _, _ = select.select(watch, [], [], timeout)
            except (OSError, ValueError):
                continue
            if self._wake_r in ready:
                with contextlib.suppress(OSError):
                    os.read(self._wake_r, 512)
            if master is not None and master in ready:
                try:
                    data = os.read(master, _READ_SIZE)
                except OSError:
                    continue
                if data:
                    self._on_bytes(data, time.time())

    def _run_actions(self) -> float:
        """Run the actions that are due; return the delay until the next one."""
        while True:
            with self._changed:
                if not self._actions:
                    return POLL_S
                delay = self._actions[0][0] - time.monotonic()
                if delay > 0:
                    return min(delay, POLL_S)
                _, _, action = heapq.heappop(self._actions)
            action()

    def _on_bytes(self, data: bytes, now: float) -> None:
        # Packet mode: a leading 0 means data; anything else is a status byte.
        if data[0] != TIOCPKT_DATA:
            if data[0] & TIOCPKT_FLUSHREAD:
                with self._changed:
                    self._port_opened()
                    self._record.count(port_opens=1)
                    self._changed.notify_all()
            return
        with self._changed:
            skipped = self._parser.stats.bytes_skipped
            for event in self._parser.feed(data[1:]):
                self._end.on_event(event, now)
            self._record.count(bytes_read=len(data) - 1,
                               host_bytes_ignored=self._parser.stats.bytes_skipped - skipped)
