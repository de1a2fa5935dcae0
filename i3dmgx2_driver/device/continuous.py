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
Continuous mode: start the stream until records arrive, or resume a known sensor.

The stream counts as started only once a record has arrived (a lost reply
may hide a stream that runs, a reply may come with no stream after it).
After a reconnect, a sensor already identified is confirmed with one
serial-number read and kept streaming; anything else gets the full
dialogue. What a sensor is and what rate it runs at are learned elsewhere
(identification.py, rate_setting.py); this uses them.
"""

import time

from .dialogue_parts import DialogueParts
from .identification import Identification
from .identity import read_identifier, SERIAL_NUMBER_SELECTOR
from .link import DeviceLink, DeviceTimeout
from .port import PortDisconnected
from .rate_setting import RateSetting
from .throttle import EVENT_PERIOD, Throttle
from ..codec import commands, layouts, streams


class ContinuousMode:
    """
    Start, resume and expect the stream of ``config.stream`` from ``config.address``.

    ``identity`` says which sensor is known (and forgets it when another
    answers); ``rate`` says how long a record may take; ``cancel`` set makes
    the waits give up.
    """

    def __init__(self, parts: DialogueParts, identity: Identification,
                 rate: RateSetting) -> None:
        self.config, self._log, _, self._cancel = parts
        self._identity = identity
        self._rate = rate
        self._throttle = Throttle()

    def start(self, link: DeviceLink) -> bool:
        """
        Ask for continuous mode of the configured record until records actually arrive.

        Returns True once a record has arrived, False if cancelled first;
        raises DeviceTimeout when none comes, PortDisconnected if the port goes.
        """
        cfg = self.config
        # From now on a record of the streamed code is a sample, even one that also
        # answers a polled request.
        link.streamed = cfg.stream
        for _ in range(cfg.continuous_retries):
            before = link.records
            try:
                link.request(commands.set_continuous(cfg.stream), layouts.SET_CONTINUOUS,
                             cfg.request_timeout, 1)
            except DeviceTimeout:
                pass  # the reply may be lost while the stream started: look for records
            deadline = time.monotonic() + max(0.3, 5 * self._rate.period)
            while time.monotonic() < deadline and not self._cancel.is_set():
                if link.records > before:
                    return True
                if link.disconnected.is_set():
                    raise PortDisconnected(link.error or 'device disconnected')
                time.sleep(0.01)
            if self._cancel.is_set():
                return False
        raise DeviceTimeout(f'continuous mode: no records after {cfg.continuous_retries} '
                            f'requests')

    def announce(self) -> None:
        """Say that records flow: called only once one has arrived on this link."""
        cfg = self.config
        stream = streams.BY_CODE[cfg.stream]
        rate = self._rate
        self._log.info(f'streaming {stream.label} from node {cfg.address} on {cfg.port}'
                       + (f' at {rate.expected_rate_hz:.1f} Hz' if rate.divider else '')
                       + ' (first record received)')

    def resume(self, link: DeviceLink) -> bool:
        """
        Confirm with one serial-number read that the known sensor is back; keep it streaming.

        The link's reader runs already, with records of the stream counted as
        samples from the first one. Returns False when the driver knows no
        sensor yet (or must not resume), or when the sensor does not answer or
        another serial number does: the caller then runs the full dialogue.
        """
        cfg = self.config
        known = self._identity.serial_number
        try:
            serial = read_identifier(link, SERIAL_NUMBER_SELECTOR, cfg.resume_timeout,
                                     cfg.resume_retries)
        except DeviceTimeout:
            if self._cancel.is_set():
                raise
            if self._throttle.allow('resume', EVENT_PERIOD):
                self._log.info(f'node {cfg.address} did not confirm its serial number: '
                               f'starting it in full')
            return False
        if serial != known:
            self._log.warning(f'another sensor answers as node {cfg.address}: serial '
                              f'{serial or "?"}, not {known}; identifying it in full')
            self._identity.forget()
            return False
        deadline = time.monotonic() + min(2 * self._rate.period, 0.1)
        while link.last_code != cfg.stream and time.monotonic() < deadline \
                and not self._cancel.is_set():
            time.sleep(0.002)
        # Not streaming (power-cycled meanwhile), or streaming another record: ask for it.
        if link.last_code != cfg.stream and not self.start(link):
            return True  # cancelled: nothing more to do here
        self._log.info(f'streaming {streams.BY_CODE[cfg.stream].label} again from node '
                       f'{cfg.address} on {cfg.port}: same sensor (serial {serial}), identity '
                       f'and data rate not asked again')
        return True

    def expect_stream(self, link: DeviceLink) -> None:
        """Drop what is in flight; count records of the stream as samples from the first."""
        link.flush_input()
        link.streamed = self.config.stream

    def can_resume(self) -> bool:
        """Whether a reconnect may try :meth:`resume` (a known sensor, and allowed to)."""
        return bool(self.config.fast_reconnect and self._identity.serial_number)
