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
The calculation cycle: data rate = 51200 / divider Hz (EEPROM word 0xFCA2).

A protocol fact, kept in the codec so that the line budget, the device
supervisor and the node's parameters all quantise a rate the same way the
device does: only the rates 51200 / x, x = 170..51200, exist.
"""

from .records import TICKS_PER_SECOND

#: EEPROM word holding the data-rate divider: rate = 51200 / x Hz.
RATE_DIVIDER_ADDRESS = 0xFCA2
#: Base of the data-rate divider (Hz).
RATE_BASE_HZ = 51200.0
#: Valid range of the divider (about 300 Hz down to 1 Hz); factory 512 (100 Hz).
MIN_DIVIDER = 170
MAX_DIVIDER = 51200
#: Lowest and highest data rate the divider can give.
MIN_RATE_HZ = RATE_BASE_HZ / MAX_DIVIDER
MAX_RATE_HZ = RATE_BASE_HZ / MIN_DIVIDER
#: The time between records assumed while the divider is unknown (s): the factory
#: divider's (512, 100 Hz).
UNKNOWN_PERIOD_S = 0.01
#: Device timer ticks in one calculation cycle of divider 1 (19,660,800 / 51,200).
TICKS_PER_DIVIDER = round(TICKS_PER_SECOND / RATE_BASE_HZ)


def divider_for_rate(rate_hz: float) -> int:
    """Return the EEPROM divider for a data rate, clamped to the valid range."""
    return max(MIN_DIVIDER, min(MAX_DIVIDER, round(RATE_BASE_HZ / rate_hz)))


def rate_of_divider(divider: int) -> float:
    """Return the data rate (Hz) a divider gives."""
    return RATE_BASE_HZ / divider


def period_of_divider(divider: int | None) -> float:
    """
    Return the time between two records at ``divider`` (s).

    While the divider is unknown (None: not read yet, or not answered) the
    factory rate's period stands in, so that a wait for records is never
    left without a length.
    """
    return divider / RATE_BASE_HZ if divider else UNKNOWN_PERIOD_S


def ticks_per_cycle(divider: int) -> int:
    """Return the device timer ticks between two records streamed at ``divider``."""
    return TICKS_PER_DIVIDER * divider
