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
The device timer's 32-bit rollover.

The timer counts ``records.TICKS_PER_SECOND`` (19,660,800) ticks a second
from power-up and wraps every 2^32 ticks (about 218.45 s), so a driver that
runs longer than that must unwrap it to get a clock that only moves forward.
Which device time a raw value stands for (across wraps, or after a reset)
takes the host time elapsed, which the codec never reads: that is the
driver's sample clock (``device/sample_clock.py``). Ticks become seconds by
dividing by ``TICKS_PER_SECOND`` where they are used.
"""

#: The timer wraps after this many ticks.
TIMER_MODULUS = 1 << 32
