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
One sensor behind the base station, with everything that is its own.

A base station serves every sensor on its radio channel: each has its own
model (motion, clock error, timer, EEPROM), its own inbox (the firmware's
quirks), its own power, its own faults in effect (a stall of one sensor
leaves the others streaming) and its own transmitter thread, whose packets
go through the one line writer under the simulator's lock, so that the
sensors' packets interleave on the line whole, as the base station forwards
them. :class:`SensorUnit` holds these parts for one address;
:func:`unit_specs` says how the sensors after the first differ from it, and
:func:`foreign_address` where the stranger stands among them.
"""

import collections.abc
import dataclasses
import random
import threading

from .base_station import BaseStation
from .config import SimulatorConfig
from .faults import FaultConfig, FaultState
from .ground_truth import GroundTruth
from .inbox import SensorInbox
from .line_writer import LineWriter
from .motion import Motion, MotionConfig
from .packet_faults import PacketFaults
from .power import Post, SensorPower
from .sensor import SensorSpec, SimulatedSensor
from .transmitter import SharedLine, Transmitter
from .wired_line import WiredLine

#: How far apart the clocks of neighbouring sensors run (ppm), so that a
#: driver mixing up two sensors' clocks shows it.
CLOCK_STEP_PPM = 30.0


def foreign_address(config: SimulatorConfig, faults: FaultConfig) -> int:
    """Return the stranger's address: next to the first sensor's, and none of ours."""
    address = faults.foreign_of(config.address)
    while faults.foreign_address is None and address in config.all_addresses:
        address = faults.foreign_of(address)
    return address


def unit_specs(config: SimulatorConfig,
               seeds: random.Random) -> list[tuple[SensorSpec, MotionConfig]]:
    """
    Return the spec and motion of every sensor, the first as ``config`` says.

    Each later sensor has a serial number ending in its address, a clock
    ``CLOCK_STEP_PPM`` further off, a timer started elsewhere, and a resting
    pose and sway of its own, so that no two sensors' records look alike.
    """
    first = config.sensor_spec
    out = [(first, config.sensor_motion)]
    for i, address in enumerate(config.all_addresses[1:], start=1):
        spec = dataclasses.replace(
            first, address=address, serial_number=f'{(3 + i) % 10}{address % 1000:03d}',
            clock_ppm=config.clock_ppm - CLOCK_STEP_PPM * i,
            timer_start=seeds.getrandbits(32), firmware_version=config.firmware_of(address))
        motion = config.sensor_motion
        roll, pitch, yaw = motion.initial_attitude_deg
        periods = motion.sway_period_s
        motion = dataclasses.replace(
            motion, initial_attitude_deg=(roll + 7.0 * i, pitch - 5.0 * i, yaw + 45.0 * i),
            sway_period_s=tuple(p * (1.0 + 0.23 * i) for p in periods),
            yaw_rate_dps=motion.yaw_rate_dps * (-1.0) ** i)
        out.append((spec, motion))
    return out


class SensorUnit:
    """
    The parts of one sensor: model, faults, transmitter, inbox, power.

    ``seed`` seeds its noise, ``rng`` draws its faults, ``faults`` are the
    faults in effect for it (the first sensor shares the line end's), ``end``
    the line end (base station or wired line), ``writer`` the line writer
    every unit shares, ``shared`` the serial line its packets share with the
    other sensors' (None: one sensor), ``foreign`` the stranger whose packets
    the radio may pick up, ``record`` the ground truth, ``wake`` the
    condition on the simulator's lock; ``post`` schedules actions on its
    reader thread.
    """

    def __init__(self, config: SimulatorConfig, spec: SensorSpec, motion: MotionConfig,
                 seed: int, rng: random.Random, faults: FaultState,
                 end: BaseStation | WiredLine, writer: LineWriter, shared: SharedLine | None,
                 foreign: SimulatedSensor, record: GroundTruth, wake: threading.Condition,
                 post: Post) -> None:
        self.sensor = SimulatedSensor(spec, Motion(motion), seed=seed)
        self.address = spec.address
        self.faults = faults
        packet_faults = PacketFaults(faults, rng, end, foreign, writer, record)
        self.tx = Transmitter(config, self.sensor, end, record, wake, packet_faults, writer,
                              shared)
        self.inbox = SensorInbox(self.sensor, record, self.tx, wake, faults)
        self.power = SensorPower(self.sensor, self.tx, record, wake, faults, post)


def unit_at(units: collections.abc.Mapping[int, SensorUnit], address: int | None) -> SensorUnit:
    """Return the sensor at ``address`` (None: the first); ValueError if there is none."""
    if address is None:
        return next(iter(units.values()))
    if address not in units:
        raise ValueError(f'no sensor at address {address}: the sensors are {list(units)}')
    return units[address]
