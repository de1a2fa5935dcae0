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
One connection to one sensor: the thread that reads its port, its requests and its records.

A single thread reads the port, feeds the parser and hands every record to
the sensor's link the moment it is complete: no queue, no executor in
between, so nothing else can delay a sample. :class:`PortReader` is that
thread; it knows nothing of requests or streams, only whom each event goes
to: a data packet to the link of its address, the base station's answers
(which carry no address) to the link that holds the port now.

:class:`DeviceLink` is what the other layers hold: the requests to one
sensor with their retries (the radio loses commands both ways), the request
waiting for its reply, which data packet is a reply, a record of the stream
or both, when the stream was last heard, and the radio's link quality. Alone
on its port it makes its own reader; on a port several sensors share
(shared_port.py) it joins that port's reader. The reader tells a link what
happens through four methods (:meth:`DeviceLink.on_data`,
:meth:`~DeviceLink.answer`, :meth:`~DeviceLink.reader_started`,
:meth:`~DeviceLink.port_lost`), as pyserial's ``ReaderThread`` tells its
``Protocol``; neither writes the other's fields.
"""

from collections.abc import Callable, Iterator
import contextlib
from dataclasses import dataclass
import threading
import time
from typing import Any, NamedTuple

from . import hot_path, timeouts
from .observer import LineObserver, QUIET_AFTER
from .port import PortDisconnected, SerialPort
from .reader_threads import READERS
from .realtime import NORMAL_SCHEDULING, NOTHING_GRANTED, PolicyOutcome, ThreadPolicy
from ..codec import commands, layouts, line_budget
from ..codec.framing import DataPacket, encode_command_packet
from ..codec.parser import Ack, Nack, SensorStreamParser
from ..codec.records import PingReply

__all__ = ['BytesCallback', 'DeviceError', 'DeviceLink', 'DeviceNack', 'DeviceTimeout',
           'EchoMismatch', 'LinkOptions', 'PortReader', 'RadioStats', 'RecordCallback',
           'RequestCancelled']

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
    ``select_timeout`` bounds each wait for bytes (s): how soon the reader
    sees it is told to stop (not the stall timeout, the node's ``read_timeout``
    parameter, which is the supervisor's). ``on_bytes``, if given, receives
    every read's bytes as read, before they are parsed (a raw capture); it
    runs in the reader thread and must not raise or block. ``observer``, if
    given, is fed every read while no packet of ours has arrived for
    ``QUIET_AFTER`` s (never while records flow). ``cancel``, if given and
    set, makes requests give up within tens of milliseconds while the reader
    goes on (the stream is being stopped, the port kept: nobody waits for
    the answers any more). ``thread_policy`` is applied by the reader thread
    to itself before its first read. ``records_of`` is the record the
    consumer takes: the node's stream, so that no other record reaches its
    publishers; None (a tool listening to whatever a sensor streams): every
    record that is no reply. ``on_lost``, if given, is called in the reader
    thread once the port is lost (the link's ``error`` said), so that whoever
    watches the link blocks until then rather than looking again and again.
    """

    wireless: bool = True
    select_timeout: float = timeouts.SELECT_TIMEOUT_S
    on_bytes: BytesCallback | None = None
    observer: LineObserver | None = None
    cancel: threading.Event | None = None
    thread_policy: ThreadPolicy = NORMAL_SCHEDULING
    records_of: int | None = None
    on_lost: Callable[[], None] | None = None

    @classmethod
    def listening(cls, wireless: bool, on_bytes: BytesCallback | None) -> 'LinkOptions':
        """Return a tool's options: every read's bytes to ``on_bytes``, a short wait."""
        return cls(wireless=wireless, select_timeout=timeouts.TOOL_READ_TIMEOUT, on_bytes=on_bytes)


class DeviceError(Exception):
    """A request to the sensor did not end as asked: catch this for every kind below."""


class DeviceTimeout(DeviceError):
    """A request got no reply after every retry."""


class DeviceNack(DeviceTimeout):
    """The base station rejected a request on every try."""


class RequestCancelled(DeviceError):
    """Given up on this side (the link shutting down, the stream stopped), not by the sensor."""


class EchoMismatch(DeviceError):
    """The sensor answered with other than what was written or asked (a read-back, an echo)."""


class RadioStats(NamedTuple):
    """Latest, lowest and mean LQI and RSSI of the packets received."""

    lqi: int
    rssi: int
    lqi_min: int
    rssi_min: int
    lqi_mean: float
    rssi_mean: float


