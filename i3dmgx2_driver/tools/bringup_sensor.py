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
The sensor during a bring-up: what the reader hears of it, its stream and its rate divider.

:class:`HeardRecords` is what the link's reader thread hands over (counts,
and the records' details while a stream is measured); :class:`SensorControl`
starts and stops the stream (until records come, or stop coming) and reads
and writes the rate divider in EEPROM, counting the writes, so that the
session (bringup.py) and its round trips (bringup_round_trips.py) share one
notion of when the sensor is quiet.
"""

import threading
import time

from ..codec import commands, layouts
from ..codec.data_rate import RATE_BASE_HZ, RATE_DIVIDER_ADDRESS
from ..codec.framing import DataPacket
from ..device import timeouts
from ..device.link import DeviceLink, DeviceTimeout

#: Silence (s) after which a stopped stream counts as stopped (plus a few periods).
QUIET_S = 0.3


class HeardRecords:
    """The records of our sensor as the reader thread hands them over."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.count = 0
        self.last_mono = 0.0
        #: While collecting: (mono, code, timer, lqi, rssi) of each record.
        self.log: list[tuple[float, int, int, int | None, int | None]] | None = None

    def __call__(self, packet: DataPacket, now: float, mono: float) -> None:
        with self.lock:
            self.count += 1
            self.last_mono = mono
            if self.log is not None:
                record = packet.record
                layout = commands.LAYOUT_BY_TYPE.get(type(record))
                code = layout.code if layout is not None else 0
                self.log.append((mono, code, getattr(record, 'timer', 0), packet.lqi,
                                 packet.rssi))

    def snapshot(self) -> tuple[int, float]:
        with self.lock:
            return self.count, self.last_mono


class SensorControl:
    """
    Start and stop the stream of the sensor behind ``link``; read and write its rate divider.

    ``heard`` is told of each record by the link's reader thread.
    """

    def __init__(self, link: DeviceLink, heard: HeardRecords) -> None:
        self.link = link
        self.heard = heard
        #: The rate divider as last written or found (None: unknown).
        self.divider: int | None = None
        #: EEPROM writes made (each written back at the end).
        self.eeprom_writes = 0
        #: When the stream was last asked to stop (a record before it is no sign of quiet).
        self._since = 0.0

    def read_divider(self) -> int:
        return self.link.request(commands.read_eeprom(RATE_DIVIDER_ADDRESS),
                                 layouts.READ_EEPROM, timeouts.REQUEST_TIMEOUT,
                                 timeouts.REQUEST_RETRIES).value

    def write_divider(self, divider: int) -> bool:
        """Write the rate divider to EEPROM and read it back; True if it holds."""
        try:
            self.link.request(commands.write_eeprom(RATE_DIVIDER_ADDRESS, divider),
                              layouts.WRITE_EEPROM, timeouts.REQUEST_TIMEOUT,
                              timeouts.REQUEST_RETRIES)
            readback = self.read_divider()
        except DeviceTimeout:
            return False
        self.eeprom_writes += 1
        if readback == divider:
            self.divider = divider
        return readback == divider

    # -- streams on and off -----------------------------------------------------------

    def period(self) -> float:
        """Return the time between two records at the divider (s; a guess while unknown)."""
        return self.divider / RATE_BASE_HZ if self.divider else 0.01

    def wait_quiet(self, within: float) -> float | None:
        """Wait until no record came for QUIET_S (and a few periods); return the last's time."""
        quiet = QUIET_S + 5 * self.period()
        deadline = time.monotonic() + within
        while time.monotonic() < deadline:
            _, last = self.heard.snapshot()
            if time.monotonic() - max(last, self._since) >= quiet:
                return last
            time.sleep(0.01)
        return None

    def stop_stream(self) -> bool:
        """Send 0xFA until records stop; True once they have."""
        for _ in range(5):
            self._since = time.monotonic()
            self.link.stop_streaming()
            if self.wait_quiet(2.0) is not None:
                return True
        return False

    def start_stream(self, code: int, tries: int = 5) -> float | None:
        """Ask for continuous mode until records arrive; return when the first did."""
        for _ in range(tries):
            before, _ = self.heard.snapshot()
            try:
                self.link.request(commands.set_continuous(code), layouts.SET_CONTINUOUS,
                                  timeouts.REQUEST_TIMEOUT, 1)
            except DeviceTimeout:
                pass  # the reply may be lost while the stream started: look for records
            deadline = time.monotonic() + max(1.0, 5 * self.period())
            while time.monotonic() < deadline:
                count, last = self.heard.snapshot()
                if count > before:
                    return last
                time.sleep(0.005)
        return None

    def send_stop(self) -> float:
        """Send 0xFA once (no retry: a round trip is measured); return when it was sent."""
        self._since = stop_sent = time.monotonic()
        self.link.send(commands.stop_continuous())
        return stop_sent
