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
The one thread that reads a port, and whom it hands each event.

A single thread reads the port, feeds the parser and hands every record to
the sensor's stream watch the moment it is complete: no queue, no executor
in between, so nothing else can delay a sample. It is its own module because
it is the hot path's first stage and the one place that knows how a port is
shared: changing how bytes become events touches nothing else.
"""

from collections.abc import Callable
from dataclasses import dataclass
import threading
import time
from typing import TYPE_CHECKING

from .hot_path import HotPathObserver
from .observer import LineObserver, QUIET_AFTER
from .port import PortDisconnected, SerialPort
from .realtime import apply_to_current_thread, NORMAL_SCHEDULING, PolicyOutcome, ThreadPolicy
from ..codec.framing import DataPacket
from ..codec.parser import SensorStreamParser

if TYPE_CHECKING:
    from .exchange import Exchange
    from .stream_watch import StreamWatch

#: Called from the reader thread with each data packet and its read time.
#: Called with a record, the system-clock time its last byte was read and the same
#: instant on the monotonic clock (what intervals and the device-clock fit use: the
#: system clock can be stepped).
RecordCallback = Callable[[DataPacket, float, float], None]
#: Called from the reader thread with each read's bytes and their read time.
BytesCallback = Callable[[bytes, float], None]


@dataclass(frozen=True)
class LinkOptions:
    """
    How a link reads and whom it tells, besides the consumer of records.

    ``wireless=False`` speaks to a wired sensor (no packets, no ACKs).
    ``read_timeout`` bounds each read (s). ``on_bytes``, if given, receives
    every read's bytes as read, before they are parsed (a raw capture); it
    runs in the reader thread and must not raise or block. ``observer``, if
    given, is fed every read while no packet of ours has arrived for
    ``QUIET_AFTER`` s (never while records flow). ``cancel``, if given and
    set, makes requests give up within tens of milliseconds while the reader
    goes on (the stream is being stopped, the port kept: nobody waits for
    the answers any more). ``thread_policy`` is applied by the reader thread
    to itself before its first read. ``timings``, if given, is told when each
    read returned and when the parser was done with it (hot_path.py); None
    costs one test per stage.
    """

    wireless: bool = True
    read_timeout: float = 0.2
    on_bytes: BytesCallback | None = None
    observer: LineObserver | None = None
    cancel: threading.Event | None = None
    thread_policy: ThreadPolicy = NORMAL_SCHEDULING
    timings: HotPathObserver | None = None


class PortReader:
    """
    The one thread that reads a port, and whom it hands each event.

    Data packets go to the stream watch of their address (``routes``); a
    port with one sensor has its watch as ``fallback`` and an empty table
    (its parser keeps the other addresses out), so the hot path is one dict
    lookup. The base station's answers (ACK, NACK, a ping's byte) carry no
    address: they go to the exchange whose request holds the port now
    (``requester``), and since ``request_lock`` lets one exchange at a time
    onto the port, that is the only one who can be waiting for them.
    ``address`` None (a port shared by several sensors) reads every node's
    packets; those of an address no watch routes are counted by address in
    ``strays``.
    """

    def __init__(self, port: SerialPort, address: int | None,
                 options: LinkOptions | None = None) -> None:
        options = options if options is not None else LinkOptions()
        self.port = port
        self.wireless = options.wireless
        self.parser = SensorStreamParser(address=address if self.wireless else None,
                                         wireless=self.wireless)
        self.routes: dict[int | None, StreamWatch] = {}
        self.fallback: StreamWatch | None = None
        #: The exchange that holds the port now (set under ``request_lock``).
        self.requester: Exchange | None = None
        #: Packets of addresses no link routes, by address (a port shared by several).
        self.strays: dict[int, int] = {}
        self.request_lock = threading.Lock()
        self.write_lock = threading.Lock()
        self._on_bytes = options.on_bytes
        self._observer = options.observer
        self._timings = options.timings
        self._read_timeout = options.read_timeout
        self._thread_policy = options.thread_policy
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._start_lock = threading.Lock()
        self.disconnected = threading.Event()
        self.error: str | None = None
        #: What the scheduler granted the thread (set once it runs).
        self.policy_outcome = PolicyOutcome()
        #: Set by the thread once its policy is applied, before its first read.
        self.running = threading.Event()

    @property
    def stopping(self) -> bool:
        """Whether the reader was told to stop (requests on it give up)."""
        return self._stop.is_set()

    def start(self) -> None:
        """Start the reader thread (once; later calls do nothing)."""
        with self._start_lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name='gx2-reader',
                                                daemon=True)
                self._thread.start()

    def stop(self) -> None:
        """Stop the reader thread and wait for it (a read times out quickly)."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def abort(self) -> None:
        """Make the reader give up (driver shutdown)."""
        self._stop.set()

    def _watches(self) -> list['StreamWatch']:
        watches = list(self.routes.values())
        if self.fallback is not None:
            watches.append(self.fallback)
        return watches

    def _run(self) -> None:
        if self._thread_policy.requested:
            self.policy_outcome = apply_to_current_thread(self._thread_policy)
        self.running.set()
        parser = self.parser
        read = self.port.read_some
        observer = self._observer
        timings = self._timings
        routes = self.routes
        while not self._stop.is_set():
            timeout = 0.02 if parser.pending == 1 else self._read_timeout
            try:
                data = read(timeout)
            except PortDisconnected as exc:
                self.error = str(exc)
                self.disconnected.set()
                for watch in self._watches():
                    watch.wake()
                return
            now = time.time()
            mono = time.monotonic()
            if timings is not None:
                timings.read(len(data), now)
            if data and self._on_bytes is not None:
                self._on_bytes(data, now)
            if observer is not None and observer.active and self.fallback is not None \
                    and mono - self.fallback.last_data_mono > QUIET_AFTER:
                observer.feed(data, mono, self.fallback.last_data_mono)
            events = parser.feed(data) if data else parser.idle()
            if timings is not None:
                timings.parsed()
            fallback = self.fallback
            for event in events:
                if type(event) is DataPacket:
                    watch = routes.get(event.address, fallback)
                    if watch is not None:
                        watch.on_data(event, now, mono)
                    else:
                        self._stray(event.address)
                else:
                    requester = self.requester
                    if requester is not None:
                        requester.answer(event)

    def _stray(self, address: int) -> None:
        """Count a packet of an address no link routes (a foreign frame, as the parser would)."""
        self.strays[address] = self.strays.get(address, 0) + 1
        stats = self.parser.stats
        stats.good_frames -= 1
        stats.foreign_frames += 1