class RadioMeter:
    """The radio's link quality so far: latest, lowest and mean LQI and RSSI."""

    def __init__(self) -> None:
        #: Latest LQI and RSSI, their lowest, their sums and the packets counted
        #: (DeviceLink.on_data counts each packet: it allocates nothing).
        self.counts: list[int] = [0, 0, 255, 255, 0, 0, 0]

    @property
    def stats(self) -> RadioStats | None:
        """Return the quality so far, or None before the first packet."""
        r = self.counts
        return RadioStats(r[0], r[1], r[2], r[3], r[4] / r[6], r[5] / r[6]) if r[6] else None


class Pending:
    """A request waiting for its reply, filled in by the reader thread."""

    def __init__(self, code: int | None) -> None:
        self.code = code
        self.reply: Any = None
        self.done, self.acked, self.nacked = (threading.Event() for _ in range(3))

    def fulfil(self, reply: Any) -> None:
        """Hand the waiting request its reply (reader thread)."""
        self.reply = reply
        self.done.set()


class PortReader:
    """
    The one thread that reads a port, and whom it hands each event.

    Data packets go to the link of their address (:meth:`route`); a port
    with one sensor has its link as ``fallback`` and an empty table (its
    parser keeps the other addresses out), so the hot path is one dict
    lookup. The base station's answers (ACK, NACK, a ping's byte) carry no
    address: they go to the link that holds the port now (:meth:`holding`),
    and since one link at a time may hold it, that is the only one who can
    be waiting for them. ``address`` None (a port shared by several sensors)
    reads every node's packets; those of an address no link routes are
    counted by address in ``strays``.
    """

    def __init__(self, port: SerialPort, address: int | None, options: LinkOptions | None = None,
                 fallback: 'DeviceLink | None' = None) -> None:
        self._options = options = options if options is not None else LinkOptions()
        self.port = port
        self.wireless = options.wireless
        self.parser = SensorStreamParser(address=address if self.wireless else None,
                                         wireless=self.wireless)
        self._routes: dict[int | None, DeviceLink] = {}
        self._fallback = fallback
        #: The link that holds the port now (set under ``_request_lock``).
        self._requester: DeviceLink | None = None
        #: Packets of addresses no link routes, by address (a port shared by several).
        self.strays: dict[int, int] = {}
        #: ``_wake_lock`` guards the port's wake size against a request that begins meanwhile.
        self._request_lock, self._write_lock, self._wake_lock, self._start_lock = (
            threading.Lock() for _ in range(4))
        #: The packet size of each link's stream (:meth:`streams`), and the bytes a
        #: wait for data may wait for while every link streams: the smallest of
        #: those (0: any byte, as it must while a link streams nothing).
        self._stream_sizes: dict[DeviceLink, int] = {}
        self._whole = 0
        #: Requests waiting for an answer (:meth:`awaiting_answer`): an ACK is one
        #: byte, a reply shorter than a record, so no wait waits for a whole packet.
        self._awaited = 0
        self._started = False
        #: The thread reading the port now (None before and after the reading).
        self._thread: threading.Thread | None = None
        #: ``_finished`` is set once the reading has returned and its thread is idle again;
        #: ``running`` by the thread once its policy is applied, before its first read;
        #: ``disconnected`` once the port is lost.
        self._stop, self._finished, self.running, self.disconnected = (
            threading.Event() for _ in range(4))
        #: Why the port was lost (None while it works); set before ``disconnected``.
        self.error: str | None = None
        #: What the scheduler granted the thread (set once it runs).
        self.policy_outcome = PolicyOutcome()

    @property
    def stopping(self) -> bool:
        """Whether the reader was told to stop (requests on it give up)."""
        return self._stop.is_set()

    # -- who gets what -------------------------------------------------------

    def route(self, address: int | None, link: 'DeviceLink') -> None:
        """
        Hand the data packets of ``address`` to ``link`` from now on.

        A link that joins a reader already running (or already dead) is told
        so at once, as those routed before were when it happened.
        """
        self._routes[address] = link
        # The thread sets running (error) before it tells the links it routes: either
        # it saw this route, or this sees what it set.
        if self.running.is_set():
            link.reader_started(self.policy_outcome)
        if self.error is not None:
            link.port_lost(self.error)

    def unroute(self, address: int | None, link: 'DeviceLink') -> None:
        """Stop handing ``address``'s packets to ``link`` (if they still go to it)."""
        if self._routes.get(address) is link:
            del self._routes[address]
        self.streams(link, None)

    # -- how long a wait waits -----------------------------------------------

    def streams(self, link: 'DeviceLink', code: int | None) -> None:
        """
        Take what ``link`` streams now (None: nothing), for the size a wait waits for.

        While every link of the port streams, the reader waits until a whole
        packet of the smallest stream is in, or the rest of one whose start the
        parser holds (``SerialPort.wake_for``): it wakes once a record rather
        than once a piece of it, and never waits past a packet's last byte.
        """
        with self._wake_lock:
            if code is None:
                self._stream_sizes.pop(link, None)
            else:
                self._stream_sizes[link] = line_budget.packet_size(code, self.wireless)
            sizes = [self._stream_sizes.get(each, 0) for each in self._links()]
            self._whole = min(sizes) if sizes and all(sizes) else 0
            if not self._whole:
                self.port.wake_for(1)

    @contextlib.contextmanager
    def awaiting_answer(self) -> Iterator[None]:
        """Wake for any byte while a request waits: its answer may be shorter than a packet."""
        with self._wake_lock:
            self._awaited += 1
            self.port.wake_for(1)
        try:
            yield
        finally:
            with self._wake_lock:
                self._awaited -= 1

    def _wake_for(self, nbytes: int) -> None:
        """Wait for ``nbytes`` from the next read on, unless a request began meanwhile."""
        with self._wake_lock:
            self.port.wake_for(1 if self._awaited else nbytes)

    @contextlib.contextmanager
    def holding(self, link: 'DeviceLink') -> Iterator[None]:
        """Hold the port for ``link``: the base station's answers go to it, and no other's."""
        with self._request_lock:
            self._requester = link
            try:
                yield
            finally:
                self._requester = None

    def write(self, data: bytes) -> None:
        """Write ``data`` whole, whichever thread or link else writes (raises PortError)."""
        with self._write_lock:
            self.port.write(data)

    def _links(self) -> list['DeviceLink']:
        return [*self._routes.values(), *filter(None, [self._fallback])]

    # -- the thread ----------------------------------------------------------

    def start(self) -> None:
        """
        Start reading, in one of the process's reader threads (once; later calls do nothing).

        The thread is not started for this port: it is one that read an earlier
        port, or lives on for a later one (reader_threads.py says why).
        """
        with self._start_lock:
            if not self._started:
                self._started = True
                READERS.run(self._run, self._options.thread_policy, self._finished)

    def stop(self) -> None:
        """Stop reading and wait for it (a read times out quickly)."""
        self._stop.set()
        if not self._started:
            self._drop_links()  # never started: no thread will
        elif self._thread is not threading.current_thread():
            self._finished.wait(timeouts.READER_STOP_WAIT_S)

    def abort(self) -> None:
        """Make the reader give up (driver shutdown)."""
        self._stop.set()

    def _run(self, outcome: PolicyOutcome = NOTHING_GRANTED) -> None:
        self._thread = threading.current_thread()
        self.policy_outcome = outcome
        try:
            self._read()
        finally:
            self._drop_links()
            self._thread = None

    def _drop_links(self) -> None:
        """
        Let go of the links, once nothing here will call them again.

        The links hold this reader and it holds them back: a reference cycle,
        which with the port, the parsers and the thread would otherwise wait
        for a full collection, and those come seldom (the start-up heap is
        frozen): the memory curve saw each reconnect's 60 objects and their
        buffers stay for thousands of faults.
        """
        self._fallback = None
        self._routes.clear()

    def _read(self) -> None:
        self.running.set()
        for link in self._links():
            link.reader_started(self.policy_outcome)
        parser = self.parser
        held = parser.buffer
        read, feed = self.port.read_some, parser.feed
        if hot_path.timings is not None:  # the hot path timed (hot_path.py): off by default
            read = hot_path.timed_read(read)
            if hot_path.timings.stages:
                feed = hot_path.marked(feed, 'parsed')
        observer, on_bytes = self._options.observer, self._options.on_bytes
        read_timeout = self._options.select_timeout
        routes, port, data = self._routes, self.port, b''
        while not self._stop.is_set():
            pending = len(held)
            timeout = timeouts.LONE_BYTE_WAIT_S if pending == 1 else read_timeout
            # While the stream flows, a whole packet, or the rest of the one the parser
            # holds the start of (a late reader that caught the next packet's first pieces
            # is back in step with the stream at its end); any byte after a silence.
            whole = max(self._whole - pending, 1) if data and not self._awaited else 1
            if whole != port.wakes_for:
                self._wake_for(whole)
            try:
                data = read(timeout)
            except PortDisconnected as exc:
                self.error = str(exc)
                # Every link knows why before anyone sees the port gone.
                for link in self._links():
                    link.port_lost(self.error)
                self.disconnected.set()
                return
            now = time.time()
            mono = time.monotonic()
            if data and on_bytes is not None:
                on_bytes(data, now)
            if observer is not None and observer.active and self._fallback is not None \
                    and mono - self._fallback.last_data_mono > QUIET_AFTER:
                observer.feed(data, mono, self._fallback.last_data_mono)
            events = feed(data) if data else parser.idle()
            fallback = self._fallback
            for event in events:
                if type(event) is DataPacket:
                    link = routes.get(event.address, fallback)
                    if link is not None:
                        link.on_data(event, now, mono)
                    else:
                        self._stray(event.address)
                else:
                    requester = self._requester
                    if requester is not None:
                        requester.answer(event)

    def _stray(self, address: int) -> None:
        """Count a packet of an address no link routes (a foreign frame, as the parser would)."""
        self.strays[address] = self.strays.get(address, 0) + 1
        self.parser.recount_as_foreign()


