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
The round trips a bring-up measures, and the driver's timeouts each is held against.

The round trips: a ping, a short command, continuous mode's start and stop,
the gap between records. Each is timed (bringup.py's ``Bringup``) with
:data:`MEASURE_TIMEOUT`, far beyond the driver's own timeouts, so that a slow
round trip is measured rather than counted lost; the longest of each kind
(:func:`note_longest`) is held against the timeouts of device/timeouts.py
(:func:`close_calls`).
"""

from collections.abc import Sequence
import statistics
from typing import NamedTuple

from ..codec import layouts
from ..device import timeouts
from ..ros.parameter_table import SPECS

#: How long a single measured exchange may take (s): far beyond every timeout the
#: driver uses, so that a slow round trip is measured rather than counted lost.
MEASURE_TIMEOUT = 2.0
#: The short command whose round trip is measured: the firmware version (0xE9).
SHORT_COMMAND = layouts.FIRMWARE_VERSION

#: What bringup measures, by the names of its round trips.
PING = 'ping'
COMMAND = 'command'
CONTINUOUS_START = 'continuous start'
RECORD_GAP = 'record gap'
_HERE = 'i3dmgx2_driver/device/timeouts.py'
#: The waits on the radio a round trip is held against: the constant in device/timeouts.py,
#: the round trip it bounds, who waits, and how a user changes it: the ``DeviceConfig``
#: field a node parameter sets (named from the parameter table), a tool's option, or
#: '' (the constant itself).
_WAITS = (
    ('PING_TIMEOUT', PING, "the node's start-up ping", ''),
    ('PROBE_PING_TIMEOUT', PING, "discover's first pings", 'discover --ping-timeout'),
    ('PROBE_ANSWER_TIMEOUT', PING, "discover's pings through a known base station", ''),
    ('REQUEST_TIMEOUT', COMMAND, "the node's commands (per try)", 'request_timeout'),
    ('RESUME_TIMEOUT', COMMAND, "the node's serial-number read on a reconnect (per try; the "
     'node parameter fast_reconnect false avoids it)', 'resume_timeout'),
    ('PROBE_REQUEST_TIMEOUT', COMMAND, "discover's commands (per try)", ''),
    ('REQUEST_TIMEOUT', CONTINUOUS_START, "the node's continuous-mode request (per try)",
     'request_timeout'),
    ('STALL_TIMEOUT', RECORD_GAP, "the node's stall watch", 'stall_timeout'),
)


class RadioTimeout(NamedTuple):
    """One wait on the radio, what it waits for and how to change it."""

    #: The constant's name in device/timeouts.py.
    name: str
    seconds: float
    #: Which measured round trip it bounds: PING, COMMAND, CONTINUOUS_START or RECORD_GAP.
    measured: str
    #: Who waits, in words.
    waits: str
    #: How a user changes it: a parameter, an option, or the constant.
    setting: str


def radio_timeouts() -> tuple[RadioTimeout, ...]:
    """Return every timeout on the radio, with the round trip it bounds."""
    parameters = {spec.feeds[len('device.'):]: spec.name for spec in SPECS
                  if spec.feeds.startswith('device.')}
    return tuple(
        RadioTimeout(name, getattr(timeouts, name), measured, waits,
                     f'the node parameter {parameters[setting]}' if setting in parameters
                     else setting or f'{name} in {_HERE}')
        for name, measured, waits, setting in _WAITS)


def close_calls(measured: dict[str, float], factor: float = 2.0) -> list[str]:
    """
    Say which timeouts a measured round trip comes within ``factor`` of.

    ``measured`` maps PING, COMMAND, CONTINUOUS_START, RECORD_GAP to the
    longest time seen (s); one sentence per timeout it comes close to.
    """
    return [f'{timeout.measured} took up to {seen * 1e3:.0f} ms, within a factor {factor:g} '
            f'of {timeout.name} = {timeout.seconds:g} s ({timeout.waits}): '
            f'raise {timeout.setting}' for timeout in radio_timeouts()
            if (seen := measured.get(timeout.measured)) is not None
            and seen * factor >= timeout.seconds]


def spread(values: Sequence[float], scale: float = 1.0,
           digits: int = 1) -> dict[str, float | int | None]:
    """Return count, min, median and max of ``values`` times ``scale``."""
    if not values:
        return {'count': 0, 'min': None, 'median': None, 'max': None}

    def shown(value: float) -> float | int:
        return round(value * scale, digits) if digits else round(value * scale)
    return {'count': len(values), 'min': shown(min(values)),
            'median': shown(statistics.median(values)), 'max': shown(max(values))}


def note_longest(longest: dict[str, float], kind: str, values: Sequence[float]) -> None:
    """Keep in ``longest`` the longest of ``values`` (s) for ``kind``, if longer."""
    if values:
        longest[kind] = max(longest.get(kind, 0.0), *values)
