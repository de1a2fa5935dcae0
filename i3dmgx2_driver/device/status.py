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
What the device side is doing, as one immutable snapshot.

Diagnostics and services run in executor threads while the supervisor and
the reader change the device's state in theirs. Rather than reading a dozen
attributes across threads (and catching them half-way through a change),
they ask the supervisor for a :class:`DeviceStatus`, made in one place
(:meth:`~.supervisor.DeviceSupervisor.status`), and read that.
"""

import dataclasses
import enum

from .identity import DeviceInfo
from .link import RadioStats


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
