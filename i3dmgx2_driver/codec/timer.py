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
The device timer: ticks to seconds, and unwrapping its 32-bit rollover.

The timer counts 19,660,800 ticks a second from power-up and wraps every
2^32 ticks (about 218.45 s), so a driver that runs longer than that must
unwrap it to get a clock that only moves forward. A jump backwards of more
than half the range is a wrap; anything else that goes backwards is a device
reset (or a reordered record), which the unwrapper reports rather than hides.
"""


from .records import TICKS_PER_SECOND

#: The timer wraps after this many ticks.
TIMER_MODULUS = 1 << 32
_HALF = TIMER_MODULUS // 2


def ticks_to_seconds(ticks: int) -> float:
    """Convert timer ticks (raw or unwrapped) to seconds."""
    return ticks / TICKS_PER_SECOND


def seconds_to_ticks(seconds: float) -> int:
    """Convert seconds to whole timer ticks (rounded to nearest)."""
    return round(seconds * TICKS_PER_SECOND)


class TimerUnwrapper:
    """
    Turn successive raw 32-bit timer values into a monotonic tick count.

    Forward steps of less than half the range are taken as they are, across
    a wrap or not. A backward step starts a new epoch: ``resets`` counts them
    and ``last_was_reset`` tells the caller to re-anchor its clock.
    """

    def __init__(self) -> None:
        self._last: int | None = None
        self._total = 0
        self.wraps = 0
        self.resets = 0
        self.last_was_reset = False

    def reset(self) -> None:
        """Forget the history (after a reconnect the device may have rebooted)."""
        self._last = None
        self._total = 0
        self.last_was_reset = False

    def update(self, raw: int) -> int:
        """Return the unwrapped tick count for the next raw timer value."""
        last = self._last
        self._last = raw
        if last is None:
            self._total = raw
            self.last_was_reset = False
            return raw
        step = (raw - last) % TIMER_MODULUS
        if step < _HALF:
            if raw < last:
                self.wraps += 1
            self._total += step
            self.last_was_reset = False
        else:
            self.resets += 1
            self._total = raw
            self.last_was_reset = True
        return self._total
