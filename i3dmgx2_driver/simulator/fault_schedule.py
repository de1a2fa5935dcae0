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
The timed faults of a ``FaultConfig``: a stall, an unplug, a power cycle, some seconds in.

They count from when the configuration takes effect (``PtySimulator.start()``
or ``set_faults()``); a change of configuration schedules again only the
ones it names.
"""

import collections.abc
from collections.abc import Callable

from .cable import Cable
from .faults import FaultConfig
from .power import Post, SensorPower


class FaultSchedule:
    """Starts the timed faults on time; call with the simulator's lock held."""

    def __init__(self, stall: Callable[[float, float], None], post: Post, cable: Cable,
                 power: SensorPower) -> None:
        #: ``stall(start, seconds)`` silences what the stall hits (a sensor, or all of them).
        self._stall = stall
        self._post = post
        self._cable = cable
        self._power = power

    def schedule(self, faults: FaultConfig, now: float,
                 changes: collections.abc.Collection[str] | None) -> None:
        """Schedule from ``now`` the timed faults (``changes`` None: all; else those it names)."""
        def asked(*names: str) -> bool:
            return changes is None or any(name in changes for name in names)

        if faults.stall_at is not None and asked('stall_at', 'stall_seconds'):
            self._stall(now + faults.stall_at, faults.stall_seconds)
        if faults.unplug_at is not None and asked('unplug_at', 'unplug_seconds'):
            seconds = faults.unplug_seconds
            self._post(faults.unplug_at, lambda: self._cable.unplug(seconds))
        if faults.power_cycle_at is not None and asked(
                'power_cycle_at', 'power_off_seconds', 'power_up_timer'):
            off, timer = faults.power_off_seconds, faults.power_up_timer
            self._post(faults.power_cycle_at, lambda: self._power.cycle(off, timer))
