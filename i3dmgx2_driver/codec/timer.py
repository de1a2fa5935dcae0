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
unwrap it to get a clock that only moves forward. A step that neither the
wrap nor (when given) the host time elapsed explains is a device reset,
which the unwrapper reports rather than hides. The codec reads no clock:
host times, when used, are the caller's.
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

    Without host times, forward steps of less than half the range (109 s)
    are taken as they are, across a wrap or not, and anything else starts a
    new epoch. Given the host time of each value, the unwrapper instead picks
    the number of whole wraps that best explains the host time elapsed, so a
    pause of several minutes (a radio outage) is unwrapped correctly, and a
    step the host time cannot explain is a device reset. Either way a new
    epoch counts in ``resets`` and sets ``last_was_reset``, so the caller can
    re-anchor its clock.
    """

    #: How far (s) the device time may disagree with the host time elapsed,
    #: beyond 10 % of it, before the step counts as a reset (host reads can
    #: come late or in bursts; the clocks differ by at most ~0.01 %).
    HOST_TOLERANCE = 2.0

    def __init__(self) -> None:
        self._last: int | None = None
        self._last_host: float | None = None
        self._total = 0
        self.wraps = 0
        self.resets = 0
        self.last_was_reset = False

    def reset(self) -> None:
        """Forget the history (after a reconnect the device may have rebooted)."""
        self._last = None
        self._last_host = None
        self._total = 0
        self.last_was_reset = False

    def update(self, raw: int, host_time: float | None = None) -> int:
        """Return the unwrapped tick count for the next raw timer value."""
        last, last_host = self._last, self._last_host
        self._last, self._last_host = raw, host_time
        if last is None:
            self._total = raw
            self.last_was_reset = False
            return raw
        step = (raw - last) % TIMER_MODULUS
        if host_time is not None and last_host is not None:
            elapsed = (host_time - last_host) * TICKS_PER_SECOND
            wraps = max(0, round((elapsed - step) / TIMER_MODULUS))
            step += wraps * TIMER_MODULUS
            tolerance = (self.HOST_TOLERANCE + 0.1 * abs(elapsed) / TICKS_PER_SECOND)
            forward = abs(step - elapsed) <= tolerance * TICKS_PER_SECOND
        else:
            forward = step < _HALF
        if forward:
            self.wraps += (last + step) // TIMER_MODULUS
            self._total += step
            self.last_was_reset = False
        else:
            self.resets += 1
            self._total = raw
            self.last_was_reset = True
        return self._total
