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
How a sensor's port is opened, and one port with one reader shared by several sensors.

A connection that opens its own port and the port several sensors share open
it the same way: the configured path, baud rate and low-latency mode, the
low-latency mode logged when it changes, and the reader made with the same
raw capture and scheduling. :class:`PortOpener` does it, once for both;
:class:`SharedPort` is the one that shares.

The node opens the port exclusively, as it must: two readers would split the
byte stream. With several sensors behind one base station, each sensor still
has its own supervisor (dialogue, thread, reconnects, counters); what
they share is this: :class:`SharedPort` opens the port when the first
sensor's supervisor asks for a link, gives every sensor a
:class:`~.link.DeviceLink` of its own on the one
:class:`~.link.PortReader` (which routes each data packet to the link of its
address), and closes the port when the last link is handed back.

An unplug is seen by every link at once (they share the reader's
``disconnected``): each sensor's supervisor thread hands its link back and asks
for a new one, and the first to ask opens the port again, the others join
it; the dead reader is closed then, whoever still held it. So the port-level
recovery stops all sensors and brings all back, and a sensor switched off
costs the others nothing but the time its requests hold the port.
"""

from collections.abc import Callable
import threading
from typing import Any

from .link import BytesCallback, DeviceLink, LinkOptions, PortReader, RecordCallback
from .observer import LineObserver
from .port import SerialPort
from .settings import DeviceConfig
from ..codec import streams


class PortOpener:
    """
    Open the port at ``config.port``; log a change of its low-latency mode.

    ``on_bytes``, if given, receives every read's raw bytes (a raw capture)
    from the reader of each port opened.
    """

    def __init__(self, config: DeviceConfig, log: Any,
                 on_bytes: BytesCallback | None = None) -> None:
        self.config = config
        self._on_bytes = on_bytes
        self._log = log
        #: What the last port opened granted of low-latency mode ('' before one).
        self.low_latency_state = ''

    def open_port(self) -> SerialPort:
        """Open the port (raises PortError); log a new low-latency mode."""
        cfg = self.config
        port = SerialPort(cfg.port, cfg.baud, low_latency=cfg.low_latency)
        if port.low_latency_state != self.low_latency_state:
            self.low_latency_state = port.low_latency_state
            self._log.info(f'{cfg.port}: low-latency mode {port.low_latency_state}')
        return port

    def reader_options(self, observer: LineObserver | None = None,
                       cancel: threading.Event | None = None, records_of: int | None = None,
                       on_lost: Callable[[], None] | None = None) -> LinkOptions:
        """Return how the port's reader reads, whom it tells, what its link's consumer takes."""
        return LinkOptions(wireless=self.config.wireless, on_bytes=self._on_bytes,
                           observer=observer, cancel=cancel, records_of=records_of,
                           thread_policy=self.config.thread_policy, on_lost=on_lost)


class SharedPort(PortOpener):
    """
    The port at ``config.port``, shared by the sensors behind its base station.

    ``on_bytes`` (a raw capture) belongs to the port's one reader.
    """

    def __init__(self, config: DeviceConfig, log: Any,
                 on_bytes: BytesCallback | None = None) -> None:
        super().__init__(config, log, on_bytes)
        self._lock = threading.Lock()
        #: The reader of the open port (None while closed); only this class sets it.
        self.reader: PortReader | None = None
        self._links: set[DeviceLink] = set()
        #: Each sensor's stream and the rate its device runs at, once known.
        self._streams: dict[int, tuple[int, float]] = {}
        self._warned = ''
        #: Times the port was opened.
        self.opens = 0

    def attach(self, address: int, on_record: RecordCallback,
               cancel: threading.Event, records_of: int | None = None,
               on_lost: Callable[[], None] | None = None) -> DeviceLink:
        """
        Return a new link to the sensor at ``address``, opening the port if need be.

        ``on_record`` takes the records of ``records_of`` (the sensor's stream);
        ``on_lost`` is told when the port is lost (LinkOptions).

        The link receives nothing until it is started (its address routed).
        Raises PortError when the port cannot be opened.
        """
        with self._lock:
            reader = self.reader
            if reader is None or reader.disconnected.is_set():
                if reader is not None:
                    self._close(reader)
                reader = self.reader = PortReader(self.open_port(), None, self.reader_options())
                self.opens += 1
            options = self.reader_options(cancel=cancel, records_of=records_of, on_lost=on_lost)
            link = DeviceLink(reader.port, address, on_record, options, reader=reader)
            self._links.add(link)
            return link

    def detach(self, link: DeviceLink) -> None:
        """Take ``link`` off its reader; close the port once no link is left on it."""
        link.stop()
        with self._lock:
            self._links.discard(link)
            reader = link.reader
            if any(other.reader is reader for other in self._links):
                return
            self._close(reader)
            if reader is self.reader:
                self.reader = None

    def line_warning(self, address: int, code: int, rate_hz: float) -> str:
        """
        Note a sensor's stream and rate; say if the sensors' streams together overflow the line.

        The parameters were checked against the line before the start, but a
        sensor left at its device's rate (``data_rate`` 0) is known only once
        connected: the base station would then drop the packets the line
        cannot carry. Returns '' while they fit (or one sensor is known); the
        first time they do not, it is also logged.
        """
        self._streams[address] = (code, rate_hz)
        if len(self._streams) < 2:
            return ''
        baud, wireless = self.config.baud, self.config.wireless
        chosen = [(a, streams.BY_CODE[c], r) for a, (c, r) in sorted(self._streams.items())]
        if streams.shared_line_fits([(st, r) for _, st, r in chosen], baud, wireless):
            return ''
        text = ('the sensors on this port are set to rates the line cannot carry together, '
                'records will be skipped: ' + streams.shared_advice(chosen, baud, wireless))
        if text != self._warned:
            self._warned = text
            self._log.warning(text)
        return text

    def parser_stats(self) -> dict[str, int]:
        """Return the counters of the open port's parser (empty while closed)."""
        reader = self.reader
        return reader.parser.stats.as_dict() if reader is not None else {}

    def strays(self) -> dict[int, int]:
        """Return the packets of unlisted addresses on the open port, by address."""
        reader = self.reader
        return dict(reader.strays) if reader is not None else {}

    @staticmethod
    def _close(reader: PortReader) -> None:
        reader.stop()
        reader.port.close()
