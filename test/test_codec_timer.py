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
The device timer: ticks to seconds, rollover unwrapping and reset detection.

docs/protocol.md §8: a uint32 counting 19,660,800 ticks per second from power-up, so it
wraps every 2^32 ticks, about 218.45 s. The unwrapper takes a forward step of
less than half the range as time passing (across a wrap or not), and anything
else as a device reset that starts a new epoch.
"""

from hypothesis import given, settings, strategies as st
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import (
    seconds_to_ticks, ticks_to_seconds, TIMER_MODULUS, TimerUnwrapper,
)
import pytest

CI = settings(max_examples=300, deadline=None, database=None)
HALF = 1 << 31


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


def test_first_value_is_taken_as_it_is():
    """The first raw value starts the count; nothing is a wrap or a reset yet."""
    unwrapper = TimerUnwrapper()
    assert unwrapper.update(123_456) == 123_456
    assert (unwrapper.wraps, unwrapper.resets, unwrapper.last_was_reset) == (0, 0, False)


def test_unwrap_across_a_rollover():
    """0xFFFFFF9C then 50: 150 ticks later, one wrap, 2^32 + 50."""
    unwrapper = TimerUnwrapper()
    assert unwrapper.update(TIMER_MODULUS - 100) == TIMER_MODULUS - 100
    assert unwrapper.update(50) == TIMER_MODULUS + 50
    assert unwrapper.wraps == 1 and unwrapper.resets == 0
    assert not unwrapper.last_was_reset
    assert unwrapper.update(196_658) == TIMER_MODULUS + 196_658


def test_multiple_wraps():
    """A timer stepping 1e9 ticks at a time, for 20 steps, wraps 5 times and stays exact."""
    unwrapper = TimerUnwrapper()
    start = 3_000_000_000
    out = [unwrapper.update((start + k * 1_000_000_000) % TIMER_MODULUS) for k in range(21)]
    assert out == [start + k * 1_000_000_000 for k in range(21)]
    assert unwrapper.wraps == (start + 20 * 1_000_000_000) // TIMER_MODULUS == 5
    assert unwrapper.resets == 0


def test_half_range_boundary():
    """A forward step of 2^31 - 1 ticks is time passing; 2^31 or more is taken as a reset."""
    unwrapper = TimerUnwrapper()
    unwrapper.update(0)
    assert unwrapper.update(HALF - 1) == HALF - 1
    assert not unwrapper.last_was_reset
    unwrapper = TimerUnwrapper()
    unwrapper.update(0)
    assert unwrapper.update(HALF) == HALF  # a new epoch, starting at the raw value
    assert unwrapper.last_was_reset and unwrapper.resets == 1


def test_repeated_value_is_not_a_reset():
    """The same timer twice (a repeated record) neither advances nor resets."""
    unwrapper = TimerUnwrapper()
    unwrapper.update(TIMER_MODULUS - 1)
    unwrapper.update(5)
    assert unwrapper.update(5) == TIMER_MODULUS + 5
    assert (unwrapper.wraps, unwrapper.resets, unwrapper.last_was_reset) == (1, 0, False)


def test_device_reset_is_detected():
    """A step backwards is a device reset: flagged once, counted, a new epoch from the raw."""
    unwrapper = TimerUnwrapper()
    unwrapper.update(TIMER_MODULUS - 10)
    assert unwrapper.update(5) == TIMER_MODULUS + 5           # a wrap
    assert unwrapper.update(100) == TIMER_MODULUS + 100
    assert unwrapper.update(3) == 3                           # rebooted: 97 ticks back
    assert unwrapper.last_was_reset
    assert (unwrapper.wraps, unwrapper.resets) == (1, 1)
    assert unwrapper.update(196_611) == 196_611               # the new epoch runs on
    assert not unwrapper.last_was_reset
    assert unwrapper.update(1) == 1                           # and another reset
    assert unwrapper.resets == 2 and unwrapper.last_was_reset


def test_reset_forgets_the_history_but_keeps_the_counters():
    """reset() after a reconnect: the next value starts afresh; wraps and resets remain."""
    unwrapper = TimerUnwrapper()
    unwrapper.update(TIMER_MODULUS - 10)
    unwrapper.update(10)
    unwrapper.update(5)  # a reset
    unwrapper.reset()
    assert not unwrapper.last_was_reset
    assert unwrapper.update(TIMER_MODULUS - 1) == TIMER_MODULUS - 1  # no reset: no history
    assert not unwrapper.last_was_reset
    assert (unwrapper.wraps, unwrapper.resets) == (1, 1)
    assert unwrapper.update(0) == TIMER_MODULUS


@CI
@given(start=st.integers(0, TIMER_MODULUS - 1),
       steps=st.lists(st.integers(0, HALF - 1), max_size=50))
def test_forward_steps_unwrap_exactly(start, steps):
    """Property: any forward steps under half the range unwrap to the exact running sum."""
    unwrapper = TimerUnwrapper()
    total = start
    assert unwrapper.update(start) == start
    previous = start
    for step in steps:
        total += step
        out = unwrapper.update(total % TIMER_MODULUS)
        assert out == total
        assert out >= previous
        assert not unwrapper.last_was_reset
        previous = out
    assert unwrapper.wraps == total // TIMER_MODULUS
    assert unwrapper.resets == 0


@CI
@given(start=st.integers(0, TIMER_MODULUS - 1), back=st.integers(1, HALF))
def test_any_step_back_is_a_reset(start, back):
    """Property: a step back of up to half the range is always reported as a reset."""
    unwrapper = TimerUnwrapper()
    unwrapper.update(start)
    raw = (start - back) % TIMER_MODULUS
    assert unwrapper.update(raw) == raw
    assert unwrapper.last_was_reset and unwrapper.resets == 1


# ---------------------------------------------------------------- with host times

def test_host_time_unwraps_a_long_pause():
    """Given host times, a 300 s outage (more than a whole wrap) is unwrapped exactly."""
    start = TIMER_MODULUS - 1000
    pause = 300 * TICKS_PER_SECOND  # 5,898,240,000 ticks: 1.37 wraps
    raw = (start + pause) % TIMER_MODULUS
    unwrapper = TimerUnwrapper()
    unwrapper.update(start, host_time=100.0)
    assert unwrapper.update(raw, host_time=400.0) == start + pause
    assert unwrapper.wraps == (start + pause) // TIMER_MODULUS == 2
    assert not unwrapper.last_was_reset
    # Without host times the same raw step can only be read modulo 2^32: 81.5 s.
    blind = TimerUnwrapper()
    blind.update(start)
    assert blind.update(raw) == start + pause - TIMER_MODULUS


def test_host_time_tolerates_late_reads():
    """Records read in a burst, 1.5 s late, still count as the 10 ms that passed."""
    unwrapper = TimerUnwrapper()
    unwrapper.update(1_000_000, host_time=10.0)
    assert unwrapper.update(1_196_608, host_time=11.5) == 1_196_608
    assert not unwrapper.last_was_reset and unwrapper.resets == 0


def test_host_time_detects_a_reset():
    """The device timer goes from 100 s to 0.5 s while the host saw 1 s pass: a reset."""
    unwrapper = TimerUnwrapper()
    unwrapper.update(100 * TICKS_PER_SECOND, host_time=50.0)
    assert unwrapper.update(TICKS_PER_SECOND // 2, host_time=51.0) == TICKS_PER_SECOND // 2
    assert unwrapper.last_was_reset and unwrapper.resets == 1


def test_host_time_resolves_the_fixture_gap():
    """
    The fixture's long set jumps from 858,295,945 to 4,171,399,561 ticks.

    That is 168.5 s forward or 49.9 s back; without host times it must be called a
    reset (see test_codec_fixtures), but a host that saw 168.5 s pass unwraps it forward.
    """
    before, after = 858_295_945, 4_171_399_561
    blind = TimerUnwrapper()
    blind.update(before)
    blind.update(after)
    assert blind.last_was_reset
    unwrapper = TimerUnwrapper()
    unwrapper.update(before, host_time=0.0)
    assert unwrapper.update(after, host_time=168.5) == after
    assert not unwrapper.last_was_reset and unwrapper.resets == 0
    assert ticks_to_seconds(after - before) == pytest.approx(168.5, abs=0.1)
