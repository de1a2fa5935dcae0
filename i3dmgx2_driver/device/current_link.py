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
The one open link of a supervisor, and what outlives each link.

The supervisor thread opens links; a lifecycle phase or a stop on another
thread may close the current one at any moment, even while a new one is
being opened. :class:`CurrentLink` decides who owns it, under its lock, and
closes a link opened after the driver was told to stop at once. Every link
is made the same way (its line observer, the cancel event, the reader
thread's scheduling, whom it tells of a lost port); what outlives a link is
kept here: how many were opened, the parser counters and the records that
were not the stream's summed over all of them, what the port granted of
low-latency mode. What to do with the link is the supervisor's.
"""

from collections import Counter
from collections.abc import Callable
import contextlib
import threading
from typing import Any

from . import timeouts
from .link import DeviceLink, RecordCallback
from .observer import Finding, LineObserver
from .port import PortDisconnected, PortError
from .sensor_steps import say_stop
from .settings import DeviceConfig
from .shared_port import PortOpener, SharedPort


class CurrentLink:
    """
    Open, hold and release the links to one sensor, one at a time.

    ``on_record`` is every link's consumer; ``cancel`` the supervisor's
    event (read only: a link opened while it is set is closed at once);
    ``on_lost`` is told when a link's port is lost; ``on_finding`` takes
    what the line observer finds. ``shared``: the port several sensors share
    (its links come from it and go back to it; no line observer watches it).
    """

    def __init__(self, config: DeviceConfig, opener: PortOpener, on_record: RecordCallback,
                 cancel: threading.Event, on_lost: Callable[[], None],
                 on_finding: Callable[[Finding], None], shared: SharedPort | None = None) -> None:
        self._config, self._opener, self._shared = config, opener, shared
        self._on_record, self._on_lost, self._on_finding = on_record, on_lost, on_finding
        self._cancel = cancel
        self._link: DeviceLink | None = None
        #: Guards who owns ``_link``: the thread opening one, or a caller releasing it.
        self._lock = threading.Lock()
        self._observer: LineObserver | None = None
        #: Links opened so far (all but the first were reconnections).
        self.connections = 0
        self._parser_totals: Counter[str] = Counter()
        #: Records of closed links that were neither a reply nor of the stream.
        self._other_records = 0

    @property
    def link(self) -> DeviceLink | None:
        """Return the current link, or None while disconnected."""
        return self._link

    def open_link(self) -> DeviceLink:
        """Open the port and make it the current link (reader not started); raise PortError."""
        cfg = self._config
        if self._shared is not None:
            return self._own(self._shared.attach(cfg.address, self._on_record, self._cancel,
                                                 cfg.stream, self._on_lost))
        port = self._opener.open_port()
        observer = self._observer = LineObserver(cfg.port, cfg.address, cfg.wireless,
                                                 cfg.baud, self._on_finding)
        options = self._opener.reader_options(observer, self._cancel, cfg.stream, self._on_lost)
        return self._own(DeviceLink(port, cfg.address, self._on_record, options))

    def _own(self, link: DeviceLink) -> DeviceLink:
        """Make ``link`` the current one, unless the driver was told to stop meanwhile."""
        with self._lock:
            if self._cancel.is_set():
                # Stopped while opening: the caller has released the link already.
                self._close(link)
                raise PortDisconnected(f'{self._config.port}: closed, the driver is stopping')
            self._link = link
        self.connections += 1
        return link

    def release(self, send_stop: bool = False) -> None:
        """Close the current link, if any (once, whichever thread gets here first)."""
        with self._lock:
            link, self._link = self._link, None
        if link is None:
            return
        link.stop()
        if send_stop:
            with contextlib.suppress(PortError):
                say_stop(link, timeouts.STOP_REPEATS_AT_EXIT, timeouts.STOP_GAP_AT_EXIT_S)
        self._close(link)
        self._other_records += link.other_records
        if self._shared is None:
            self._parser_totals.update(link.parser.stats.as_dict())

    def _close(self, link: DeviceLink) -> None:
        """Close the link's port, or hand the link back to the shared one."""
        if self._shared is not None:
            self._shared.detach(link)
        else:
            link.port.close()

    def totals(self) -> dict[str, Any]:
        """
        Return what the status says of the links so far (from any thread).

        The parser counters summed over every connection (shared: the open
        port's), the records neither a reply nor of the stream, the packets
        of addresses no sensor on a shared port has, the radio of the link.
        """
        link, shared = self._link, self._shared
        # What the port last granted this sensor's links (a shared one: at its last open).
        granted = (shared or self._opener).low_latency_state if self.connections else ''
        parser = shared.parser_stats() if shared is not None else Counter(self._parser_totals)
        if shared is None and link is not None:
            parser.update(link.parser.stats.as_dict())
        return {'parser': dict(parser), 'strays': shared.strays() if shared is not None else {},
                'other_records': self._other_records + (link.other_records if link else 0),
                'radio': link.radio.stats if link else None, 'connected': link is not None,
                'connections': self.connections, 'reconnects': max(self.connections - 1, 0),
                'low_latency_state': granted}

    def observe(self, on: bool) -> None:
        """Resume or pause the line observer: silence is a symptom only while we ask."""
        observer = self._observer
        if observer is not None:
            (observer.resume if on else observer.pause)()

    def observed(self) -> str:
        """Say what the line observer last found on this link ('' if nothing)."""
        seen = self._observer.last_finding if self._observer is not None else None
        return seen.message if seen is not None else ''
