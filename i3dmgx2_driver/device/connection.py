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
The one open link to the device, whichever thread opens or closes it.

The recovery thread opens links; a lifecycle phase or :meth:`stop` on
another thread may close the current one at any moment, even while a new
one is being opened. :class:`Connection` makes both safe (a lock decides
who owns the link, and a link opened after the driver was told to stop is
closed at once), makes every link the same way (its line observer, its
cancel event, the reader thread's scheduling) and keeps what outlives a
link: how many were opened, the parser counters summed over all of them,
what the port granted of low-latency mode and the reader of its scheduling
(each logged when it changes, not at every reconnect).
"""

from collections.abc import Callable
import threading
from typing import Any

from .link import DeviceLink, RecordCallback
from .observer import Finding, LineObserver
from .port import PortDisconnected, PortError
from .port_opener import PortOpener, PortParts
from .realtime import PolicyOutcome
from .settings import DeviceConfig
from .shared_port import SharedPort


class Connection:
    """
    Open, hold and close the link to the device at ``config.port``.

    ``parts`` open the port and are handed to every link's reader (the raw
    capture and the hot-path observer run in its thread, port_opener.py);
    ``on_record`` is handed to every link too; ``on_finding`` receives what
    the line observer finds; ``cancel`` set means no stream is wanted now
    (every request on the link gives up, and a link opened meanwhile is
    closed at once). ``shared``, if given, is the port several sensors
    share (shared_port.py): the links come from it and go back to it, the
    port is its to open and close, and no line observer watches it.
    """

    def __init__(self, config: DeviceConfig, log: Any, parts: PortParts,
                 on_record: RecordCallback, on_finding: Callable[[Finding], None],
                 cancel: threading.Event, shared: SharedPort | None = None) -> None:
        self.config = config
        self._shared = shared
        self._opener = PortOpener(config, log, parts)
        self._log = log
        self._on_record = on_record
        self._on_finding = on_finding
        self._cancel = cancel
        self._link: DeviceLink | None = None
        #: Guards who owns ``_link``: the thread opening one, or a caller releasing it.
        self._lock = threading.Lock()
        self._observer: LineObserver | None = None
        self._policy_logged = PolicyOutcome()
        #: Links opened so far, and how many of them were reconnections.
        self.connections = 0
        self.reconnects = 0
        self.low_latency_state = ''
        self._parser_totals: dict[str, int] = {}

    @property
    def link(self) -> DeviceLink | None:
        """Return the current link, or None while disconnected."""
        return self._link

    def lost(self) -> bool:
        """Whether there is no usable link: none open, or its port gone."""
        link = self._link
        return link is None or link.disconnected.is_set()

    def open_link(self) -> DeviceLink:
        """Open the port and make it the current link (reader not started); raise PortError."""
        cfg = self.config
        if self._shared is not None:
            link = self._shared.attach(cfg.address, self._on_record, self._cancel)
            self.low_latency_state = self._shared.low_latency_state
            return self._own(link)
        port = self._opener.open_port()
        self.low_latency_state = self._opener.low_latency_state
        observer = self._observer = LineObserver(cfg.port, cfg.address, cfg.wireless,
                                                 cfg.baud, self._on_finding)
        link = DeviceLink(port, cfg.address, self._on_record,
                          self._opener.reader_options(observer, self._cancel))
        return self._own(link)

    def _own(self, link: DeviceLink) -> DeviceLink:
        """Make ``link`` the current one, unless the driver was told to stop meanwhile."""
        cfg = self.config
        with self._lock:
            if self._cancel.is_set():
                # Stopped while opening: the caller has released the link already.
                self._close(link)
                raise PortDisconnected(f'{cfg.port}: closed, the driver is stopping')
            self._link = link
        self.connections += 1
        if self.connections > 1:
            self.reconnects += 1
        return link

    def start_reader(self, link: DeviceLink) -> None:
        """Start the link's reader thread; log what its scheduling became, when that changes."""
        link.start()
        if not link.running.wait(1.0):
            return
        outcome = link.policy_outcome
        if outcome != self._policy_logged:
            self._policy_logged = outcome
            if outcome.applied:
                self._log.info(f'reader thread: {", ".join(outcome.applied)}')
            for refusal in outcome.refused:
                self._log.warning(refusal)

    def release(self, send_stop: bool = False) -> None:
        """Close the current link, if any (once, whichever thread gets here first)."""
        with self._lock:
            link, self._link = self._link, None
        if link is None:
            return
        link.stop()
        if send_stop:
            try:
                link.stop_streaming(repeats=2, gap=0.01)
            except PortError:
                pass
        self._close(link)
        if self._shared is None:
            for key, value in link.parser.stats.as_dict().items():
                self._parser_totals[key] = self._parser_totals.get(key, 0) + value

    def _close(self, link: DeviceLink) -> None:
        """Close the link's port, or hand the link back to the shared one."""
        if self._shared is not None:
            self._shared.detach(link)
        else:
            link.port.close()

    def abort(self) -> None:
        """Make the current link's reader and any waiting request give up (shutdown)."""
        link = self._link
        if link is not None:
            link.abort()

    def parser_stats(self) -> dict[str, int]:
        """Parser counters summed over every connection so far (shared: the open port's)."""
        if self._shared is not None:
            return self._shared.parser_stats()
        totals = dict(self._parser_totals)
        link = self._link
        if link is not None:
            for key, value in link.parser.stats.as_dict().items():
                totals[key] = totals.get(key, 0) + value
        return totals

    def strays(self) -> dict[int, int]:
        """Packets of addresses no sensor on a shared port has, by address (else empty)."""
        return self._shared.strays() if self._shared is not None else {}

    def observe(self, on: bool) -> None:
        """Resume or pause the line observer: silence is a symptom only while we ask."""
        observer = self._observer
        if observer is not None:
            if on:
                observer.resume()
            else:
                observer.pause()

    def observed(self) -> str:
        """Say what the line observer last found on this link ('' if nothing)."""
        seen = self._observer.last_finding if self._observer is not None else None
        return seen.message if seen is not None else ''
