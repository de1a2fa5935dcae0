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
The simulated sensor behind a pseudo-terminal: ``PtySimulator``, which puts the parts together.

A driver opens ``sim.port`` exactly as it would open ``/dev/ttyUSB0`` and
talks to it with pyserial. Behind it sits either a wireless base station
(``base_station``: ACK/NACK, ping) and a wireless ``SimulatedSensor``, or a
wired sensor on its own line (``wired_line``). Two threads: the
``HostReader`` (``host_reader``) reads the host's bytes and runs the
scheduled actions (unplug and replug by the ``Cable``, power-up after a
power cycle by the ``SensorPower``, the timed faults of the
``FaultSchedule``); the ``Transmitter`` writes the
sensor's records at their scheduled times, with their ``PacketFaults``,
through the ``LineWriter`` to the pty (``pty_port``). A command that
reaches the sensor goes through its ``SensorInbox`` (the firmware's
quirks). Every data packet, written or lost, is recorded in ``sim.truth``
(``ground_truth``, read through ``TruthQueries``) with the time its
sample was taken and the time its last byte was written, so that tests and
benchmarks can compare what the driver publishes with what really happened.

Wired (``SimulatorConfig(wireless=False)``), the sensor sits on the port
itself and reads the host's bytes as a plain stream: it picks out the
command bytes it knows (every command but the wireless ping) followed by
their confirmation and argument bytes, ignores and counts every other byte
(``stats.host_bytes_ignored``), and answers with wired records (echo, data,
uint16 checksum). No ACK, no NACK, no ping answer, no LQI/RSSI. So a driver
that sends packets to a wired sensor gets no ACK, and wired replies only to
the commands that happen to sit whole inside its packets (a packet for
0xC2 holds the byte 0xC2: the sensor answers it, wired; a header byte that
happens to be a command byte may swallow the start of the next packet):
exactly what a byte-reading device would do. (docs/protocol.md §3 says wired
sensors accept packets too; this model is the stricter firmware, so that a
driver set up for the wrong framing shows it at once.) The other way round,
the wireless base station takes only packets and pings: raw commands are
skipped as garbage and unanswered, though a sensor already streaming is
heard. Unplugging a wired sensor's cable powers it off: it comes back
from power-up (timer restarted, EEPROM auto-start) when plugged in again.
The radio faults (command loss, NACK, foreign packets, corrupted length
bytes) do not exist wired and are refused.
"""

import atexit
import dataclasses
import random
import threading
import time
import typing
from typing import Any

from i3dmgx2_driver.codec.commands import Command

from .base_station import BaseStation
from .cable import Cable
from .config import DEFAULT_STREAM, SimulatorConfig
from .fault_schedule import FaultSchedule
from .faults import FaultConfig, FaultState
from .ground_truth import GroundTruth
from .host_reader import HostReader
from .line_writer import LineWriter
from .motion import Motion, MotionConfig
from .pty_port import PtyPort
from .sensor import SensorSpec, SimulatedSensor
from .sensor_unit import AllInboxes, SensorUnit, unit_specs
from .transmitter import SharedLine
from .truth_queries import TruthQueries
from .wired_line import WiredLine

if typing.TYPE_CHECKING:  # typing.Self is new in Python 3.11; Jazzy allows 3.10
    from typing import Self

__all__ = ['PtySimulator']


class PtySimulator(TruthQueries):
    """
    A 3DM-GX2 and its wireless base station on a pseudo-terminal, or a wired 3DM-GX2.

    Use as a context manager, or call :meth:`start` and :meth:`stop`. After
    start, ``port`` is the path to open (stable across unplugs). The ground
    truth (``truth``, ``commands``, ``host_log``, ``stats``, ``stream_changes``:
    see :class:`TruthQueries`) is thread-safe to read at any time; the
    properties return copies. The module's docstring tells how a wired
    sensor differs.
    """

    def __init__(self, config: SimulatorConfig | None = None, **overrides: Any) -> None:
        if config is None:
            config = SimulatorConfig(**overrides)
        elif overrides:
            config = dataclasses.replace(config, **overrides)
        self.config = config
        seeds = random.Random(config.seed)
        # The first sensor's seeds are drawn as they always were: a seeded run of
        # one sensor is the same run it was before there could be several.
        sensor_seed = seeds.getrandbits(64)
        foreign = SimulatedSensor(
            SensorSpec(self._foreign_address(config.faults), '0000', clock_ppm=-25.0,
                       timer_start=seeds.getrandbits(32)),
            Motion(MotionConfig(static=True)), seed=seeds.getrandbits(64))
        self._fault_rng = random.Random(seeds.getrandbits(64))
        command_rng = random.Random(seeds.getrandbits(64))
        chunk_rng = random.Random(seeds.getrandbits(64))

        #: Guards the sensor, the queues and the ground truth. Lock order: ``lock``
        #: may be held while taking the port's ``io_lock``, never the reverse.
        self.lock = threading.RLock()
        self._tx_wake = threading.Condition(self.lock)
        changed = threading.Condition(self.lock)
        record = GroundTruth(config.truth_limit, changed)
        super().__init__(record, changed)
        self._stop = threading.Event()
        self._pty = PtyPort(config.symlink, config.link_via_proc)
        #: Every sensor's parts, by address, in the order given (sensor_unit.py).
        self.units: dict[int, SensorUnit] = {}
        self._end: BaseStation | WiredLine
        writer = LineWriter(self._pty, record, config.chunks, config.chunk_gap_s, chunk_rng)
        station_faults = FaultState(config.faults)
        if config.wireless:
            self._end = BaseStation(self.units, record, self._pty, station_faults, command_rng)
        else:
            self._end = WiredLine(record, self._deliver, station_faults)
        self._reader = HostReader(self._pty, self._end, record, AllInboxes(self.units),
                                  changed)
        specs = unit_specs(config, seeds)
        line = SharedLine() if len(specs) > 1 else None
        for i, (spec, motion) in enumerate(specs):
            self.units[spec.address] = SensorUnit(
                config, spec, motion, sensor_seed if i == 0 else seeds.getrandbits(64),
                self._fault_rng if i == 0 else random.Random(seeds.getrandbits(64)),
                self._end, writer, record, self._tx_wake, self._reader.post, foreign,
                station_faults if i == 0 else None, line)
        first = next(iter(self.units.values()))
        #: The device model of the first sensor; touch it only while holding ``sim.lock``.
        self.sensor = first.sensor
        self._faults, self._packet_faults = first.faults, first.packet_faults
        self._tx, self._inbox, self._power = first.tx, first.inbox, first.power
        self._cable = Cable(self._pty, self._reader, record, changed,
                            None if config.wireless else self._power, self._stop)
        target = self.units.get(config.fault_address) if config.fault_address else None
        self._schedule = FaultSchedule(
            target.faults.stall if target is not None else self._stall_all, self._reader.post,
            self._cable, (target or first).power)
        self._threads: list[threading.Thread] = []
        self._started = False
        #: Wall-clock time of start() (the sensor's power-up).
        self.start_time: float | None = None

    # -- lifecycle --------------------------------------------------------------------------

    def start(self) -> 'PtySimulator':
        """Create the port, power the sensor up and start the threads."""
        if self._started:
            raise RuntimeError('the simulator is already started')
        self._stop.clear()
        self._pty.create()
        self._reader.open_pipe()
        self._reader.plug_in()
        now = time.time()
        with self.lock:
            self.start_time = now
            for unit in self.units.values():
                unit.sensor.power_up(now)
                self._record.note_streaming(now, unit.sensor.streaming)
            self._packet_faults.foreign.power_up(now - 1000.0 * self._fault_rng.random())
            self._schedule.schedule(self._faults.config, now, None)
        self._started = True
        # An interpreter that exits without stop() still removes the port.
        atexit.register(self.stop)
        self._threads = [
            threading.Thread(target=self._reader.run, args=(self._stop,), name='gx2sim-rx',
                             daemon=True),
            *(threading.Thread(target=unit.tx.run, args=(self._stop,),
                               name='gx2sim-tx' if i == 0 else f'gx2sim-tx-{unit.address}',
                               daemon=True)
              for i, unit in enumerate(self.units.values())),
        ]
        for thread in self._threads:
            thread.start()
        return self

    def stop(self) -> None:
        """Stop the threads, close the pty and remove the port symlink."""
        if not self._started:
            return
        self._stop.set()
        self._reader.wake()
        with self.lock:
            self._tx_wake.notify_all()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._pty.pull_out()
        self._reader.close_pipe()
        self._pty.remove()
        self._started = False
        atexit.unregister(self.stop)

    def __enter__(self) -> 'Self':
        """Start (if not yet started) for a ``with`` block."""
        if not self._started:
            self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Stop at the end of the ``with`` block."""
        self.stop()

    @property
    def started(self) -> bool:
        """Whether the threads run."""
        return self._started

    # -- the port ---------------------------------------------------------------------------

    @property
    def port(self) -> str | None:
        """Path to open: a symlink that survives unplug and replug (None before start)."""
        return self._pty.path

    @property
    def device(self) -> str | None:
        """Return the pseudo-terminal the symlink points to now (None while unplugged)."""
        return self._pty.device

    @property
    def link_target(self) -> str | None:
        """Return what the port symlink points to now: ``/proc/<pid>/fd/<n>`` or the device."""
        return self._pty.link_target

    @property
    def plugged(self) -> bool:
        """Whether the port exists now (False between unplug and replug)."""
        return self._pty.plugged.is_set()

    @property
    def last_port_open(self) -> float | None:
        """Wall-clock time the host last opened the port (or flushed its input)."""
        return self._reader.last_port_open

    def unplug(self, seconds: float | None = None, timeout: float = 5.0) -> None:
        """
        Unplug the base station now; plug it back in after ``seconds``.

        The pty closes (the host's reads and writes fail), the symlink goes,
        and a new pty appears at the same path after the delay (None: only on
        :meth:`replug`). A wireless sensor keeps running meanwhile; a wired one
        loses its power and starts again from power-up when plugged back in.
        Returns once the port is gone.
        """
        self._cable.pull_out(seconds, timeout)

    def replug(self, timeout: float = 5.0) -> bool:
        """Plug the base station back in now; return whether the port is back."""
        return self._cable.plug_in(timeout)

    def wait_for_port(self, timeout: float = 10.0) -> bool:
        """Wait until the port exists (after an unplug); return whether it does."""
        return self._pty.plugged.wait(timeout)

    # -- run-time control -------------------------------------------------------------------

    def stall(self, seconds: float, address: int | None = None) -> None:
        """
        Silence from now for ``seconds`` (radio; wired: a hung sensor): nothing gets through.

        ``address`` stalls that sensor alone (its radio link), the others
        streaming on; None the base station (every sensor).
        """
        with self.lock:
            if address is None:
                self._stall_all(time.time(), seconds)
            else:
                self._unit(address).faults.stall(time.time(), seconds)

    def _stall_all(self, start: float, seconds: float) -> None:
        for unit in self.units.values():
            unit.faults.stall(start, seconds)

    def _unit(self, address: int | None) -> SensorUnit:
        """Return the sensor at ``address`` (None: the first); ValueError if there is none."""
        if address is None:
            return next(iter(self.units.values()))
        if address not in self.units:
            raise ValueError(f'no sensor at address {address}: the sensors are '
                             f'{list(self.units)}')
        return self.units[address]

    def _foreign_address(self, faults: FaultConfig) -> int:
        """Return the stranger's address: next to the first sensor's, and none of ours."""
        address = faults.foreign_of(self.config.address)
        while faults.foreign_address is None and address in self.config.all_addresses:
            address = faults.foreign_of(address)
        return address

    @property
    def faults(self) -> FaultConfig:
        """Return the faults in effect."""
        return self._faults.config

    def set_faults(self, faults: FaultConfig | None = None, **changes: Any) -> FaultConfig:
        """
        Replace the fault configuration, or change some of its fields.

        Scheduled faults (``stall_at``, ``unplug_at``) given here count from
        now. Turning ``already_streaming`` on makes the sensor stream 0xCC now.
        A wired simulator refuses the radio's faults (ValueError).
        """
        with self.lock:
            old = self._faults.config
            new = faults if faults is not None else dataclasses.replace(old, **changes)
            if not self.config.wireless:
                new.check_wired()
            for unit in self.units.values():
                unit.faults.config = new
            self._packet_faults.foreign.address = self._foreign_address(new)
            if new.ignore_first_continuous and not old.ignore_first_continuous:
                self._inbox.ignore_next_continuous = True
            now = time.time()
            if new.already_streaming and not old.already_streaming and self._started:
                for unit in self.units.values():
                    unit.sensor.start_streaming(DEFAULT_STREAM, now)
                    self._record.note_streaming(now, unit.sensor.streaming)
            if self._started:
                self._schedule.schedule(new, now, None if faults is not None else changes)
            self._tx_wake.notify_all()
        return new

    def set_moving(self, moving: bool) -> None:
        """Start or stop the sensor's motion now (a capture while moving goes wrong)."""
        with self.lock:
            self.sensor.motion.set_static(not moving, self.sensor.clock.rel(time.time()))

    def set_rate(self, rate_hz: float | None) -> None:
        """Override the calculation rate now (None: back to the EEPROM divider)."""
        with self.lock:
            self.sensor.set_rate_override(rate_hz, time.time())
            self._tx_wake.notify_all()

    def power_cycle(self, off_seconds: float = 0.0, timer_start: int | None = None,
                    address: int | None = None) -> None:
        """
        Restart the sensor: dark for ``off_seconds``, then up again as from power-up.

        While dark nothing is sampled, sent or answered (to the host it is a
        radio silence). At power-up the timer starts at ``timer_start`` (None:
        the sensor's configured ``timer_start``; a value given here stays the
        sensor's from then on), the stream as the EEPROM auto-start says.
        ``address``: that sensor, the others going on; None: the first.
        """
        self._unit(address).power.cycle(off_seconds, timer_start)

    # -- the device now ---------------------------------------------------------------------

    @property
    def streaming(self) -> int:
        """Command byte the (first) sensor streams now, 0 when polled."""
        with self.lock:
            return self.sensor.streaming

    def streaming_of(self, address: int) -> int:
        """Command byte the sensor at ``address`` streams now, 0 when polled."""
        with self.lock:
            return self._unit(address).sensor.streaming

    @property
    def addresses(self) -> tuple[int, ...]:
        """Return the address of every sensor behind the base station, the first first."""
        return tuple(self.units)

    @property
    def wireless(self) -> bool:
        """Whether this is a base station with a wireless sensor (False: a wired sensor)."""
        return self.config.wireless

    @property
    def eeprom(self) -> dict[int, int]:
        """Return the sensor's EEPROM words now (a copy): presets and what the host wrote."""
        with self.lock:
            return dict(self.sensor.eeprom)

    def _deliver(self, command: Command | None, raw: bytes, now: float) -> str:
        """Hand a command to the sensor's inbox (built after the line end that calls this)."""
        return self._inbox.deliver(command, raw, now)
