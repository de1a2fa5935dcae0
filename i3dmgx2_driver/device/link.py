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
One connection to one sensor: what the other layers hold and call.

:class:`DeviceLink` puts together the pieces of a sensor's connection,
each in a module of its own: the reader thread (``port_reader.py``,
:class:`~.port_reader.PortReader`, its own or a port's that several sensors
share), the request/reply exchange (``exchange.py``), the stream's
bookkeeping the reader hands each data packet to (``stream_watch.py``) and
the radio's link quality (``radio.py``). It owns no behaviour of its own but
starting and stopping: a change to one of those belongs in its module.
"""

import threading
from typing import Any

from .exchange import DeviceNack, DeviceTimeout, Exchange
from .port import SerialPort
from .port_reader import BytesCallback, LinkOptions, PortReader, RecordCallback
from .radio import RadioQuality, RadioStats
from .realtime import PolicyOutcome
from .stream_watch import StreamWatch
from ..forwarding import Forwarded

__all__ = ['BytesCallback', 'DeviceLink', 'DeviceNack', 'DeviceTimeout', 'LinkOptions',
           'PortReader', 'RadioStats', 'RecordCallback']


class DeviceLink:
    """
    The exchanges with one sensor over an open port, and its records.

    ``address`` selects the sensor behind a base station; ``on_record``
    receives every data packet not claimed by a pending request; ``options``
    say how to read and whom else to tell (:class:`LinkOptions`).
    ``streamed`` is the command byte of the record being streamed, None
    while the device is not streaming (the dialogue sets it): a polled
    reply of that code is then both the reply and a record of the stream.
    ``policy_outcome`` says what the scheduler granted the reader thread.

    Alone on its port (``reader`` None) the link makes its own
    :class:`PortReader` and starts and stops it. Given a ``reader`` that
    several sensors share, it only joins it: :meth:`start` routes its
    address to it, :meth:`stop` takes that route away, and the port, its
    reader and flushes belong to whoever shares it (shared_port.py).
    """

    def __init__(self, port: SerialPort, address: int | None, on_record: RecordCallback,
                 options: LinkOptions | None = None, reader: PortReader | None = None) -> None:
        options = options if options is not None else LinkOptions()
        self.port = port
        self.wireless = options.wireless
        self.shared = reader is not None
        if reader is None:
            reader = PortReader(port, address, options)
        self.reader = reader
        self.parser = reader.parser
        cancel = options.cancel if options.cancel is not None else threading.Event()
        self.exchange = Exchange(port, address, reader, cancel, self.shared)
        self._radio = RadioQuality()
        self.watch = StreamWatch(on_record, self.exchange, self._radio)
        if not self.shared:
            reader.fallback = self.watch
        self.disconnected = reader.disconnected
        #: Set once the link receives its packets (its own reader runs, or its
        #: address is routed on the shared one).
        self.running = reader.running if not self.shared else threading.Event()

    # -- what the pieces know ------------------------------------------------

    address: 'int | None' = Forwarded(
        'exchange', 'The node address requests go to (:meth:`retarget` changes it).')

    streamed: 'int | None' = Forwarded(
        'watch', 'The command byte of the record being streamed, or None while none is.',
        writable=True)

    records: 'int' = Forwarded('watch', 'The records of the stream received so far.')

    replies: 'int' = Forwarded('watch', "The replies to this link's requests received so far.")

    last_code: 'int | None' = Forwarded(
        'watch', 'The command byte of the last record handed on (None before one).')

    last_data_time: 'float' = Forwarded(
        'watch', 'The system-clock time the stream was last heard.')

    last_data_mono: 'float' = Forwarded(
        'watch', 'The same instant on the monotonic clock, for stall detection.')

    @property
    def heard(self) -> bool:
        """Whether any packet of this sensor arrived on this link (a record or a reply)."""
        return bool(self.watch.records or self.watch.replies)

    radio: 'RadioStats | None' = Forwarded(
        '_radio', 'Radio link quality so far, or None before the first packet.', 'stats')

    error: 'str | None' = Forwarded('reader', 'Why the port was lost (None while it works).')

    policy_outcome: 'PolicyOutcome' = Forwarded(
        'reader', 'What the scheduler granted the reader thread.')

    # -- reader thread -------------------------------------------------------

    def start(self) -> None:
        """Start receiving: the reader thread, or this address's route on the shared one."""
        reader = self.reader
        if self.shared:
            reader.routes[self.address] = self.watch
            reader.start()
            if reader.running.wait(1.0):
                self.running.set()
        else:
            reader.start()

    def stop(self) -> None:
        """Stop receiving: the reader thread (waited for), or this address's route."""
        self.exchange.stopped.set()
        if self.shared:
            if self.reader.routes.get(self.address) is self.watch:
                del self.reader.routes[self.address]
            self.exchange.wake()
        else:
            self.reader.stop()

    def abort(self) -> None:
        """Make the reader (if the link's own) and any waiting request give up."""
        self.exchange.stopped.set()
        if not self.shared:
            self.reader.abort()
        self.exchange.wake()

    def _run(self) -> None:
        """Read in the calling thread (tests); the link's own reader only."""
        self.reader._run()

    def flush_input(self) -> None:
        """Drop what the port holds unread; not on a shared port (the others' packets)."""
        if not self.shared:
            self.port.flush_input()

    # -- requests (exchange.py) ------------------------------------------------

    def send(self, command: bytes) -> None:
        """Write one command, framed for the link; no waiting."""
        self.exchange.send(command)

    def request(self, command: bytes, reply_code: int | None, timeout: float = 0.5,
                retries: int = 3) -> Any:
        """Send ``command`` until its reply arrives (:meth:`.Exchange.request`)."""
        return self.exchange.request(command, reply_code, timeout, retries)

    def ping(self, timeout: float = 0.5, retries: int = 3) -> bool:
        """Ask the base station whether the sensor answers over the radio."""
        return self.exchange.ping(timeout, retries)

    def ping_once(self, address: int, timeout: float) -> bool | None:
        """Ping ``address`` once (:meth:`.Exchange.ping_once`): True, False or None."""
        return self.exchange.ping_once(address, timeout)

    def stop_streaming(self, repeats: int = 3, gap: float = 0.02) -> None:
        """Send 0xFA several times: it has no reply and the radio may drop it."""
        self.exchange.stop_streaming(repeats, gap)

    def retarget(self, address: int | None) -> None:
        """
        Speak to another node behind the same base station from now on.

        For discovery, which visits several nodes over one open port. None
        accepts data packets from every node (listening for sensors that
        already stream); requests need an address again before they are sent.
        """
        self.exchange.address = address
        if self.wireless:
            self.parser.address = address
