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
The simulated sensor behind a pseudo-terminal: ``PtySimulator``, the orchestrator.

A driver opens ``sim.port`` exactly as it would open ``/dev/ttyUSB0`` and
talks to it with pyserial. Behind it sits either a wireless base station
(``base_station``: ACK/NACK, ping) and a wireless ``SimulatedSensor``, or a
wired sensor on its own line (``wired_line``); the sensor's records travel
through the ``transmitter`` (scheduling, delays, faults) to the pty
(``pty_port``). Every data packet, written or lost, is recorded in
``sim.truth`` (``ground_truth``) with the time its sample was taken and the
time its last byte was written, so that tests and benchmarks can compare what
the driver publishes with what really happened.

Two threads: one reads the host (select with a timeout, never a busy poll)
and runs scheduled actions (unplug, replug); one writes the sensor's records
at their scheduled times (``Transmitter.run``). The names this module always
exported (``SimulatorConfig``, ``SentRecord``, ``HostCommand``,
``SimulatorStats``, ``LINE_BYTES_PER_SECOND``, ``PORT_NAME``,
``DEFAULT_STREAM``) are still importable from it.
"""

import atexit
import collections.abc
import dataclasses
import heapq
import os
import random
import select
import threading
import time
import typing
from typing import Any

from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.commands import Command
from i3dmgx2_driver.codec.timer import TIMER_MODULUS

from .base_station import BaseStation
from .config import DEFAULT_STREAM, SimulatorConfig
from .faults import FaultConfig, Stall
from .ground_truth import GroundTruth, HostCommand, SentRecord, SimulatorStats
from .motion import Motion, MotionConfig
from .pty_port import PORT_NAME, PtyPort, TIOCPKT_DATA, TIOCPKT_FLUSHREAD
from .sensor import SimulatedSensor
from .transmitter import LINE_BYTES_PER_SECOND, POLL_S, Transmitter
from .wired_line import WiredLine

if typing.TYPE_CHECKING:  # typing.Self is new in Python 3.11; Jazzy allows 3.10
    from typing import Self

__all__ = [
    'DEFAULT_STREAM',
    'LINE_BYTES_PER_SECOND',
    'PORT_NAME',
    'HostCommand',
    'PtySimulator',
    'SentRecord',
    'SimulatorConfig',
    'SimulatorStats',
]

_READ_SIZE = 4096


class PtySimulator:
    """
    A 3DM-GX2 and its wireless base station on a pseudo-terminal, or a wired 3DM-GX2.

    Use as a context manager, or call :meth:`start` and :meth:`stop`. After
    start, ``port`` is the path to open (stable across unplugs). The ground
    truth (``truth``, ``commands``, ``host_log``, ``stats``, ``stream_changes``)
    is thread-safe to read at any time; the properties return copies.

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

    def __init__(self, config: SimulatorConfig | None = None, **overrides: Any) -> None:
        if config is None:
            config = SimulatorConfig(**overrides)
        elif overrides:
            config = dataclasses.replace(config, **overrides)
        self.config = config
        seeds = random.Random(config.seed)
        motion_config = config.motion
        if config.nan_mag or config.mag_nan_probability:
            motion_config = dataclasses.replace(
                motion_config, nan_mag=config.nan_mag or motion_config.nan_mag,
                mag_nan_probability=config.mag_nan_probability or
                motion_config.mag_nan_probability)
        #: The device model; touch it only while holding ``sim.lock``.
        self.sensor = SimulatedSensor(
            config.address, config.serial_number, Motion(motion_config),
            clock_ppm=config.clock_ppm, timer_start=config.timer_start, rate_hz=config.rate_hz,
            firmware_version=config.firmware_version, eeprom=config.power_up_eeprom,
            seed=seeds.getrandbits(64))
        self._foreign = SimulatedSensor(
            self._foreign_address(config.faults), '0000', Motion(MotionConfig(static=True)),
            clock_ppm=-25.0, timer_start=seeds.getrandbits(32), seed=seeds.getrandbits(64))
        self._fault_rng = random.Random(seeds.getrandbits(64))
        command_rng = random.Random(seeds.getrandbits(64))
        chunk_rng = random.Random(seeds.getrandbits(64))
        self._faults = config.faults

        #: Guards the sensor, the queues and the ground truth. Lock order: ``lock``
        #: may be held while taking the port's ``io_lock``, never the reverse.
        self.lock = threading.RLock()
        self._tx_wake = threading.Condition(self.lock)
        self._changed = threading.Condition(self.lock)
        self._stop = threading.Event()
        self._record = GroundTruth(config.truth_limit, self._changed)
        self._stall = Stall()
        self._pty = PtyPort(config.symlink, config.link_via_proc)
        self._end: BaseStation | WiredLine
        if config.wireless:
            self._end = BaseStation(self.sensor, self._record, self._pty, self._deliver,
                                    self._stall, lambda: self._faults, command_rng)
        else:
            self._end = WiredLine(self._record, self._deliver, self._stall)
        self._tx = Transmitter(config, self.sensor, self._foreign, self._end, self._pty,
                               self._record, self.lock, self._tx_wake, self._stall,
                               lambda: self._faults, self._fault_rng, chunk_rng)
        self._seq = 0
        self._polled_since_open = False
        self._ignore_next_continuous = config.faults.ignore_first_continuous
        self._actions: list[tuple[float, int, collections.abc.Callable[[], None]]] = []

        self._parser = self._end.new_parser()
        self._wake_r, self._wake_w = -1, -1
        self._threads: list[threading.Thread] = []
        self._started = False
        #: Wall-clock time of start() (the sensor's power-up).
        self.start_time: float | None = None
        #: Wall-clock time the host last opened the port (or flushed its input).
        self.last_port_open: float | None = None

    # -- lifecycle --------------------------------------------------------------------------

    def start(self) -> 'PtySimulator':
        """Create the port, power the sensor up and start the threads."""
        if self._started:
            raise RuntimeError('the simulator is already started')
        self._stop.clear()
        self._pty.create()
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._open_pty()
        now = time.time()
        with self.lock:
            self.start_time = now
            self.sensor.power_up(now)
            self._note_streaming(now)
            self._foreign.power_up(now - 1000.0 * self._fault_rng.random())
            self._schedule_faults(self._faults, now, None)
        self._started = True
        # An interpreter that exits without stop() still removes the port.
        atexit.register(self.stop)
        self._threads = [
            threading.Thread(target=self._rx_loop, name='gx2sim-rx', daemon=True),
            threading.Thread(target=self._tx.run, args=(self._stop,), name='gx2sim-tx',
                             daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        return self

    def stop(self) -> None:
        """Stop the threads, close the pty and remove the port symlink."""
        if not self._started:
            return
        self._stop.set()
        self._wake()
        with self.lock:
            self._tx_wake.notify_all()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._pty.pull_out()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
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

    def _open_pty(self) -> None:
        self._pty.plug_in()
        with self.lock:
            self._parser = self._end.new_parser()
            self._polled_since_open = False

    @property
    def plugged(self) -> bool:
        """Whether the port exists now (False between unplug and replug)."""
        return self._pty.plugged.is_set()

    def unplug(self, seconds: float | None = None, timeout: float = 5.0) -> None:
        """
        Unplug the base station now; plug it back in after ``seconds``.

        The pty closes (the host's reads and writes fail), the symlink goes,
        and a new pty appears at the same path after the delay (None: only on
        :meth:`replug`). A wireless sensor keeps running meanwhile; a wired one
        loses its power and starts again from power-up when plugged back in.
        Returns once the port is gone.
        """
        self._post(0.0, lambda: self._do_unplug(seconds))
        deadline = time.monotonic() + timeout
        while self._pty.plugged.is_set() and time.monotonic() < deadline:
            time.sleep(0.005)

    def replug(self, timeout: float = 5.0) -> bool:
        """Plug the base station back in now; return whether the port is back."""
        self._post(0.0, self._do_replug)
        return self._pty.plugged.wait(timeout)

    def wait_for_port(self, timeout: float = 10.0) -> bool:
        """Wait until the port exists (after an unplug); return whether it does."""
        return self._pty.plugged.wait(timeout)

    def _do_unplug(self, seconds: float | None) -> None:
        if self._pty.master is None:
            return
        with self.lock:
            self._record.count(unplugs=1)
            if not self.config.wireless:
                # The cable feeds a wired sensor: it goes dark with the port
                # (first, so that whoever sees the port gone sees it off too).
                self._tx.clear()
                self.sensor.power_off()
                self._note_streaming(time.time())
        self._pty.pull_out()
        if seconds is not None:
            self._post(seconds, self._do_replug)

    def _do_replug(self) -> None:
        if self._pty.master is None and not self._stop.is_set():
            if not self.config.wireless:
                with self.lock:
                    self.sensor.power_up(time.time())
                    self._note_streaming(time.time())
                    self._tx_wake.notify_all()
            self._open_pty()
            with self.lock:
                self._changed.notify_all()

    # -- run-time control -------------------------------------------------------------------

    def stall(self, seconds: float) -> None:
        """Silence from now for ``seconds`` (radio; wired: a hung sensor): nothing gets through."""
        with self.lock:
            self._stall.begin(time.time(), seconds)

    @property
    def faults(self) -> FaultConfig:
        """Return the faults in effect."""
        return self._faults

    def set_faults(self, faults: FaultConfig | None = None, **changes: Any) -> FaultConfig:
        """
        Replace the fault configuration, or change some of its fields.

        Scheduled faults (``stall_at``, ``unplug_at``) given here count from
        now. Turning ``already_streaming`` on makes the sensor stream 0xCC now.
        A wired simulator refuses the radio's faults (ValueError).
        """
        with self.lock:
            old = self._faults
            new = faults if faults is not None else dataclasses.replace(old, **changes)
            if not self.config.wireless:
                new.check_wired()
            self._faults = new
            self._foreign.address = self._foreign_address(new)
            if new.ignore_first_continuous and not old.ignore_first_continuous:
                self._ignore_next_continuous = True
            now = time.time()
            if new.already_streaming and not old.already_streaming and self._started:
                self.sensor.start_streaming(DEFAULT_STREAM, now)
                self._note_streaming(now)
            if self._started:
                self._schedule_faults(new, now, None if faults is not None else changes)
            self._tx_wake.notify_all()
        return new

    def _schedule_faults(self, faults: FaultConfig, now: float,
                         changes: dict[str, Any] | None) -> None:
        def asked(name: str) -> bool:
            return changes is None or name in changes

        if faults.stall_at is not None and (asked('stall_at') or asked('stall_seconds')):
            self._stall.begin(now + faults.stall_at, faults.stall_seconds)
        if faults.unplug_at is not None and (asked('unplug_at') or asked('unplug_seconds')):
            seconds = faults.unplug_seconds
            self._post(faults.unplug_at, lambda: self._do_unplug(seconds))
        if faults.power_cycle_at is not None and (
                asked('power_cycle_at') or asked('power_off_seconds')
                or asked('power_up_timer')):
            off, timer = faults.power_off_seconds, faults.power_up_timer
            self._post(faults.power_cycle_at, lambda: self.power_cycle(off, timer))

    def _foreign_address(self, faults: FaultConfig) -> int:
        if faults.foreign_address is not None:
            return faults.foreign_address
        return self.config.address % 65534 + 1

    def set_moving(self, moving: bool) -> None:
        """Start or stop the sensor's motion now (a capture while moving goes wrong)."""
        with self.lock:
            self.sensor.motion.set_static(not moving, time.time() - self.sensor.power_up_time)

    def set_rate(self, rate_hz: float | None) -> None:
        """Override the calculation rate now (None: back to the EEPROM divider)."""
        with self.lock:
            self.sensor.set_rate_override(rate_hz, time.time())
            self._tx_wake.notify_all()

    def power_cycle(self, off_seconds: float = 0.0, timer_start: int | None = None) -> None:
        """
        Restart the sensor: dark for ``off_seconds``, then up again as from power-up.

        While dark nothing is sampled, sent or answered (to the host it is a
        radio silence). At power-up the timer starts at ``timer_start`` (None:
        the sensor's configured ``timer_start``; a value given here stays the
        sensor's from then on), the stream as the EEPROM auto-start says.
        """
        if timer_start is not None and not 0 <= timer_start < TIMER_MODULUS:
            raise ValueError(f'timer_start must be a uint32, got {timer_start!r}')
        if off_seconds < 0:
            raise ValueError(f'off_seconds must not be negative, got {off_seconds!r}')
        if off_seconds == 0:
            self._power_up(timer_start)
            return
        with self.lock:
            self._tx.clear()  # what had not been sent before the power went is gone
            self.sensor.power_off()
            now = time.time()
            self._stall.begin(now, off_seconds)
            self._note_streaming(now)
        self._post(off_seconds, lambda: self._power_up(timer_start))

    def _power_up(self, timer_start: int | None) -> None:
        with self.lock:
            self._tx.clear()  # what the old power cycle had not sent is gone
            if timer_start is not None:
                self.sensor.timer_start = timer_start
            self.sensor.power_up(time.time())
            self._note_streaming(time.time())
            self._tx_wake.notify_all()

    # -- ground truth -----------------------------------------------------------------------

    @property
    def truth(self) -> list[SentRecord]:
        """Every data packet produced so far, in order (a copy)."""
        with self.lock:
            truth = self._record.truth
            return list(truth) if truth is not None else []

    @property
    def truth_count(self) -> int:
        """How many truth entries were produced (cheap; counts dropped ones too)."""
        with self.lock:
            return self._record.truth_index

    @property
    def commands(self) -> list[tuple[float, Command]]:
        """(time, command) of every command the sensor received (a copy)."""
        with self.lock:
            return list(self._record.commands)

    @property
    def host_log(self) -> list[HostCommand]:
        """Everything the host sent, with what became of it (a copy)."""
        with self.lock:
            return list(self._record.host_log)

    @property
    def stats(self) -> SimulatorStats:
        """Return a snapshot of the counters."""
        with self.lock:
            return self._record.stats.copy()

    @property
    def streaming(self) -> int:
        """Command byte the sensor streams now, 0 when polled."""
        with self.lock:
            return self.sensor.streaming

    @property
    def stream_changes(self) -> list[tuple[float, int]]:
        """
        (time, command byte or 0) each time the sensor's stream changed (a copy).

        The first entry is the power-up state. A start, stop or change of
        stream (0xC4, 0xFA, power cycle, unplugging a wired sensor) adds one;
        asking for the record already streamed adds none. A test proves that
        an interrupted stream was restarted by finding a 0 followed by a code.
        """
        with self.lock:
            return list(self._record.stream_changes)

    @property
    def wireless(self) -> bool:
        """Whether this is a base station with a wireless sensor (False: a wired sensor)."""
        return self.config.wireless

    @property
    def eeprom(self) -> dict[int, int]:
        """Return the sensor's EEPROM words now (a copy): presets and what the host wrote."""
        with self.lock:
            return dict(self.sensor.eeprom)

    def commands_of(self, *codes: int) -> list[tuple[float, Command]]:
        """(time, command) of the commands with these command bytes the sensor received."""
        with self.lock:
            return [entry for entry in self._record.commands if entry[1].code in codes]

    def eeprom_writes(self) -> list[tuple[float, Command]]:
        """
        Every EEPROM write (0xE4) the sensor received, whether or not it stored it.

        Empty proves that nothing was written to the EEPROM. (A write the radio
        lost never reached the sensor; ``host_log`` still shows it was sent.)
        """
        return self.commands_of(lay.WRITE_EEPROM)

    def wait_until(self, condition: collections.abc.Callable[[], bool],
                   timeout: float = 5.0) -> bool:
        """Wait until ``condition()`` is true (checked on every change); return it."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                if condition():
                    return True
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._changed.wait(min(remaining, 0.05))

    def wait_for_commands(self, predicate: collections.abc.Callable[[Command], bool] | None = None,
                          timeout: float = 5.0, count: int = 1) -> list[tuple[float, Command]]:
        """
        Wait until the sensor received ``count`` commands matching ``predicate``.

        Returns the matching (time, command) pairs; fewer than ``count`` means
        the timeout passed.
        """
        def matches() -> list[tuple[float, Command]]:
            return [entry for entry in self._record.commands
                    if predicate is None or predicate(entry[1])]

        self.wait_until(lambda: len(matches()) >= count, timeout)
        with self.lock:
            return matches()

    def wait_for_truth(self, count: int, timeout: float = 5.0,
                       predicate: collections.abc.Callable[[SentRecord], bool] | None = None
                       ) -> bool:
        """Wait until ``count`` truth entries (matching ``predicate``) exist."""
        if predicate is None:
            return self.wait_until(lambda: self._record.truth_index >= count, timeout)
        return self.wait_until(
            lambda: sum(1 for e in (self._record.truth or ()) if predicate(e)) >= count, timeout)

    # -- the host side: reading commands ----------------------------------------------------

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b'!')
        except OSError:
            pass

    def _post(self, delay: float, action: collections.abc.Callable[[], None]) -> None:
        """Run ``action`` on the reader thread after ``delay`` seconds."""
        with self.lock:
            self._seq += 1
            heapq.heappush(self._actions, (time.monotonic() + delay, self._seq, action))
        self._wake()

    def _run_actions(self) -> float:
        """Run the actions that are due; return the delay until the next one."""
        while True:
            with self.lock:
                if not self._actions:
                    return POLL_S
                delay = self._actions[0][0] - time.monotonic()
                if delay > 0:
                    return min(delay, POLL_S)
                _, _, action = heapq.heappop(self._actions)
            action()

    def _rx_loop(self) -> None:
        while not self._stop.is_set():
            timeout = self._run_actions()
            master = self._pty.master
            watch = [self._wake_r] if master is None else [master, self._wake_r]
            try:
                ready, _, _ = select.select(watch, [], [], timeout)
            except (OSError, ValueError):
                continue
            if self._wake_r in ready:
                try:
                    os.read(self._wake_r, 512)
                except OSError:
                    pass
            if master is not None and master in ready:
                try:
                    data = os.read(master, _READ_SIZE)
                except OSError:
                    continue
                if data:
                    self._on_bytes(data, time.time())

    def _on_bytes(self, data: bytes, now: float) -> None:
        # Packet mode: a leading 0 means data; anything else is a status byte.
        if data[0] != TIOCPKT_DATA:
            if data[0] & TIOCPKT_FLUSHREAD:
                with self.lock:
                    self._polled_since_open = False
                    self._record.count(port_opens=1)
                    self.last_port_open = now
                    self._changed.notify_all()
            return
        # Each event is handled whole under the lock, answer written included, so
        # that the ground truth already shows a command when the host sees its ACK.
        with self.lock:
            skipped = self._parser.stats.bytes_skipped
            for event in self._parser.feed(data[1:]):
                self._end.on_event(event, now)
            self._record.count(bytes_read=len(data) - 1,
                               host_bytes_ignored=self._parser.stats.bytes_skipped - skipped)

    def _deliver(self, command: Command | None, raw: bytes, now: float) -> str:
        """Hand a command to the sensor (lock held); return the outcome."""
        if command is None:
            self.sensor.handle(raw, now)
            return 'ignored'
        self._record.received(now, command)
        if command.code == lay.SET_CONTINUOUS and command.args[0] != 0:
            if self._ignore_next_continuous:
                self._ignore_next_continuous = False
                return 'ignored'
            if self._faults.needs_polled_first and not self._polled_since_open:
                return 'ignored'
        elif command.code not in (lay.SET_CONTINUOUS, lay.STOP_CONTINUOUS):
            self._polled_since_open = True
        ignored_before = self.sensor.ignored
        for reply in self.sensor.handle(command, now):
            self._tx.enqueue(reply, 'reply', self.sensor.address)
        self._note_streaming(now)
        self._tx_wake.notify_all()
        return 'ignored' if self.sensor.ignored != ignored_before else 'delivered'

    def _note_streaming(self, now: float) -> None:
        """Record the sensor's stream if it changed (lock held)."""
        self._record.note_streaming(now, self.sensor.streaming)
