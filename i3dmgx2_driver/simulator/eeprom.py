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
The sensor's EEPROM and the settings it holds: ``SensorEeprom``.

The EEPROM outlives power cycles: what the host wrote is what the sensor
powers up with. Two of its words set the sensor up: the data-rate divider
(rate = 51200 / divider Hz, ``codec.data_rate``), which the firmware keeps
only if it is in range, and the power-up auto-start (LSB: the record to
stream; MSB 0x80: wireless). A word nobody wrote reads as erased flash.
The bias corrections a 0xD0 transfer stores are kept with the corrections
themselves (``data_records.BiasCorrections``); whether this memory takes
them at all is decided here: ``refuse_bias_store`` makes it answer 0xD0 with
0xFFFF and keep what it had (a worn or write-protected memory), so that a
host can be shown a refused store.
Kept apart from the device model so that a change to what the EEPROM
stores, or refuses, is made in one small place.
"""

from i3dmgx2_driver.codec.data_rate import (
    MAX_DIVIDER, MIN_DIVIDER, RATE_BASE_HZ, RATE_DIVIDER_ADDRESS,
)

__all__ = ['AUTOSTART_ADDRESS', 'ERASED_WORD', 'FACTORY_DIVIDER', 'SensorEeprom']

#: The divider a sensor leaves the factory with (100 Hz).
FACTORY_DIVIDER = 512
#: EEPROM word of the power-up auto-start (LSB: command; MSB 0x80: wireless).
AUTOSTART_ADDRESS = 0xFCA6
#: What the EEPROM answers for a word nobody wrote (erased flash).
ERASED_WORD = 0xFFFF


class SensorEeprom:
    """
    The EEPROM words, and the rate and auto-start they give; not thread-safe.

    ``presets`` are words on top of the factory ones; ``rate_override`` a
    calculation rate (Hz) that overrides the divider (benchmarks; None: the
    divider's).
    """

    def __init__(self, presets: dict[int, int] | None = None,
                 rate_override: float | None = None) -> None:
        #: The words (address -> value); the sensor shows this dict as ``eeprom``.
        self.words: dict[int, int] = {RATE_DIVIDER_ADDRESS: FACTORY_DIVIDER,
                                      AUTOSTART_ADDRESS: 0x0000, **(presets or {})}
        #: A rate (Hz) calculated at whatever the divider says (None: the divider's).
        self.rate_override = rate_override
        #: Refuse every 0xD0 transfer (answer 0xFFFF, store nothing).
        self.refuse_bias_store = False

    @property
    def rate_hz(self) -> float:
        """Return the calculation rate (Hz): the override, or 51200 / EEPROM divider."""
        if self.rate_override is not None:
            return self.rate_override
        return RATE_BASE_HZ / self.words.get(RATE_DIVIDER_ADDRESS, FACTORY_DIVIDER)

    @property
    def autostart(self) -> int:
        """Return the command byte the auto-start word names (0: none)."""
        return self.words.get(AUTOSTART_ADDRESS, 0) & 0xFF

    def read(self, address: int) -> int:
        """Return the word at ``address`` (erased if nobody wrote it)."""
        return self.words.get(address, ERASED_WORD)

    def write(self, address: int, value: int) -> bool:
        """
        Store ``value`` at ``address``; return whether a divider was stored (the rate is new).

        An invalid divider is not stored (the reply shows the word kept).
        """
        if address == RATE_DIVIDER_ADDRESS and not MIN_DIVIDER <= value <= MAX_DIVIDER:
            return False
        self.words[address] = value
        return address == RATE_DIVIDER_ADDRESS
