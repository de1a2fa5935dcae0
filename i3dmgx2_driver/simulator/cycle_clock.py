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
When a simulated 3DM-GX2 computes, and what its timer shows then.

The calculation cycles sit on an exact grid counted from power-up (or from
the last rate change), and the timer is derived from that grid, not from the
absolute time, so that the tick spacing of a stream is exact to the
rounding of one tick: ``384 * divider * (1 + ppm * 1e-6)`` ticks per cycle.
Times are wall-clock seconds, passed in by the caller.
"""

import math

from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.codec.timer import TIMER_MODULUS


class CycleClock:
    """
    The grid of calculation cycles and the device timer; no clock of its own.

    ``rel`` times count seconds from power-up. The next cycle to stream is
    kept here too, so that a stream never repeats or skips a cycle by accident.
    """

    def __init__(self, clock_ppm: float, timer_start: int) -> None:
        #: Timer at power-up.
        self.timer_start = timer_start
        self._tick_rate = rec.TICKS_PER_SECOND * (1.0 + clock_ppm * 1e-6)
        self.restart(0.0, 1.0)

    def restart(self, t: float, rate_hz: float, timer_start: int | None = None) -> None:
        """Start the grid from power-up at wall-clock time ``t`` (the timer at ``timer_start``)."""
        if timer_start is not None:
            self.timer_start = timer_start  # kept from now on, as the sensor's own
        #: Wall-clock time of the last power-up.
        self.power_up_time = t
        self._grid_origin = 0.0
        self._next_index = 0
        #: Seconds between two cycles.
        self.period = 1.0 / rate_hz

    def regrid(self, t: float, rate_hz: float) -> None:
        """Restart the cycle grid at ``t`` with a new rate (a rate change)."""
        self.period = 1.0 / rate_hz
        self._grid_origin = t - self.power_up_time
        self._next_index = 1

    def rel(self, t: float) -> float:
        """Return the seconds from power-up to wall-clock time ``t``."""
        return t - self.power_up_time

    def timer_at(self, t: float) -> int:
        """Return the timer the device shows at wall-clock time ``t``."""
        return self.timer_rel(t - self.power_up_time)

    def timer_rel(self, rel: float) -> int:
        """Return the timer ``rel`` seconds after power-up."""
        return (self.timer_start + round(rel * self._tick_rate)) % TIMER_MODULUS

    def _cycle_rel(self, index: int) -> float:
        return self._grid_origin + index * self.period

    def latest_cycle_rel(self, rel: float) -> float:
        """Return the cycle at or before ``rel``."""
        index = math.floor((rel - self._grid_origin) / self.period + 1e-9)
        return self._cycle_rel(max(index, 0))

    def next_cycle_rel(self, rel: float) -> float:
        """Return the cycle at or after ``rel``."""
        index = math.ceil((rel - self._grid_origin) / self.period - 1e-9)
        return self._cycle_rel(max(index, 0))

    def stream_from(self, t: float) -> None:
        """Make the first cycle after wall-clock time ``t`` the next one streamed."""
        rel = t - self.power_up_time
        self._next_index = max(math.floor((rel - self._grid_origin) / self.period) + 1, 0)
        while self._cycle_rel(self._next_index) <= rel:
            self._next_index += 1

    @property
    def next_time(self) -> float:
        """Wall-clock time of the next cycle to stream."""
        return self.power_up_time + self._cycle_rel(self._next_index)

    def take(self) -> float:
        """Take the next cycle to stream; return its ``rel`` time."""
        rel = self._cycle_rel(self._next_index)
        self._next_index += 1
        return rel

    def skip_to(self, t: float) -> int:
        """Skip the cycles to stream before ``t``; return how many."""
        rel = t - self.power_up_time
        target = max(math.ceil((rel - self._grid_origin) / self.period), self._next_index)
        skipped, self._next_index = target - self._next_index, target
        return skipped
