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
The sensor's data rate: read it, set it if asked (an EEPROM write), check the line.

The divider cell wears with every write, so what was written and how often
is kept here, with the one rule that guards it: one change of setting
writes the cell once, however rough the radio, and never again from this
driver's run. The rate then says whether the line carries the stream.
"""

from .dialogue_parts import DialogueParts
from .link import DeviceLink, DeviceTimeout
from .throttle import Throttle
from ..codec import commands, layouts, streams
from ..codec.data_rate import divider_for_rate, RATE_BASE_HZ, RATE_DIVIDER_ADDRESS


class RateSetting:
    """
    The data-rate divider of the sensor at ``config.address``, as read and as written.

    ``cancel`` set means the driver is stopping (a failed read is then no
    reason to warn).
    """

    def __init__(self, parts: DialogueParts) -> None:
        self.config, self._log, self._warn, self._cancel = parts
        self._throttle = Throttle()
        self.divider: int | None = None
        #: EEPROM write commands sent (the divider's cell; each may wear it).
        self.eeprom_writes = 0
        #: Dividers written (or tried): never written again by this dialogue.
        self._divider_written: set[int] = set()
        #: The stream's use of the line at the device's rate (once the rate is known),
        #: and, when it does not fit, what to do about it ('' when it fits).
        self.line_use = ''
        self.line_warning = ''

    @property
    def expected_rate_hz(self) -> float | None:
        """Return the rate the divider gives, once known."""
        return RATE_BASE_HZ / self.divider if self.divider else None

    @property
    def period(self) -> float:
        """Return the time between samples (s), or 10 ms while the rate is unknown."""
        return 1.0 / self.expected_rate_hz if self.divider else 0.01

    def configure(self, link: DeviceLink) -> None:
        """Read the divider; write the one ``config.data_rate_hz`` asks for, if it differs."""
        cfg = self.config
        try:
            current = link.request(commands.read_eeprom(RATE_DIVIDER_ADDRESS),
                                   layouts.READ_EEPROM, cfg.request_timeout,
                                   cfg.request_retries).value
        except DeviceTimeout:
            if cfg.data_rate_hz is not None or self._cancel.is_set():
                raise
            # Nothing to set, so streaming can go on without knowing the rate
            # (a replayed capture answers no request; lost packets and the
            # rate check in diagnostics then wait for a known divider).
            self._warn('rate', 'the device did not tell its data rate (EEPROM 0xFCA2)', None)
            return
        self.divider = current
        if cfg.data_rate_hz is None:
            return
        wanted = divider_for_rate(cfg.data_rate_hz)
        if wanted == current:
            return
        if wanted in self._divider_written:
            # Written before: a retry, a reconnect or a restart of the stream must not
            # write the cell again. The sensor (or a reply that only looks valid, or
            # another sensor put in its place) says otherwise; go on with what it says,
            # and say so. (Not even the serial number can be trusted for this: a reply
            # that only looks valid can carry any.)
            self._warn('rate', f'the device reports divider {current} though {wanted} was '
                               f'written before: not writing its EEPROM again (restart the '
                               f'driver to write it)', None)
            return
        # Noted before the first write goes out: from then on the cell may be written,
        # whatever the replies say (found by the stateful dialogue test: a forged
        # read-back made the next initialise write again).
        self._divider_written.add(wanted)
        self.divider = self._write_divider(link, current, wanted)
        self._log.warning(
            f'data rate of node {cfg.address} set to {RATE_BASE_HZ / wanted:.2f} Hz (EEPROM '
            f'0xFCA2: {current} -> {wanted}); this persists across power cycles')

    def _write_divider(self, link: DeviceLink, current: int, wanted: int) -> int:
        """
        Write the divider once; return it as read back.

        An EEPROM cell wears with every write, so a write is never resent
        blindly: when its reply does not come, the write may have reached
        the sensor and only the reply been lost. The divider is read back
        instead, and written again only if the sensor still has the old one
        (the command itself was lost). So one change of setting writes the
        cell once, however rough the radio.
        """
        cfg = self.config
        readback = current
        for _ in range(cfg.request_retries):
            self.eeprom_writes += 1
            try:
                link.request(commands.write_eeprom(RATE_DIVIDER_ADDRESS, wanted),
                             layouts.WRITE_EEPROM, cfg.request_timeout, 1)
            except DeviceTimeout:
                pass  # written or not: the read below tells
            readback = link.request(commands.read_eeprom(RATE_DIVIDER_ADDRESS),
                                    layouts.READ_EEPROM, cfg.request_timeout,
                                    cfg.request_retries).value
            if readback != current:
                break
        if readback != wanted:
            raise DeviceTimeout(f'data rate: wrote divider {wanted}, read back {readback}')
        return readback

    def check_line(self) -> None:
        """
        Warn when the device's rate is more than the line carries for the stream.

        A requested rate that does not fit was refused before the node
        started; this catches a device already set (data_rate 0) to a rate the
        stream cannot keep, which would otherwise show only as records missing.
        """
        if not self.divider:
            return
        cfg = self.config
        stream = streams.BY_CODE[cfg.stream]
        budget = streams.line_budget(stream, self.expected_rate_hz, cfg.baud, cfg.wireless)
        self.line_use = streams.describe(budget)
        if budget.fits:
            self.line_warning = ''
            return
        self.line_warning = ('the device is set to a rate the line cannot carry, records '
                             'will be skipped: ' + streams.advice(stream, budget))
        if self._throttle.allow('line'):
            self._log.warning(self.line_warning)
