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
The round trips a bring-up measures: ping, a short command, continuous mode's start and stop.

Each is timed with :data:`MEASURE_TIMEOUT`, far beyond the driver's own
timeouts, so that a slow round trip is measured rather than counted lost;
the longest of each kind is noted for the check of the driver's timeouts
(:func:`close_calls`). When a stream is stopped is told
as every tool and the node tell it (``device/sensor_steps.py``).
"""

import argparse
from collections.abc import Callable, Sequence
import statistics
import time
from typing import Any, NamedTuple

from ..codec import commands, layouts
from ..device import timeouts
from ..device.link import DeviceError, DeviceLink, DeviceNack
from ..device.sensor_steps import SensorSteps
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


class RoundTrips:
    """
    Time the round trips over ``link`` as many times as ``args`` say.

    Each method returns its entries of the report's ``round_trips`` and
    notes the longest round trip of its kind in ``longest``. ``steps`` tell
    when a stream has stopped, and stop one for sure.
    """

    def __init__(self, link: DeviceLink, steps: SensorSteps, args: argparse.Namespace,
                 say: Callable[[str], None], longest: dict[str, float]) -> None:
        self.link, self.steps, self.args, self.say, self.longest = link, steps, args, say, longest

    def _request(self, command: bytes, code: int) -> str | None:
        """Send ``command`` once; return the failure's name ('nacked', 'lost') or None."""
        try:
            self.link.request(command, code, MEASURE_TIMEOUT, 1)
        except DeviceNack:
            return 'nacked'
        except DeviceError:
            return 'lost'
        return None

    def _timed(self, kind: str, count: int, failures: tuple[str, ...],
               attempt: Callable[[], str | None]) -> dict[str, Any]:
        """Time ``count`` tries of ``attempt`` (it returns the failure's name, or None)."""
        times, failed = [], dict.fromkeys(failures, 0)
        for _ in range(count):
            start = time.monotonic()
            failure = attempt()
            if failure is None:
                times.append(time.monotonic() - start)
            else:
                failed[failure] += 1
        note_longest(self.longest, kind, times)
        return {kind: {**spread(times, 1e3), **failed}}

    def ping(self) -> dict[str, Any]:
        """Time pings through the base station (no answer: lost; 0x21: not the sensor's)."""
        self.say(f'timing {self.args.pings} pings')

        def once() -> str | None:
            answer = self.link.ping_once(self.link.address, MEASURE_TIMEOUT)
            # Falsy: the base station answered, the sensor did not (0x21).
            return 'lost' if answer is None else None if answer else 'not_answered_by_sensor'
        return self._timed(PING, self.args.pings, ('lost', 'not_answered_by_sensor'), once)

    def command(self) -> dict[str, Any]:
        """Time the short command's request and reply."""
        self.say(f'timing {self.args.commands} short commands (0x{SHORT_COMMAND:02X})')
        return self._timed(COMMAND, self.args.commands, ('lost', 'nacked'),
                           lambda: self._request(bytes((SHORT_COMMAND,)), SHORT_COMMAND))

    def continuous(self, code: int, period: float) -> dict[str, Any]:
        """
        Time continuous mode ``code``: reply and first record, then the stop's last record.

        ``period`` is the time between records at the sensor's rate.
        """
        self.say(f'timing {self.args.cycles} continuous-mode starts and stops (0x{code:02X})')
        link, steps = self.link, self.steps
        starts, stops, replies = [], [], []
        failed = dict.fromkeys(('lost', 'nacked', 'no_records'), 0)
        for _ in range(self.args.cycles):
            before = link.records
            start = time.monotonic()
            if (failure := self._request(commands.set_continuous(code),
                                         layouts.SET_CONTINUOUS)) is None:
                replies.append(time.monotonic() - start)
            else:
                failed[failure] += 1
            deadline = start + MEASURE_TIMEOUT + timeouts.RECORD_PERIODS * period
            while link.records <= before and time.monotonic() < deadline:
                time.sleep(0.002)
            if link.records <= before:
                failed['no_records'] += 1
                continue
            starts.append(link.last_data_mono - start)
            time.sleep(0.2)
            # Once, no retry: the stop's round trip is measured.
            stop_sent = time.monotonic()
            link.send(commands.stop_continuous())
            last = steps.wait_quiet(link, stop_sent, period, MEASURE_TIMEOUT)
            if last is None:
                failed['lost'] += 1  # the stop was lost: stop it the sure way
                steps.stop_until_quiet(link, period)
                continue
            stops.append(max(0.0, last - stop_sent))
        note_longest(self.longest, CONTINUOUS_START, starts)
        return {'continuous_start': {**spread(starts, 1e3), 'reply': spread(replies, 1e3),
                                     **failed},
                'continuous_stop': spread(stops, 1e3)}
