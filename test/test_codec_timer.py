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
The device timer: ticks to seconds and back, and the rollover's period.

docs/protocol.md §8: a uint32 counting 19,660,800 ticks per second from power-up, so it
wraps every 2^32 ticks, about 218.45 s. Reading the raw timer across its rollovers and
resets is the driver's sample clock's work (test_sample_clock.py).
"""

from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import seconds_to_ticks, ticks_to_seconds, TIMER_MODULUS
import pytest


def test_constants():
    """19,660,800 ticks per second; the timer wraps after 2^32 ticks, about 218.45 s."""
    assert TICKS_PER_SECOND == 19_660_800
    assert TIMER_MODULUS == 4_294_967_296
    assert ticks_to_seconds(TIMER_MODULUS) == pytest.approx(218.4533, abs=1e-4)


def test_ticks_to_seconds():
    """Ticks to seconds and back, raw or unwrapped (beyond 32 bits)."""
    assert ticks_to_seconds(0) == 0.0
    assert ticks_to_seconds(19_660_800) == 1.0
    assert ticks_to_seconds(9_830_400) == 0.5
    assert ticks_to_seconds(3 * TIMER_MODULUS) == pytest.approx(655.36, abs=1e-2)
    assert seconds_to_ticks(1.0) == 19_660_800
    assert seconds_to_ticks(0.01) == 196_608  # one cycle at 100 Hz
    assert seconds_to_ticks(1.0 / TICKS_PER_SECOND * 0.4) == 0  # rounds to nearest
    assert seconds_to_ticks(1.0 / TICKS_PER_SECOND * 0.6) == 1
    for ticks in (0, 1, 196_608, TIMER_MODULUS - 1, 10 * TIMER_MODULUS + 12345):
        assert seconds_to_ticks(ticks_to_seconds(ticks)) == ticks
