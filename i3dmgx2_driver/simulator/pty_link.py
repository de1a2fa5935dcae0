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
wired sensor on its own line (``wired_line``). Two kinds of thread: the
``HostReader`` (``host_reader``) reads the host's bytes and runs the
scheduled actions (unplugging and replugging the cable, power-up after a
power cycle, the timed faults this class schedules); one ``Transmitter``
a sensor (``SensorUnit``, ``sensor_unit``) writes the sensor's records at
their scheduled times, with their faults, through the ``LineWriter`` to
the pty (``pty_port``). A command that reaches the sensor goes through
its ``SensorUnit`` (the firmware's quirks). Every data packet, written or
lost, is recorded in ``sim.truth`` (``ground_truth``, read through
``TruthQueries``) with the time its sample was taken and the time its last
byte was written, so that tests and benchmarks can compare what the driver
publishes with what really happened.

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

Start creates the pty and its symlink, powers the sensors up (under the
lock) and starts the threads: the reader and one transmitter per sensor.
Stop ends them and removes the port, also at interpreter exit if nobody
called it, so that no symlink is left behind. The order of these steps is
what keeps a host from seeing a port before its sensor is up, or a sensor
after its port is gone. While it runs, the faults in effect change
(``set_faults``), the radio is silenced (``stall``) or a sensor restarted
(``power_cycle``): every sensor takes the change under the lock, and the
timed faults it names are scheduled from now. This class is the one place
that knows which sensor a fault hits: the base station (all of them), one
address, or the first sensor.
"""

import atexit
import collections.abc
import dataclasses
import functools
import random
import threading
import time
from typing import Any

from .base_station import BaseStation
from .config import DEFAULT_STREAM, SimulatorConfig
from .faults import FaultConfig, FaultState
from .ground_truth import GroundTruth, TruthQueries
from .host_reader import HostReader
from .motion import Motion, MotionConfig
from .pty_port import PtyPort
from .sensor import SensorSpec, SimulatedSensor
from .sensor_unit import foreign_address, SensorUnit, unit_at, unit_specs
from .transmitter import LineWriter, SharedLine
from .wired_line import WiredLine

__all__ = ['PtySimulator']


class PtySimulator(TruthQueries):
    """
    A 3DM-GX2 and its wireless base station on a pseudo-terminal, or a wired 3DM-GX2.

    Use as a context manager, or call :meth:`start` and :meth:`stop` (from
    one thread). After start, ``port`` is the path to open (stable across
    unplugs); ``pty`` is the pseudo-terminal behind it and ``host_reader``
    the thread that reads the host's bytes. The ground truth (``truth``,
    ``commands``, ``host_log``, ``stats``, ``stream_changes``: see
    :class:`TruthQueries`) is thread-safe to read at any time; the
    properties return copies. The module's docstring tells how a wired
    sensor differs. It builds every part once from the configuration, in one
    order, starts and stops them and changes their faults: it is the face
    that tests, the harness and the benchmarks use.

    The run-time control (``unplug``, ``replug``, ``stall``, ``set_faults``,
    ``set_moving``, ``set_rate``, ``power_cycle``) is the simulator's control
    surface for them: the package never calls it (the command line schedules
    its faults through the configuration instead), and a fault no test,
    harness or benchmark asks for has no method here.
    """

    def __init__(self, config: SimulatorConfig | None = None, **overrides: Any) -> None:
        if config is None:
            config = SimulatorConfig(**overrides)
        elif overrides:
            config = dataclasses.replace(config, **overrides)
        self.config = config
        seeds = random.Random(config.seed)
        # The seeds are drawn in the order they always were, the first sensor's
        # first: a seeded run of one sensor is the same run it was before there
        # could be several.
        sensor_seed = seeds.getrandbits(64)
        #: The stranger whose packets the radio may pick up.
        self._foreign = SimulatedSensor(
            SensorSpec(foreign_address(config, config.faults), '0000', clock_ppm=-25.0,
                       timer_start=seeds.getrandbits(32)),
            Motion(MotionConfig(static=True)), seed=seeds.getrandbits(64))
        self._fault_rng = random.Random(seeds.getrandbits(64))
        command_rng, chunk_rng = (random.Random(seeds.getrandbits(64)) for _ in range(2))
        #: Guards the sensor, the queues and the ground truth. Lock order: ``lock``
        #: may be held while taking the port's ``io_lock``, never the reverse.
        self.lock = threading.RLock()
        #: What the transmitters wait on; notified when their work may have changed.
        self._wake = threading.Condition(self.lock)
        changed = threading.Condition(self.lock)
        record = GroundTruth(config.truth_limit, changed)
        super().__init__(record, changed)
        self._stop = threading.Event()
        #: The pseudo-terminal behind ``port``: ``device`` (the pty now, None while
        #: unplugged), ``link_target`` (what the symlink points to now) and
        #: ``plugged`` (an event, set while the port exists).
        self.pty = PtyPort(config.symlink, config.link_via_proc)
        #: Every sensor's parts, by address, in the order given (sensor_unit.py).
        self.units: dict[int, SensorUnit] = {}
        writer = LineWriter(self.pty, record, config.chunks, config.chunk_gap_s, chunk_rng)
        station_faults = FaultState(config.faults)
        end = (BaseStation(self.units, record, self.pty, station_faults, command_rng)
               if config.wireless else WiredLine(self.units, record))
        #: Reads the host's bytes and runs the scheduled actions.
        self.host_reader = HostReader(self.pty, end, record, self._port_opened, changed)
        specs = unit_specs(config, seeds)
        shared = SharedLine() if len(specs) > 1 else None
        for i, (spec, motion) in enumerate(specs):
            seed = sensor_seed if i == 0 else seeds.getrandbits(64)
            rng = self._fault_rng if i == 0 else random.Random(seeds.getrandbits(64))
            self.units[spec.address] = SensorUnit(
                config, spec, motion, seed, rng,
                station_faults if i == 0 else FaultState(config.faults), end, writer, shared,
                self._foreign, record, self._wake, self.host_reader.post)
        #: The first sensor: its faults in effect are every sensor's configuration.
        self._first = unit_at(self.units, None)
        #: The device model of the first sensor; touch it only while holding ``sim.lock``.
        self.sensor = self._first.sensor
        self._threads: list[threading.Thread] = []
        #: Path to open: a symlink that survives unplug and replug (None before start).
        self.port: str | None = None
        #: Whether the threads run.
        self.started = False
        #: Wall-clock time of start() (the sensor's power-up).
        self.start_time: float | None = None

    def _port_opened(self) -> None:
        """Note on every sensor that the host opened the port (or flushed its input)."""
        for unit in self.units.values():
            unit.port_opened()

    # -- lifecycle --------------------------------------------------------------------------

    def start(self) -> 'PtySimulator':
        """Create the port, power the sensor up and start the threads."""
        if self.started:
            raise RuntimeError('the simulator is already started')
        self._stop.clear()
        self.port = self.pty.create()
        self.host_reader.open_pipe()
        self.host_reader.plug_in()
        with self._wake:
            self.start_time = now = time.time()
            # Every sensor up, then the stranger's clock somewhere; the timed faults from now.
            for unit in self.units.values():
                unit.sensor.power_up(now)
                self._record.note_streaming(now, unit.sensor.streaming)
            self._foreign.power_up(now - 1000.0 * self._fault_rng.random())
            self._schedule(self._first.faults.config, now, None)
        self.started = True
        # An interpreter that exits without stop() still removes the port.
        atexit.register(self.stop)
        self._threads = [
            threading.Thread(target=self.host_reader.run, args=(self._stop,),
                             name='gx2sim-rx', daemon=True),
            *(threading.Thread(target=unit.tx.run, args=(self._stop,), daemon=True,
                               name='gx2sim-tx' if i == 0 else f'gx2sim-tx-{unit.address}')
              for i, unit in enumerate(self.units.values())),
        ]
        for thread in self._threads:
            thread.start()
        return self

    def stop(self) -> None:
        """Stop the threads, close the pty and remove the port symlink."""
        if not self.started:
            return
        self._stop.set()
        self.host_reader.wake()
        with self._wake:
            self._wake.notify_all()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self.pty.pull_out()
        self.host_reader.close_pipe()
        self.pty.remove()
        self.started = False
        atexit.unregister(self.stop)

    def __enter__(self) -> 'PtySimulator':
        """Start (if not yet started) for a ``with`` block."""
        if not self.started:
            self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Stop at the end of the ``with`` block."""
        self.stop()

    def _schedule(self, faults: FaultConfig, now: float,
                  changes: collections.abc.Collection[str] | None) -> None:
        """
        Schedule from ``now`` the timed faults (``changes`` None: all; else those it names).

        They count from when the configuration takes effect (:meth:`start` or
        :meth:`set_faults`); a change of configuration schedules again only
        the ones it names. They hit ``config.fault_address`` (None: a stall
        every sensor, a power cycle the first).
        """
        def asked(*names: str) -> bool:
            return changes is None or any(name in changes for name in names)

        post, address = self.host_reader.post, self.config.fault_address
        if faults.stall_at is not None and asked('stall_at', 'stall_seconds'):
            self._stall(now + faults.stall_at, faults.stall_seconds, address)
        if faults.unplug_at is not None and asked('unplug_at', 'unplug_seconds'):
            post(faults.unplug_at, functools.partial(self._pull_cable, faults.unplug_seconds))
        if faults.power_cycle_at is not None and asked(
                'power_cycle_at', 'power_off_seconds', 'power_up_timer'):
            unit = unit_at(self.units, address)
            off, timer = faults.power_off_seconds, faults.power_up_timer
            post(faults.power_cycle_at, lambda: unit.power_cycle(off, timer))

    def _stall(self, start: float, seconds: float, address: int | None) -> None:
        """Silence the sensor at ``address`` (None: the base station, every sensor)."""
        for unit in self.units.values() if address is None else [unit_at(self.units, address)]:
            unit.faults.stall(start, seconds)

    # -- the port ---------------------------------------------------------------------------

    def unplug(self, seconds: float | None = None, timeout: float = 5.0) -> None:
        """
        Unplug the base station now; plug it back in after ``seconds``.

        The pty closes (the host's reads and writes fail), the symlink goes,
        and a new pty appears at the same path after the delay (None: only on
        :meth:`replug`). A wireless sensor keeps running meanwhile; a wired one
        loses its power and starts again from power-up when plugged back in.
        Returns once the port is gone (the cable is pulled on the reader thread).
        """
        self.host_reader.post(0.0, lambda: self._pull_cable(seconds))
        deadline = time.monotonic() + timeout
        while self.pty.plugged.is_set() and time.monotonic() < deadline:
            time.sleep(0.005)

    def replug(self, timeout: float = 5.0) -> bool:
        """Plug the base station back in now; return whether the port is back in ``timeout`` s."""
        self.host_reader.post(0.0, self._plug_cable)
        return self.pty.plugged.wait(timeout)

    def _pull_cable(self, seconds: float | None) -> None:
        """
        Pull the cable now (on the reader thread); plug it back in after ``seconds``.

        A wired sensor is fed by the cable: it goes dark with the port (first,
        so that whoever sees the port gone sees it off too), and starts from
        power-up when the cable is back. ``seconds`` None: only on :meth:`replug`.
        """
        if self.pty.master is None:
            return
        with self._changed:
            self._record.count(unplugs=1)
            if not self.config.wireless:
                self._first.power_off()
        self.pty.pull_out()
        if seconds is not None:
            self.host_reader.post(seconds, self._plug_cable)

    def _plug_cable(self) -> None:
        """Plug the cable back in (if unplugged and still running); notify ``changed``."""
        if self.pty.master is None and not self._stop.is_set():
            if not self.config.wireless:
                self._first.power_on()
            self.host_reader.plug_in()
            with self._changed:
                self._changed.notify_all()

    # -- run-time control -------------------------------------------------------------------

    def stall(self, seconds: float, address: int | None = None) -> None:
        """
        Silence from now for ``seconds`` (radio; wired: a hung sensor): nothing gets through.

        ``address`` stalls that sensor alone (its radio link), the others
        streaming on; None the base station (every sensor).
        """
        with self._wake:
            self._stall(time.time(), seconds, address)

    @property
    def faults(self) -> FaultConfig:
        """Return the faults in effect."""
        return self._first.faults.config

    def set_faults(self, faults: FaultConfig | None = None, **changes: Any) -> FaultConfig:
        """
        Replace the fault configuration, or change some of its fields.

        Scheduled faults (``stall_at``, ``unplug_at``) given here count from
        now. Turning ``already_streaming`` on makes the sensor stream 0xCC now.
        A wired simulator refuses the radio's faults (ValueError).
        """
        with self._wake:
            old = self._first.faults.config
            new = faults if faults is not None else dataclasses.replace(old, **changes)
            if not self.config.wireless:
                new.check_wired()
            for unit in self.units.values():
                unit.take_faults(new)
            self._foreign.address = foreign_address(self.config, new)
            now = time.time()
            if new.already_streaming and not old.already_streaming and self.started:
                for unit in self.units.values():
                    unit.sensor.start_streaming(DEFAULT_STREAM, now)
                    self._record.note_streaming(now, unit.sensor.streaming)
            if self.started:
                self._schedule(new, now, None if faults is not None else changes)
            self._wake.notify_all()
        return new

    def set_moving(self, moving: bool) -> None:
        """Start or stop the sensor's motion now (a capture while moving goes wrong)."""
        with self.lock:
            self.sensor.motion.set_static(not moving, self.sensor.clock.rel(time.time()))

    def set_rate(self, rate_hz: float | None) -> None:
        """Override the calculation rate now (None: back to the EEPROM divider)."""
        with self.lock:
            self.sensor.set_rate_override(rate_hz, time.time())
            self._wake.notify_all()

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
        unit_at(self.units, address).power_cycle(off_seconds, timer_start)

    # -- the device now ---------------------------------------------------------------------

    @property
    def streaming(self) -> int:
        """Command byte the (first) sensor streams now, 0 when polled."""
        return self.streaming_of(None)

    def streaming_of(self, address: int | None) -> int:
        """Command byte the sensor at ``address`` (None: the first) streams now, 0 when polled."""
        with self.lock:
            return unit_at(self.units, address).sensor.streaming

    @property
    def addresses(self) -> tuple[int, ...]:
        """Return the address of every sensor behind the base station, the first first."""
        return tuple(self.units)

    @property
    def eeprom(self) -> dict[int, int]:
        """Return the sensor's EEPROM words now (a copy): presets and what the host wrote."""
        with self.lock:
            return dict(self.sensor.eeprom)
