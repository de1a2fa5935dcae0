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
What the device side is doing: the state and counters, and their one snapshot.

The supervisor thread, the lifecycle phases, the reader thread (through the
line observer) and a service's exclusive operation all change what
diagnostics show: the state, the counters, the last problem said. Each such
change is one method of :class:`DeviceReport`, so that every rule about it
lives here: the device is declared streaming in one place only
(:meth:`~DeviceReport.streaming`), a problem is logged once per key and
period and kept as the last error (:meth:`~DeviceReport.warn`), and what
the observer found is forgotten once records flow.

Diagnostics and services run in executor threads while the supervisor and
the reader change the device's state in theirs. Rather than reading a dozen
attributes across threads (and catching them half-way through a change),
they ask the supervisor for a :class:`DeviceStatus`, made in one place
(:meth:`~.supervisor.DeviceSupervisor.status`) from the report's fields
(taken under its lock), and read that. Its field types (``State``,
``RadioStats``, ``DeviceInfo``) are named from here for its readers.
"""

import dataclasses
import enum
import threading
from typing import Any

from .identity import DeviceInfo
from .link import RadioStats
from .observer import Finding
from .port import PortError
from .throttle import Throttle

__all__ = ['DeviceInfo', 'DeviceReport', 'DeviceStatus', 'RadioStats', 'State']


class State(str, enum.Enum):
    """What the supervisor is doing, for logs and diagnostics."""

    CONNECTING = 'connecting'
    INITIALISING = 'initialising'
    #: Port open and the device quiet, not streaming (a managed node, inactive).
    READY = 'ready'
    STREAMING = 'streaming'
    STALLED = 'stalled'
    PAUSED = 'paused'
    DISCONNECTED = 'disconnected'
    STOPPED = 'stopped'


@dataclasses.dataclass(frozen=True)
class DeviceStatus:
    """The device side at one moment: connection, identity, rate, line and radio."""

    state: State = State.CONNECTING
    #: The port, the sensor's address and whether it is wireless, as configured.
    port: str = ''
    address: int = 0
    wireless: bool = True
    #: Links opened so far, and how many of them were reconnections.
    connections: int = 0
    reconnects: int = 0
    stalls: int = 0
    #: The last problem said (a warning's text), '' if none yet.
    last_error: str = ''
    #: What the port accepted of low-latency mode ('' before the first open).
    low_latency_state: str = ''
    #: Whether the base station's ping of the node was answered (None: not asked).
    ping_ok: bool | None = None
    #: What the line observer last found while nothing of ours arrived ('' once records flow).
    advice: str = ''
    #: Why the port can never work, once found ('' otherwise).
    fatal_error: str = ''
    #: The device's identity, once read.
    info: DeviceInfo | None = None
    #: The data-rate divider found or set, and the rate it gives (Hz), once known.
    divider: int | None = None
    expected_rate_hz: float | None = None
    #: EEPROM write commands sent to the sensor so far (the divider; 0 when it was right).
    eeprom_writes: int = 0
    #: The stream's use of the line at that rate, and what to do when it does not fit.
    line_use: str = ''
    line_warning: str = ''
    #: How the last connection got streaming ('full', 'resumed'), and resumes so far.
    last_start: str = ''
    resumes: int = 0
    #: Parser counters summed over every connection so far.
    parser: dict[str, int] = dataclasses.field(default_factory=dict)
    #: The radio's LQI/RSSI of the current link (None: none yet or wired).
    radio: RadioStats | None = None
    #: Whether a link is open now.
    connected: bool = False
    #: On a port several sensors share: packets of addresses none of them has, by address.
    strays: dict[int, int] = dataclasses.field(default_factory=dict)
    #: Records of this sensor that were neither a reply nor of the stream, over every
    #: connection so far (the link decides which: link.py's ``set_streamed``).
    other_records: int = 0


class DeviceReport:
    """
    The device side's state and counters, and the one way to change each.

    ``log`` has ``debug/info/warning/error``. Any thread may call any
    method; :meth:`fields` returns them all at one moment.
    """

    def __init__(self, log: Any) -> None:
        self.log = log
        self._throttle = Throttle()
        self._lock = threading.Lock()
        self.state = State.CONNECTING
        self.stalls = 0
        #: The last problem said (a warning's text), '' if none yet; what the line
        #: observer last found while nothing of ours arrived ('' once records flow), for
        #: diagnostics; why the port can never work (a path that is no serial port).
        self.last_error = self.advice = self.fatal_error = ''
        #: How the last connection got streaming: 'full' (the whole dialogue) or 'resumed'.
        self.last_start, self.resumes = '', 0

    def enter(self, state: State) -> None:
        """Say what the supervisor does now (never STREAMING: see :meth:`streaming`)."""
        if state is State.STREAMING:
            raise ValueError('streaming is declared by streaming(), once a record arrived')
        self.state = state

    def streaming(self, start: str = '') -> None:
        """
        Declare the device streaming: call only once a record has arrived on this link.

        ``start`` says how a new connection got there ('full' or 'resumed');
        '' for a stream taken up again on the same link (after a stall or an
        exclusive operation). What the observer found is past.
        """
        with self._lock:
            self.state = State.STREAMING
            self.advice = ''
            self.last_start = start or self.last_start
            self.resumes += start == 'resumed'

    def stalled(self) -> None:
        """Count a stall: no record for longer than the stall timeout."""
        with self._lock:
            self.stalls += 1
            self.state = State.STALLED

    def records_flow(self) -> None:
        """Forget what the observer found: records flow again."""
        self.advice = ''

    def warn(self, key: str, message: str, period: float | None = None) -> None:
        """Log ``message`` once, then again at most every ``period`` s (a reminder)."""
        self.last_error = message
        if self._throttle.allow(key, period):
            self.log.warning(message)

    def finding(self, finding: Finding) -> None:
        """Report what the line observer found (reader thread; never blocks long)."""
        self.advice = finding.message
        self.warn(f'observed {finding.kind}', finding.message)

    def failed(self, error: PortError) -> None:
        """Keep why the port can never work; the supervisor stops."""
        with self._lock:
            self.fatal_error = self.last_error = str(error)
            self.state = State.STOPPED

    def fields(self) -> dict[str, Any]:
        """Return the report's fields at one moment, named as in DeviceStatus."""
        with self._lock:
            return {name: getattr(self, name) for name in (
                'state', 'stalls', 'last_error', 'advice', 'last_start', 'resumes', 'fatal_error')}
