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
The faults of a running simulation, changed while it runs: ``FaultControl``.

A test changes the faults in effect (``set_faults``), silences the radio
(``stall``) or restarts a sensor (``power_cycle``) while the threads run;
every sensor takes the change under the simulator's lock, and the timed
faults it names are scheduled from now. This is the one place that knows
which sensor a fault hits: the base station (all of them), one address, or
the first sensor.
"""

import collections.abc
import dataclasses
import random
import threading
import time
from typing import Any

from .config import DEFAULT_STREAM, SimulatorConfig
from .fault_schedule import FaultSchedule
from .faults import FaultConfig
from .ground_truth import GroundTruth
from .sensor import SimulatedSensor
from .sensor_unit import SensorUnit, unit_at

Units = collections.abc.Mapping[int, SensorUnit]


def foreign_address(config: SimulatorConfig, faults: FaultConfig) -> int:
    """Return the stranger's address: next to the first sensor's, and none of ours."""
    address = faults.foreign_of(config.address)
    while faults.foreign_address is None and address in config.all_addresses:
        address = faults.foreign_of(address)
    return address


def stall_every(units: Units, start: float, seconds: float) -> None:
    """Silence every sensor from ``start`` for ``seconds``: the base station stalls."""
    for unit in units.values():
        unit.faults.stall(start, seconds)


class FaultControl:
    """
    Changes the faults in effect while the simulation runs; thread-safe.

    ``wake`` is the condition on the simulator's lock the transmitters wait
    on; ``foreign`` the stranger and ``fault_rng`` the first sensor's fault
    choices (which also place the stranger's clock at start); ``started``
    says whether the threads run (a change before start waits for it).
    """

    def __init__(self, config: SimulatorConfig, units: Units, wake: threading.Condition,
                 record: GroundTruth, foreign: SimulatedSensor, fault_rng: random.Random,
                 schedule: FaultSchedule, started: collections.abc.Callable[[], bool]) -> None:
        self._config = config
        self._units = units
        self._wake = wake
        self._record = record
        self._foreign = foreign
        self._fault_rng = fault_rng
        self._schedule = schedule
        self._started = started
        first = unit_at(units, None)
        #: The first sensor's faults in effect (every sensor has the same configuration).
        self._faults = first.faults
        self._inbox = first.inbox

    @property
    def faults(self) -> FaultConfig:
        """Return the faults in effect."""
        return self._faults.config

    def start(self, now: float) -> None:
        """At power-up (lock held): the stranger's clock somewhere, the timed faults from now."""
        self._foreign.power_up(now - 1000.0 * self._fault_rng.random())
        self._schedule.schedule(self._faults.config, now, None)

    def set_faults(self, faults: FaultConfig | None, changes: dict[str, Any]) -> FaultConfig:
        """Replace the fault configuration, or change the fields ``changes`` names."""
        with self._wake:
            old = self._faults.config
            new = faults if faults is not None else dataclasses.replace(old, **changes)
            if not self._config.wireless:
                new.check_wired()
            for unit in self._units.values():
                unit.faults.config = new
            self._foreign.address = foreign_address(self._config, new)
            if new.ignore_first_continuous and not old.ignore_first_continuous:
                self._inbox.ignore_next_continuous = True
            now = time.time()
            started = self._started()
            if new.already_streaming and not old.already_streaming and started:
                for unit in self._units.values():
                    unit.sensor.start_streaming(DEFAULT_STREAM, now)
                    self._record.note_streaming(now, unit.sensor.streaming)
            if started:
                self._schedule.schedule(new, now, None if faults is not None else changes)
            self._wake.notify_all()
        return new

    def stall(self, seconds: float, address: int | None) -> None:
        """Silence from now for ``seconds`` the sensor at ``address`` (None: every sensor)."""
        with self._wake:
            if address is None:
                stall_every(self._units, time.time(), seconds)
            else:
                unit_at(self._units, address).faults.stall(time.time(), seconds)

    def power_cycle(self, off_seconds: float, timer_start: int | None,
                    address: int | None) -> None:
        """Restart the sensor at ``address`` (None: the first) after ``off_seconds`` dark."""
        unit_at(self._units, address).power.cycle(off_seconds, timer_start)
