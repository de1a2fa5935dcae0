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
How one simulation's parts are built and wired together: ``SimulatorParts``.

Everything a configuration asks for is made here, once, in one order: the
seeds (drawn in the order they always were, so that a seeded run stays the
same run), the lock and its conditions, the ground truth, the pty, the line
end (base station or wired line), the reader, every sensor's unit, the
cable and the fault schedule. ``PtySimulator`` hands each of its pieces only
the parts it uses. The stranger's address and a stall of every sensor are
worked out here for the build and again by the simulator when its faults
change.
"""

import collections.abc
import functools
import random
import threading

from i3dmgx2_driver.codec.commands import Command

from .base_station import BaseStation
from .cable import Cable
from .config import SimulatorConfig
from .fault_schedule import FaultSchedule
from .faults import FaultConfig, FaultState
from .ground_truth import GroundTruth
from .host_reader import HostReader
from .line_writer import LineWriter
from .motion import Motion, MotionConfig
from .pty_port import PtyPort
from .sensor import SensorSpec, SimulatedSensor
from .sensor_unit import (
    AllInboxes, SensorUnit, unit_at, unit_specs, UnitFaults, UnitLine, UnitSensor,
)
from .transmitter import SharedLine, Transmitter
from .wired_line import WiredLine

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


class SimulatorParts:
    """Every part of one simulation, built from ``config`` and wired; nothing runs yet."""

    def __init__(self, config: SimulatorConfig) -> None:
        seeds = random.Random(config.seed)
        # The first sensor's seeds are drawn as they always were: a seeded run of
        # one sensor is the same run it was before there could be several.
        sensor_seed = seeds.getrandbits(64)
        #: The stranger whose packets the radio may pick up.
        self.foreign = SimulatedSensor(
            SensorSpec(foreign_address(config, config.faults), '0000', clock_ppm=-25.0,
                       timer_start=seeds.getrandbits(32)),
            Motion(MotionConfig(static=True)), seed=seeds.getrandbits(64))
        #: The first sensor's fault choices.
        self.fault_rng = random.Random(seeds.getrandbits(64))
        command_rng = random.Random(seeds.getrandbits(64))
        chunk_rng = random.Random(seeds.getrandbits(64))

        #: Guards the sensor, the queues and the ground truth. Lock order: ``lock``
        #: may be held while taking the port's ``io_lock``, never the reverse.
        self.lock = threading.RLock()
        #: What the transmitters wait on; notified when their work may have changed.
        self.wake = threading.Condition(self.lock)
        #: Notified on every new entry of the ground truth (and when the port is back).
        self.changed = threading.Condition(self.lock)
        self.record = GroundTruth(config.truth_limit, self.changed)
        #: Set to stop every thread.
        self.stop = threading.Event()
        self.pty = PtyPort(config.symlink, config.link_via_proc)
        #: Every sensor's parts, by address, in the order given (sensor_unit.py).
        self.units: dict[int, SensorUnit] = {}
        self.end: BaseStation | WiredLine
        writer = LineWriter(self.pty, self.record, config.chunks, config.chunk_gap_s, chunk_rng)
        station_faults = FaultState(config.faults)
        if config.wireless:
            self.end = BaseStation(self.units, self.record, self.pty, station_faults,
                                   command_rng)
        else:
            self.end = WiredLine(self.record, self._deliver, station_faults)
        self.reader = HostReader(self.pty, self.end, self.record, AllInboxes(self.units),
                                 self.changed)
        specs = unit_specs(config, seeds)
        line = UnitLine(self.end, writer, SharedLine() if len(specs) > 1 else None)
        for i, (spec, motion) in enumerate(specs):
            is_first = i == 0
            sensor = UnitSensor(spec, motion, sensor_seed if is_first else seeds.getrandbits(64))
            faults = UnitFaults(
                self.fault_rng if is_first else random.Random(seeds.getrandbits(64)),
                self.foreign, station_faults if is_first else None)
            self.units[spec.address] = SensorUnit(config, sensor, line, faults, self.record,
                                                  self.wake, self.reader.post)
        first = unit_at(self.units, None)
        self._first_inbox = first.inbox
        self.cable = Cable(self.pty, self.reader, self.record, self.changed,
                           None if config.wireless else first.power, self.stop)
        target = self.units.get(config.fault_address) if config.fault_address else None
        self.schedule = FaultSchedule(
            target.faults.stall if target is not None
            else functools.partial(stall_every, self.units),
            self.reader.post, self.cable, (target or first).power)

    def transmitters(self) -> list[tuple[str, Transmitter]]:
        """Return each sensor's transmitter with the name of its thread (the first: plain)."""
        return [('gx2sim-tx' if i == 0 else f'gx2sim-tx-{unit.address}', unit.tx)
                for i, unit in enumerate(self.units.values())]

    def _deliver(self, command: Command | None, raw: bytes, now: float) -> str:
        """Hand a command to the first inbox (built after the line end that calls this)."""
        return self._first_inbox.deliver(command, raw, now)
