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
The device timer: its ticks per second and the rollover's period.

docs/protocol.md §8: a uint32 counting 19,660,800 ticks per second from power-up, so it
wraps every 2^32 ticks, about 218.45 s. The package turns ticks into seconds by dividing
by TICKS_PER_SECOND. Reading the raw timer across its rollovers and resets is the
driver's sample clock's work (test_sample_clock.py).
"""

from i3dmgx2_driver.codec.data_rate import ticks_per_cycle
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
import pytest


def test_constants():
    """19,660,800 ticks per second; the timer wraps after 2^32 ticks, about 218.45 s."""
    assert TICKS_PER_SECOND == 19_660_800
    assert TIMER_MODULUS == 4_294_967_296
    rollover_s = TIMER_MODULUS / TICKS_PER_SECOND
    assert rollover_s == pytest.approx(218.4533, abs=1e-4)


def test_ticks_to_seconds():
    """Ticks to seconds as the package reads them, raw or unwrapped (beyond 32 bits)."""
    assert 0 / TICKS_PER_SECOND == 0.0
    assert 19_660_800 / TICKS_PER_SECOND == 1.0
    assert 9_830_400 / TICKS_PER_SECOND == 0.5
    three_wraps = 3 * TIMER_MODULUS
    assert three_wraps / TICKS_PER_SECOND == pytest.approx(655.36, abs=1e-2)
    # One cycle at 100 Hz (divider 512) is a whole number of ticks.
    assert ticks_per_cycle(512) == 196_608 == TICKS_PER_SECOND / 100