class DeviceLink:
    """
    The exchanges with one sensor over an open port, and its records.

    ``address`` selects the sensor behind a base station; ``on_record``
    receives the records of the stream (:meth:`set_streamed`); ``options``
    say how to read and whom else to tell (:class:`LinkOptions`).
    ``policy_outcome`` says what the scheduler granted the reader thread.

    Alone on its port (``reader`` None) the link makes its own
    :class:`PortReader` and starts and stops it. Given a ``reader`` that
    several sensors share, it only joins it: :meth:`start` routes its
    address to it, :meth:`stop` takes that route away, and the port, its
    reader and flushes belong to whoever shares it (shared_port.py). Then
    this sensor's requests are serialised by a lock of its own, and the port
    is held only while the base station's answer (which carries no address)
    is due.
    """

    def __init__(self, port: SerialPort, address: int | None, on_record: RecordCallback,
                 options: LinkOptions | None = None, reader: PortReader | None = None) -> None:
        options = options if options is not None else LinkOptions()
        self.port = port
        self.wireless = options.wireless
        #: The node address requests go to (:meth:`retarget` changes it).
        self.address = address
        self.shared = reader is not None
        self.reader = reader = reader or PortReader(port, address, options, fallback=self)
        self.parser = reader.parser
        self.disconnected = reader.disconnected
        #: Why the port was lost (None while it works).
        self.error: str | None = None
        #: What the scheduler granted the reader thread (once it runs).
        self.policy_outcome = PolicyOutcome()
        #: ``running`` is set once the link receives its packets (its own reader runs, or
        #: its address is routed on a shared one that runs); ``_stopped`` when the link
        #: stops: every request gives up.
        self.running, self._stopped = threading.Event(), threading.Event()
        self._on_record, self._records_of, self._on_lost = (
            on_record, options.records_of, options.on_lost)
        self._cancel = options.cancel if options.cancel is not None else threading.Event()
        #: One exchange at a time with this sensor.
        self._lock = threading.Lock()
        #: The request waiting for its reply (read by the reader thread).
        self._pending: Pending | None = None
        #: The command byte of the record being streamed, None while none is
        #: (:meth:`set_streamed`): a polled reply of that code is then both the
        #: reply and a record of the stream.
        self._streamed: int | None = None
        #: Records of the stream (of any code while none is streamed) received so far,
        #: and those neither a reply nor handed to the consumer (not of ``records_of``).
        self.records = self.other_records = 0
        #: The command byte of the last record handed on (None before one).
        self.last_code: int | None = None
        #: The monotonic time the stream was last heard, for stall detection.
        self.last_data_mono = 0.0
        #: Whether a reply to one of this link's requests arrived.
        self._replied = False
        #: The radio's link quality, from the packets received.
        self.radio = RadioMeter()

    # -- what the link knows -------------------------------------------------

    @property
    def heard(self) -> bool:
        """Whether any packet of this sensor arrived on this link (a record or a reply)."""
        return self._replied or self.records > 0

    def set_streamed(self, code: int | None) -> None:
        """Say which record the device streams from now on (None: none), for :meth:`on_data`."""
        self._streamed = code
        self.reader.streams(self, code)

    # -- the reader thread's side --------------------------------------------

    def on_data(self, event: DataPacket, now: float, mono: float) -> None:
        """
        Take one data packet of this sensor (reader thread, for every sample).

        The one rule that tells them apart (docs/architecture.md, change 3):
        a packet of the waiting request's code is its reply; while a stream
        runs, a packet of its code is a record of it (a polled reply of that
        code is both), and only those keep it alive; while none runs, any
        record that is no reply says the sensor still streams. What is no
        reply reaches the consumer if it is of ``LinkOptions.records_of``,
        else it is counted in :attr:`other_records`. Those who wait for the
        stream read :attr:`records` and :attr:`last_data_mono` instead of
        comparing codes. Allocates nothing, takes no lock.
        """
        code = event.code
        streamed = self._streamed
        # While a stream runs, only its records keep it alive: a sensor power-cycled
        # into its EEPROM auto-start streams another record, and the stall watch
        # and the wait for the stream must not take that one for it (found by the
        # long soak).
        ours = streamed is None or code == streamed
        if ours:
            self.last_data_mono = mono
        lqi = event.lqi
        if lqi is not None:
            # RadioMeter.note's counts, here: one call less a record.
            radio, rssi = self.radio.counts, event.rssi
            radio[0], radio[1] = lqi, rssi
            radio[2] = min(radio[2], lqi)
            radio[3] = min(radio[3], rssi)
            radio[4] += lqi
            radio[5] += rssi
            radio[6] += 1
        pending = self._pending
        if pending is not None and pending.code == code:
            pending.fulfil(event.record)
            self._replied = True
            if code != streamed:
                return
        if ours:
            self.records += 1
        self.last_code = code
        records_of = self._records_of
        if records_of is None or code == records_of:
            self._on_record(event, now, mono)
        else:
            self.other_records += 1

    def answer(self, event: Any) -> None:
        """Take the base station's answer to this link's request (ACK, NACK, ping)."""
        pending = self._pending
        if pending is None:
            return
        if isinstance(event, Ack):
            pending.acked.set()
        elif isinstance(event, Nack):
            pending.nacked.set()
        elif isinstance(event, PingReply) and pending.code == layouts.PING:
            pending.fulfil(event)

    def reader_started(self, outcome: PolicyOutcome) -> None:
        """Take the news that the reader reads for this link now, with what it was granted."""
        self.policy_outcome = outcome
        self.running.set()

    def port_lost(self, error: str) -> None:
        """Take the news that the port is gone (``error`` says why): wake a waiting request."""
        self.error = error
        self._wake()
        if self._on_lost is not None:
            self._on_lost()

    def _wake(self) -> None:
        pending = self._pending
        if pending is not None:
            pending.done.set()

    # -- starting and stopping -----------------------------------------------

    def start(self) -> None:
        """Start receiving: the reader thread, or this address's route on the shared one."""
        if self.shared:
            self.reader.route(self.address, self)
        self.reader.start()

    def stop(self) -> None:
        """Stop receiving: the reader thread (waited for), or this address's route."""
        self._stopped.set()
        if self.shared:
            self.reader.unroute(self.address, self)
            self._wake()
        else:
            self.reader.stop()

    def abort(self) -> None:
        """Make the reader (if the link's own) and any waiting request give up."""
        self._stopped.set()
        if not self.shared:
            self.reader.abort()
        self._wake()

    def flush_input(self) -> None:
        """Drop what the port holds unread; not on a shared port (the others' packets)."""
        if not self.shared:
            self.port.flush_input()

    # -- requests ------------------------------------------------------------

    def send(self, command: bytes) -> None:
        """Write one command, framed for the link; no waiting."""
        data = encode_command_packet(self.address, command) if self.wireless else command
        self.reader.write(data)

    def request(self, command: bytes, reply_code: int | None,
                timeout: float = timeouts.REQUEST_TIMEOUT,
                retries: int = timeouts.REQUEST_RETRIES) -> Any:
        """
        Send ``command`` until its reply (a record of ``reply_code``) arrives.

        Returns the reply record. A NACK resends at once; silence resends
        after ``timeout``. Raises DeviceTimeout (DeviceNack if every try was
        rejected) after ``retries`` tries, PortDisconnected if the port died.
        """
        with self._lock:
            nacks = 0
            for _ in range(retries):
                self._check_cancelled()
                with self._awaiting(reply_code) as pending:
                    self._exchange(command, pending, timeout)
                if pending.done.is_set():
                    return pending.reply
                if pending.nacked.is_set():
                    nacks += 1
            name = layouts.LAYOUTS[command[0]].name
            if nacks == retries:
                raise DeviceNack(f'{name}: the base station rejected it {retries} times')
            raise DeviceTimeout(f'{name}: no reply after {retries} tries')

    @contextlib.contextmanager
    def _awaiting(self, code: int | None) -> Iterator[Pending]:
        """Wait for a reply of ``code``; then raise if the port died or it was cancelled."""
        pending = self._pending = Pending(code)
        try:
            with self.reader.awaiting_answer():
                yield pending
        finally:
            self._pending = None
        self.check_port()
        self._check_cancelled()

    def _exchange(self, command: bytes, pending: Pending, timeout: float) -> None:
        """
        Send ``command`` and wait for its reply, holding the port; a shared one until the ACK.

        On a shared port the reply is a data packet with this sensor's address,
        routed to this link whoever else streams or asks meanwhile; only the
        base station's one-byte answer must not be mistaken for another
        sensor's, so the port is held until the ACK or NACK alone.
        """
        deadline = time.monotonic() + timeout
        with self.reader.holding(self):
            self.send(command)
            if not self.shared:
                self._wait(pending, timeout)
                return
            self._wait(pending, min(timeouts.ACK_TIMEOUT, timeout), until=pending.acked,
                       step=timeouts.ACK_LOOK_S)
        if not pending.nacked.is_set():
            self._wait(pending, deadline - time.monotonic())

    def _wait(self, pending: Pending, timeout: float, nack_ends: bool = True,
              until: threading.Event | None = None, step: float = timeouts.REPLY_LOOK_S) -> None:
        """Wait for a reply (or ``until``), a NACK (if ``nack_ends``), a cancel or the timeout."""
        until = until or pending.done
        deadline = time.monotonic() + timeout
        while not ((nack_ends and pending.nacked.is_set()) or pending.done.is_set()
                   or self._cancel.is_set()):
            left = deadline - time.monotonic()
            if left <= 0 or until.wait(min(left, step)):
                break

    def check_port(self) -> None:
        """Raise PortDisconnected if the port is lost (the reader tells each link first)."""
        if self.error is not None or self.disconnected.is_set():
            raise PortDisconnected(self.error or 'device disconnected')

    def _check_cancelled(self) -> None:
        if self._stopped.is_set() or self.reader.stopping:
            raise RequestCancelled('the link is shutting down')
        if self._cancel.is_set():
            raise RequestCancelled('cancelled: the stream is being stopped')

    def ping_once(self, address: int, timeout: float) -> bool | None:
        """
        Ping ``address`` once: True (link OK), False (0x21: no such node).

        None means no answer at all, which a base station never gives: a
        wired sensor, or nothing, is on the port (what discovery needs to
        tell apart from a node that is not there).
        """
        parser = self.parser
        with self._lock, self.reader.holding(self):
            for _ in range(2):
                skipped = parser.stats.bytes_skipped
                with self._awaiting(layouts.PING) as pending:
                    parser.expect_ping()
                    self.reader.write(commands.ping(address))
                    self._wait(pending, timeout, nack_ends=False)
                # The answer is one byte, 0x02 or 0x21, found between frames. While
                # the parser skips garbage (the tail of another node's packet cut by
                # a flush) a byte of that garbage can pass for it; the parser is in
                # step with the stream after it, so a second ping is trustworthy.
                if pending.reply is None or parser.stats.bytes_skipped == skipped:
                    break
            return None if pending.reply is None else bool(pending.reply.ok)

    def retarget(self, address: int | None) -> None:
        """
        Speak to another node behind the same base station from now on.

        For discovery, which visits several nodes over one open port. None
        accepts data packets from every node (listening for sensors that
        already stream); requests need an address again before they are sent.
        """
        self.address = address
        if self.reader.wireless:  # the parser takes that address's packets alone (None: all)
            self.parser.listen_to(address)
