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
model (motion, clock error, timer, EEPROM), its own faults in effect (a stall
of one sensor leaves the others streaming), its own transmitter thread, whose
packets go through the one line writer under the simulator's lock, so that
the sensors' packets interleave on the line whole, as the base station
forwards them, its own inbox and its own power. :class:`SensorUnit` holds
these for one address: a command that reaches the sensor passes the
firmware's quirks (``FaultConfig.ignore_first_continuous``,
``needs_polled_first``) before ``SimulatedSensor.handle`` sees it, and its
replies are queued on the transmitter; power lost takes what the sensor had
not yet sent with it, power back starts it as from power-up (timer, EEPROM
rate and auto-start). Each change of stream is recorded in the ground truth.
:func:`unit_specs` says how the sensors after the first differ from it, and
:func:`foreign_address` where the stranger stands among them.
"""

import collections.abc
import dataclasses
import random
import threading
import time

from i3dmgx2_driver.codec import framing, layouts as lay
from i3dmgx2_driver.codec.commands import Command
from i3dmgx2_driver.codec.timer import TIMER_MODULUS

from .base_station import BaseStation
from .config import SimulatorConfig
from .faults import FaultConfig, FaultState
from .ground_truth import GroundTruth
from .motion import Motion, MotionConfig
from .sensor import SensorSpec, SimulatedSensor
from .transmitter import LineWriter, SharedLine, Transmitter
from .wired_line import WiredLine

#: Runs an action on the simulator's reader thread after a delay (s).
Post = collections.abc.Callable[[float, collections.abc.Callable[[], None]], None]

#: How far apart the clocks of neighbouring sensors run (ppm), so that a
#: driver mixing up two sensors' clocks shows it.
CLOCK_STEP_PPM = 30.0


def foreign_address(config: SimulatorConfig, faults: FaultConfig) -> int:
    """Return the stranger's address: as set, or next to the first sensor's and none of ours."""
    if faults.foreign_address is not None:
        return faults.foreign_address
    address = config.address % framing.MAX_ADDRESS + framing.MIN_ADDRESS
    while address in config.all_addresses:  # the next one, wrapping inside 1..65534
        address = address % framing.MAX_ADDRESS + framing.MIN_ADDRESS
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
        motion = dataclasses.replace(
            motion, initial_attitude_deg=(roll + 7.0 * i, pitch - 5.0 * i, yaw + 45.0 * i),
            sway_period_s=tuple(p * (1.0 + 0.23 * i) for p in motion.sway_period_s),
            yaw_rate_dps=motion.yaw_rate_dps * (-1.0) ** i)
        out.append((spec, motion))
    return out


class SensorUnit:
    """
    One sensor: its model, faults in effect, transmitter, inbox and power.

    ``seed`` seeds its noise, ``rng`` draws its faults, ``faults`` are the
    faults in effect for it (the first sensor shares the line end's), ``end``
    the line end (base station or wired line), ``writer`` the line writer
    every unit shares, ``shared`` the serial line its packets share with the
    other sensors' (None: one sensor), ``foreign`` the stranger whose packets
    the radio may pick up, ``record`` the ground truth, ``wake`` the
    condition on the simulator's lock, notified when the sensor has
    something new to send; ``post`` schedules the power-up after a power
    cycle's dark time on the reader thread. Call with the simulator's lock
    held; the power methods take it themselves.
    """

    def __init__(self, config: SimulatorConfig, spec: SensorSpec, motion: MotionConfig,
                 seed: int, rng: random.Random, faults: FaultState,
                 end: BaseStation | WiredLine, writer: LineWriter, shared: SharedLine | None,
                 foreign: SimulatedSensor, record: GroundTruth, wake: threading.Condition,
                 post: Post) -> None:
        self.sensor = SimulatedSensor(spec, Motion(motion), seed=seed)
        self.address, self.faults = spec.address, faults
        self.tx = Transmitter(config, self.sensor, end, record, wake, faults, rng, foreign,
                              writer, shared)
        self._record, self._wake, self._post = record, wake, post
        #: Whether a polled request came since the host opened the port.
        self._polled_since_open = False
        #: Whether the next request to stream is ignored (a quirk, armed by the faults).
        self.ignore_next_continuous = faults.config.ignore_first_continuous

    def take_faults(self, new: FaultConfig) -> None:
        """Put ``new`` in effect; the quirk newly asked for is armed for the next request."""
        if new.ignore_first_continuous and not self.faults.config.ignore_first_continuous:
            self.ignore_next_continuous = True
        self.faults.config = new

    # -- the inbox: a command that reached the sensor ---------------------------------------

    def port_opened(self) -> None:
        """Note that the host opened the port (or flushed its input)."""
        self._polled_since_open = False

    def deliver(self, command: Command | None, raw: bytes, now: float) -> str:
        """Hand a command to the sensor; return the outcome ('delivered' or 'ignored')."""
        sensor = self.sensor
        if command is None:
            sensor.handle(raw, now)
            return 'ignored'
        self._record.commands.append((now, command))
        if command.code == lay.SET_CONTINUOUS and command.args[0] != 0:
            if self.ignore_next_continuous:
                self.ignore_next_continuous = False
                return 'ignored'
            if self.faults.config.needs_polled_first and not self._polled_since_open:
                return 'ignored'
        elif command.code not in (lay.SET_CONTINUOUS, lay.STOP_CONTINUOUS):
            self._polled_since_open = True
        ignored_before = sensor.ignored
        for reply in sensor.handle(command, now):
            self.tx.enqueue(reply, 'reply')
        self._record.note_streaming(now, sensor.streaming)
        self._wake.notify_all()
        return 'ignored' if sensor.ignored != ignored_before else 'delivered'

    # -- power ------------------------------------------------------------------------------

    def power_off(self) -> float:
        """Lose power now: the stream stops, the queue is forgotten; return the time."""
        with self._wake:
            self.tx.clear()
            self.sensor.power_off()
            now = time.time()
            self._record.note_streaming(now, self.sensor.streaming)
            return now

    def power_on(self, timer_start: int | None = None) -> None:
        """
        Power up now, the timer at ``timer_start`` (None: the sensor's own, kept from now).

        What was queued before is gone (a power cycle's old queue included).
        """
        with self._wake:
            self.tx.clear()
            self.sensor.power_up(time.time(), timer_start)
            self._record.note_streaming(time.time(), self.sensor.streaming)
            self._wake.notify_all()

    def power_cycle(self, off_seconds: float, timer_start: int | None) -> None:
        """Go dark for ``off_seconds`` (silent both ways), then power up (see PtySimulator)."""
        if timer_start is not None and not 0 <= timer_start < TIMER_MODULUS:
            raise ValueError(f'timer_start must be a uint32, got {timer_start!r}')
        if off_seconds < 0:
            raise ValueError(f'off_seconds must not be negative, got {off_seconds!r}')
        if off_seconds == 0:
            self.power_on(timer_start)
            return
        with self._wake:
            self.faults.stall(self.power_off(), off_seconds)
        self._post(off_seconds, lambda: self.power_on(timer_start))


def unit_at(units: collections.abc.Mapping[int, SensorUnit], address: int | None) -> SensorUnit:
    """Return the sensor at ``address`` (None: the first); ValueError if there is none."""
    if address is None:
        return next(iter(units.values()))
    if address not in units:
        raise ValueError(f'no sensor at address {address}: the sensors are {list(units)}')
    return units[address]
