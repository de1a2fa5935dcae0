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
The simulated sensor and wireless base station behind a pseudo-terminal.

A driver opens ``sim.port`` exactly as it would open ``/dev/ttyUSB0`` and
talks to it with pyserial; behind it, a base station ACKs or NACKs command
packets and answers pings, and a ``SimulatedSensor`` answers and streams
through a radio that can lose, delay, corrupt and interleave packets. Every
data packet, written or lost, is recorded in ``sim.truth`` with the time its
sample was taken and the time its last byte was written, so that tests and
benchmarks can compare what the driver publishes with what really happened.

Design points, each for a reason:

* The pty slave is put in raw mode at once and kept open by the simulator:
  the data are binary (no echo, no CR/LF translation), reads on the master do
  not fail with EIO whenever the driver closes the port, and the line settings
  persist between the driver's opens.
* ``sim.port`` is a symlink in a private directory, so the path stays the same
  when an unplug replaces the pty (the real ``/dev/ttyUSB0`` comes back under
  the same name too). It points to ``/proc/<pid>/fd/<slave>``, not to
  ``/dev/pts/N``: if the simulator is killed before it removes the link, the
  link dangles, where a link to ``/dev/pts/N`` would lead a still-running
  driver into whichever new pseudo-terminal reuses the number (seen in practice
  on a shared machine).
* The master runs in packet mode (TIOCPKT), which reports the input flush that
  pyserial does on every open: that is how the simulator knows the host has
  (re)opened the port, for the "poll before streaming" quirk.
* One thread reads the host (select with a timeout, never a busy poll); one
  writes the sensor's packets at their scheduled times, computed from an
  absolute grid so that no drift accumulates. Writes are non-blocking and
  split into random chunks; when nobody reads and the pty buffer is full the
  bytes are lost, as on a real line, and counted.
"""

import atexit
import collections
import collections.abc
import dataclasses
import fcntl
import heapq
import itertools
import os
import random
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty
import typing
from typing import Any, NamedTuple

from i3dmgx2_driver.codec import framing
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.commands import Command, decode_command
from i3dmgx2_driver.codec.errors import CodecError
from i3dmgx2_driver.codec.stream import CommandStreamParser, RawCommand, RejectedPacket

from . import faults as flt
from . import sensor as sns
from .faults import FaultConfig
from .motion import Motion, MotionConfig
from .sensor import Reply, SimulatedSensor

if typing.TYPE_CHECKING:  # typing.Self is new in Python 3.11; Jazzy allows 3.10
    from typing import Self

#: Bytes per second of a 115200-baud 8N1 line.
LINE_BYTES_PER_SECOND = 11520
#: Name of the port symlink inside the simulator's private directory.
PORT_NAME = 'ttyGX2'
#: Record streamed when "already streaming" is asked for without a command.
DEFAULT_STREAM = lay.ACCEL_ANG_RATE_MAG_ORIENTATION

_TIOCPKT = getattr(termios, 'TIOCPKT', 0x5420)
_TIOCPKT_FLUSHREAD = getattr(termios, 'TIOCPKT_FLUSHREAD', 0x01)
_READ_SIZE = 4096
#: Longest sleep of either thread, so that stop() never waits long.
_POLL_S = 0.25
_PING_FAILED = bytes((framing.NACK,))


@dataclasses.dataclass
class SimulatorConfig:
    """Everything a simulated base station and sensor can be set up with."""

    #: Node address of the sensor (factory: last two digits of its serial number).
    address: int = 95
    #: Serial number the sensor reports (identifier 1).
    serial_number: str = '3095'
    #: Calculation rate (Hz) overriding the EEPROM divider: for benchmarks beyond 300 Hz.
    rate_hz: float | None = None
    #: Command byte the sensor streams from power-up (True: 0xCC; False/0: polled).
    streaming_at_start: bool | int = False
    #: Seed of every random choice (noise, faults, chunking), for reproducible runs.
    seed: int | None = None
    motion: MotionConfig = dataclasses.field(default_factory=MotionConfig)
    faults: FaultConfig = dataclasses.field(default_factory=FaultConfig)
    #: Shortcut for ``motion.nan_mag``: no magnetometer, NaN fields (Inertia-Link).
    nan_mag: bool = False
    #: Shortcut for ``motion.mag_nan_probability``: NaN on that share of cycles.
    mag_nan_probability: float = 0.0
    #: Error of the sensor's clock (ppm; positive: its timer runs fast).
    clock_ppm: float = 40.0
    #: Timer at power-up (None: 5 s before the 32-bit rollover).
    timer_start: int | None = None
    firmware_version: int = 2103
    #: Radio latency (s) between the sensor sending a packet and the host getting it.
    latency_s: float = 0.002
    #: Baud rate of the serial line between the base station and the host: a
    #: packet's last byte arrives its wire time (10 bits a byte) after its first,
    #: so each packet is written that much later (throughput is not limited;
    #: see ``limit_to_line_rate``). None: bytes arrive at once, as over USB.
    wire_baud: int | None = 115200
    #: Each packet is written in a random number of chunks in this range.
    chunks: tuple[int, int] = (1, 3)
    #: Pause between the chunks of one packet (s), so that reads see them apart.
    chunk_gap_s: float = 0.0
    #: Fixed path for the port symlink (None: a private temporary directory).
    symlink: str | None = None
    #: Most truth entries kept (None: all; 0: none, for long demos).
    truth_limit: int | None = None
    #: Skip streamed cycles the 115200-baud line could not carry, as the device does.
    limit_to_line_rate: bool = False
    #: When the writer falls this far behind (s), it skips cycles instead of bursting.
    max_lag_s: float = 1.0
    #: Point the port symlink at /proc/<pid>/fd/<slave> rather than /dev/pts/N, so
    #: that it dangles when the simulator dies, however it dies (see _open_pty).
    link_via_proc: bool = True

    def __post_init__(self) -> None:
        """Reject settings that cannot work, naming the field."""
        if not 1 <= self.address <= 65534:
            raise ValueError(f'address must be in 1..65534, got {self.address}')
        low, high = self.chunks
        if not 1 <= low <= high:
            raise ValueError(f'chunks must be (min, max) with 1 <= min <= max, got {self.chunks}')
        if self.rate_hz is not None and self.rate_hz <= 0:
            raise ValueError('rate_hz must be positive')
        if self.latency_s < 0 or self.chunk_gap_s < 0:
            raise ValueError('latency_s and chunk_gap_s must not be negative')

    @property
    def start_stream(self) -> int:
        """Command byte streamed from power-up, 0 for none."""
        if self.faults.already_streaming and not self.streaming_at_start:
            return DEFAULT_STREAM
        if self.streaming_at_start is True:
            return DEFAULT_STREAM
        return int(self.streaming_at_start)


class SentRecord(NamedTuple):
    """Ground truth of one data packet the sensor produced, written or lost."""

    #: Position in the order of production (0, 1, ...), across every source.
    index: int
    #: Wall-clock time (time.time()) of the sample it carries: its calculation cycle.
    sample_time: float
    #: Wall-clock time right after its last byte was written (a reader may see the
    #: bytes a moment earlier); None if never written whole.
    write_time: float | None
    #: Raw uint32 timer of the record (None for records without one).
    timer: int | None
    #: The record as the codec decodes it.
    record: Any
    #: The packet bytes as written (corrupted if it was), or as it would have been.
    packet: bytes
    #: Node address in the packet.
    address: int
    #: Whether a correct parser, set to our address, accepts it.
    valid: bool
    #: What went wrong (see faults.FAULT_*), None for a good packet.
    fault: str | None
    #: 'stream', 'reply' (to a polled command) or 'foreign' (another sensor).
    source: str


class HostCommand(NamedTuple):
    """One thing the host sent, as the base station saw it, and what came of it."""

    time: float
    #: 'packet' (command packet), 'rejected' (NACKed) or 'ping'.
    kind: str
    address: int | None
    #: The decoded command, or None if it did not decode.
    command: Command | None
    raw: bytes
    #: 'delivered', 'ignored', 'lost', 'stalled', 'other_address', 'rejected: ...',
    #: 'ping ok', 'ping failed'.
    outcome: str


class SimulatorStats:
    """Counters of what the simulator did, for tests, benchmarks and the CLI."""

    __slots__ = (
        'acks', 'bytes_read', 'bytes_written', 'commands_ignored', 'commands_lost',
        'commands_other_address', 'commands_received', 'corrupted_checksum',
        'corrupted_length', 'dropped', 'foreign', 'garbage_bursts', 'garbage_bytes',
        'late_skipped', 'line_rate_skipped', 'nacks', 'overflow_bytes', 'overflow_packets',
        'packets_written', 'pings', 'port_opens', 'records_sent', 'replies_sent', 'stalled',
        'unplugged_lost', 'unplugs')

    def __init__(self) -> None:
        for name in self.__slots__:
            setattr(self, name, 0)

    def as_dict(self) -> dict[str, int]:
        """Return the counters by name."""
        return {name: getattr(self, name) for name in self.__slots__}

    def copy(self) -> 'SimulatorStats':
        """Return a snapshot that later counting does not change."""
        other = SimulatorStats()
        for name in self.__slots__:
            setattr(other, name, getattr(self, name))
        return other

    def __repr__(self) -> str:
        fields_ = ', '.join(f'{k}={v}' for k, v in self.as_dict().items() if v)
        return f'SimulatorStats({fields_})'


class _Outgoing(NamedTuple):
    """A packet waiting in the radio, ordered by when the sensor sent it."""

    send: float
    seq: int
    write_at: float
    reply: Reply
    source: str
    address: int


class PtySimulator:
    """
    A 3DM-GX2 and its wireless base station on a pseudo-terminal.

    Use as a context manager, or call :meth:`start` and :meth:`stop`. After
    start, ``port`` is the path to open (stable across unplugs). The ground
    truth (``truth``, ``commands``, ``host_log``, ``stats``) is thread-safe to
    read at any time; the properties return copies.
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
        eeprom = {}
        if config.start_stream:
            if config.start_stream not in sns.STREAMABLE:
                raise ValueError(f'0x{config.start_stream:02X} cannot be streamed')
            eeprom[sns.AUTOSTART_ADDRESS] = 0x8000 | config.start_stream
        #: The device model; touch it only while holding ``sim.lock``.
        self.sensor = SimulatedSensor(
            config.address, config.serial_number, Motion(motion_config),
            clock_ppm=config.clock_ppm, timer_start=config.timer_start, rate_hz=config.rate_hz,
            firmware_version=config.firmware_version, eeprom=eeprom,
            seed=seeds.getrandbits(64))
        self._foreign = SimulatedSensor(
            self._foreign_address(config.faults), '0000', Motion(MotionConfig(static=True)),
            clock_ppm=-25.0, timer_start=seeds.getrandbits(32), seed=seeds.getrandbits(64))
        self._fault_rng = random.Random(seeds.getrandbits(64))
        self._command_rng = random.Random(seeds.getrandbits(64))
        self._chunk_rng = random.Random(seeds.getrandbits(64))
        self._faults = config.faults

        #: Guards the sensor, the queues and the ground truth. Lock order: ``lock``
        #: may be held while taking ``_io_lock`` (one-byte answers), never the reverse.
        self.lock = threading.RLock()
        self._tx_wake = threading.Condition(self.lock)
        self._changed = threading.Condition(self.lock)
        # Guards the pty file descriptors and every write to them.
        self._io_lock = threading.Lock()
        self._stop = threading.Event()
        self._plugged = threading.Event()

        self._truth: collections.deque[SentRecord] | None = (
            None if config.truth_limit == 0 else collections.deque(maxlen=config.truth_limit))
        self._truth_index = 0
        self._commands: list[tuple[float, Command]] = []
        self._host_log: list[HostCommand] = []
        self._stats = SimulatorStats()
        self._outbox: list[_Outgoing] = []
        self._seq = 0
        self._stall_from = 0.0
        self._stall_until = 0.0
        self._line_free_at = 0.0
        self._polled_since_open = False
        self._ignore_next_continuous = config.faults.ignore_first_continuous
        self._actions: list[tuple[float, int, collections.abc.Callable[[], None]]] = []

        self._master: int | None = None
        self._slave: int | None = None
        self._link_target: str | None = None
        self._parser = CommandStreamParser()
        self._wake_r, self._wake_w = -1, -1
        self._dir: str | None = None
        self._threads: list[threading.Thread] = []
        self._started = False
        #: Path to open: a symlink that survives unplug and replug.
        self.port: str | None = None
        #: The pseudo-terminal the symlink points to now (None while unplugged).
        self.device: str | None = None
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
        if self.config.symlink:
            self.port = os.path.abspath(self.config.symlink)
            if os.path.lexists(self.port) and not os.path.islink(self.port):
                raise FileExistsError(f'{self.port} exists and is not a symlink')
        else:
            self._dir = tempfile.mkdtemp(prefix='i3dmgx2-sim-')
            self.port = os.path.join(self._dir, PORT_NAME)
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._open_pty()
        now = time.time()
        with self.lock:
            self.start_time = now
            self.sensor.power_up(now)
            self._foreign.power_up(now - 1000.0 * self._fault_rng.random())
            self._schedule_faults(self._faults, now, None)
        self._started = True
        # An interpreter that exits without stop() still removes the port.
        atexit.register(self.stop)
        self._threads = [
            threading.Thread(target=self._rx_loop, name='gx2sim-rx', daemon=True),
            threading.Thread(target=self._tx_loop, name='gx2sim-tx', daemon=True),
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
        self._close_pty()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None
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

    # -- the pseudo-terminal ----------------------------------------------------------------

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        fcntl.ioctl(master, _TIOCPKT, struct.pack('i', 1))
        os.set_blocking(master, False)
        device = os.ttyname(slave)
        # Through /proc, the link dangles once this process is gone, even if it
        # was killed before it could remove it: a stale link never leads a
        # driver to whatever pseudo-terminal reuses the number later.
        target = f'/proc/{os.getpid()}/fd/{slave}'
        if not self.config.link_via_proc or not os.path.exists(target):
            target = device
        temporary = f'{self.port}.{os.getpid()}.new'
        if os.path.lexists(temporary):
            os.unlink(temporary)
        os.symlink(target, temporary)
        os.replace(temporary, self.port)
        with self._io_lock:
            self._master, self._slave, self.device = master, slave, device
            self._link_target = target
        with self.lock:
            self._parser = CommandStreamParser()
            self._polled_since_open = False
        self._plugged.set()

    def _close_pty(self) -> None:
        with self._io_lock:
            for fd in (self._master, self._slave):
                if fd is not None:
                    try:
                        os.close(fd)
                    except OSError:
                        pass
            target = self._link_target
            self._master = self._slave = self.device = self._link_target = None
        self._plugged.clear()
        if self.port and os.path.islink(self.port) and os.readlink(self.port) == target:
            try:
                os.unlink(self.port)
            except FileNotFoundError:
                pass

    @property
    def plugged(self) -> bool:
        """Whether the port exists now (False between unplug and replug)."""
        return self._plugged.is_set()

    def unplug(self, seconds: float | None = None, timeout: float = 5.0) -> None:
        """
        Unplug the base station now; plug it back in after ``seconds``.

        The pty closes (the host's reads and writes fail), the symlink goes,
        and a new pty appears at the same path after the delay (None: only on
        :meth:`replug`). The sensor is wireless and keeps running meanwhile.
        Returns once the port is gone.
        """
        self._post(0.0, lambda: self._do_unplug(seconds))
        deadline = time.monotonic() + timeout
        while self._plugged.is_set() and time.monotonic() < deadline:
            time.sleep(0.005)

    def replug(self, timeout: float = 5.0) -> bool:
        """Plug the base station back in now; return whether the port is back."""
        self._post(0.0, self._do_replug)
        return self._plugged.wait(timeout)

    def wait_for_port(self, timeout: float = 10.0) -> bool:
        """Wait until the port exists (after an unplug); return whether it does."""
        return self._plugged.wait(timeout)

    def _do_unplug(self, seconds: float | None) -> None:
        if self._master is None:
            return
        self._close_pty()
        with self.lock:
            self._stats.unplugs += 1
        if seconds is not None:
            self._post(seconds, self._do_replug)

    def _do_replug(self) -> None:
        if self._master is None and not self._stop.is_set():
            self._open_pty()
            with self.lock:
                self._changed.notify_all()

    # -- run-time control -------------------------------------------------------------------

    def stall(self, seconds: float) -> None:
        """Radio silence from now for ``seconds``: packets in both directions are lost."""
        self._stall_window(time.time(), seconds)

    def _stall_window(self, start: float, seconds: float) -> None:
        with self.lock:
            self._stall_from = start
            self._stall_until = start + seconds

    def _stalled(self, t: float) -> bool:
        return self._stall_from <= t < self._stall_until

    @property
    def faults(self) -> FaultConfig:
        """Return the faults in effect."""
        return self._faults

    def set_faults(self, faults: FaultConfig | None = None, **changes: Any) -> FaultConfig:
        """
        Replace the fault configuration, or change some of its fields.

        Scheduled faults (``stall_at``, ``unplug_at``) given here count from
        now. Turning ``already_streaming`` on makes the sensor stream 0xCC now.
        """
        with self.lock:
            old = self._faults
            new = faults if faults is not None else dataclasses.replace(old, **changes)
            self._faults = new
            self._foreign.address = self._foreign_address(new)
            if new.ignore_first_continuous and not old.ignore_first_continuous:
                self._ignore_next_continuous = True
            now = time.time()
            if new.already_streaming and not old.already_streaming and self._started:
                self.sensor.start_streaming(DEFAULT_STREAM, now)
            if self._started:
                self._schedule_faults(new, now, None if faults is not None else changes)
            self._tx_wake.notify_all()
        return new

    def _schedule_faults(self, faults: FaultConfig, now: float,
                         changes: dict[str, Any] | None) -> None:
        def asked(name: str) -> bool:
            return changes is None or name in changes

        if faults.stall_at is not None and (asked('stall_at') or asked('stall_seconds')):
            self._stall_window(now + faults.stall_at, faults.stall_seconds)
        if faults.unplug_at is not None and (asked('unplug_at') or asked('unplug_seconds')):
            seconds = faults.unplug_seconds
            self._post(faults.unplug_at, lambda: self._do_unplug(seconds))

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

    def power_cycle(self) -> None:
        """Restart the sensor: timer from ``timer_start``, auto-start from EEPROM."""
        with self.lock:
            self._outbox.clear()  # what the old power cycle had not sent is gone
            self.sensor.power_up(time.time())
            self._tx_wake.notify_all()

    # -- ground truth -----------------------------------------------------------------------

    @property
    def truth(self) -> list[SentRecord]:
        """Every data packet produced so far, in order (a copy)."""
        with self.lock:
            return list(self._truth) if self._truth is not None else []

    @property
    def truth_count(self) -> int:
        """How many truth entries were produced (cheap; counts dropped ones too)."""
        with self.lock:
            return self._truth_index

    @property
    def commands(self) -> list[tuple[float, Command]]:
        """(time, command) of every command the sensor received (a copy)."""
        with self.lock:
            return list(self._commands)

    @property
    def host_log(self) -> list[HostCommand]:
        """Everything the host sent, with what became of it (a copy)."""
        with self.lock:
            return list(self._host_log)

    @property
    def stats(self) -> SimulatorStats:
        """Return a snapshot of the counters."""
        with self.lock:
            return self._stats.copy()

    @property
    def streaming(self) -> int:
        """Command byte the sensor streams now, 0 when polled."""
        with self.lock:
            return self.sensor.streaming

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
            return [entry for entry in self._commands
                    if predicate is None or predicate(entry[1])]

        self.wait_until(lambda: len(matches()) >= count, timeout)
        with self.lock:
            return matches()

    def wait_for_truth(self, count: int, timeout: float = 5.0,
                       predicate: collections.abc.Callable[[SentRecord], bool] | None = None
                       ) -> bool:
        """Wait until ``count`` truth entries (matching ``predicate``) exist."""
        if predicate is None:
            return self.wait_until(lambda: self._truth_index >= count, timeout)
        return self.wait_until(
            lambda: sum(1 for e in (self._truth or ()) if predicate(e)) >= count, timeout)

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
                    return _POLL_S
                delay = self._actions[0][0] - time.monotonic()
                if delay > 0:
                    return min(delay, _POLL_S)
                _, _, action = heapq.heappop(self._actions)
            action()

    def _rx_loop(self) -> None:
        while not self._stop.is_set():
            timeout = self._run_actions()
            master = self._master
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
        if data[0] != 0:
            if data[0] & _TIOCPKT_FLUSHREAD:
                with self.lock:
                    self._polled_since_open = False
                    self._stats.port_opens += 1
                    self.last_port_open = now
                    self._changed.notify_all()
            return
        # Each event is handled whole under the lock, answer written included, so
        # that the ground truth already shows a command when the host sees its ACK.
        with self.lock:
            self._stats.bytes_read += len(data) - 1
            for event in self._parser.feed(data[1:]):
                if isinstance(event, framing.CommandPacket):
                    self._on_command_packet(event, now)
                elif isinstance(event, RejectedPacket):
                    self._log(HostCommand(now, 'rejected', None, None, b'',
                                          f'rejected: {event.reason}'), nacks=1)
                    self._write_raw(bytes((framing.NACK,)))
                elif isinstance(event, RawCommand):
                    self._on_raw_command(event.command, now)

    def _on_raw_command(self, raw: bytes, now: float) -> None:
        """Answer a ping for the base station (lock held)."""
        try:
            command = decode_command(raw)
        except CodecError:
            return
        if command.code != lay.PING:
            return
        answer = self.sensor.ping_reply(command.args[0])
        if self._stalled(now):
            answer = _PING_FAILED
        outcome = 'ping ok' if answer != _PING_FAILED else 'ping failed'
        self._log(HostCommand(now, 'ping', command.args[0], command, raw, outcome), pings=1)
        self._write_raw(answer)

    def _on_command_packet(self, packet: framing.CommandPacket, now: float) -> None:
        """ACK a command packet and pass it on over the radio (lock held)."""
        # The base station ACKs every well-formed packet: it only checks the
        # framing and sends it over the air, whoever it is for. The ACK goes out
        # first; the sensor's answer is queued behind it. A busy base station
        # (fault) NACKs a good packet instead and sends nothing.
        if self._command_rng.random() < self._faults.nack_probability:
            self._write_raw(bytes((framing.NACK,)))
            self._log(HostCommand(now, 'rejected', packet.address, None, packet.command,
                                  'rejected: busy'), nacks=1)
            return
        self._write_raw(bytes((framing.ACK,)))
        try:
            command: Command | None = decode_command(packet.command)
        except CodecError:
            command = None
        if packet.address != self.sensor.address:
            outcome, counter = 'other_address', 'commands_other_address'
        elif self._stalled(now):
            outcome, counter = 'stalled', 'commands_lost'
        elif self._command_rng.random() < self._faults.command_loss_probability:
            outcome, counter = 'lost', 'commands_lost'
        else:
            outcome = self._deliver(command, packet.command, now)
            counter = 'commands_received' if outcome == 'delivered' else 'commands_ignored'
        self._log(HostCommand(now, 'packet', packet.address, command, packet.command, outcome),
                  acks=1, **{counter: 1})

    def _deliver(self, command: Command | None, raw: bytes, now: float) -> str:
        """Hand a command to the sensor (lock held); return the outcome."""
        if command is None:
            self.sensor.handle(raw, now)
            return 'ignored'
        self._commands.append((now, command))
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
            self._enqueue(reply, 'reply', self.sensor.address)
        self._tx_wake.notify_all()
        return 'ignored' if self.sensor.ignored != ignored_before else 'delivered'

    def _log(self, entry: HostCommand, **counters: int) -> None:
        with self.lock:
            self._host_log.append(entry)
            for name, value in counters.items():
                setattr(self._stats, name, getattr(self._stats, name) + value)
            self._changed.notify_all()

    # -- the sensor side: writing packets ---------------------------------------------------

    def _enqueue(self, reply: Reply, source: str, address: int) -> None:
        """Queue a packet the sensor sends at ``reply.due`` (lock held)."""
        delay = self.config.latency_s
        if self.config.wire_baud:
            size = len(reply.data) + framing.HEADER_SIZE + framing.DATA_TRAILER_SIZE
            delay += size * 10.0 / self.config.wire_baud
        if self._faults.jitter_ms > 0:
            delay += self._fault_rng.uniform(0.0, self._faults.jitter_ms / 1000.0)
        self._seq += 1
        heapq.heappush(self._outbox, _Outgoing(reply.due, self._seq, reply.due + delay,
                                               reply, source, address))

    def _tx_loop(self) -> None:
        while not self._stop.is_set():
            item = None
            with self.lock:
                now = time.time()
                next_sample = self.sensor.next_sample_time
                if next_sample is not None and next_sample <= now:
                    if now - next_sample > self.config.max_lag_s:
                        self._stats.late_skipped += self.sensor.skip_to(now)
                    else:
                        self._enqueue(self.sensor.stream_sample(), 'stream', self.sensor.address)
                    continue
                # The radio is a FIFO: the packet sent first is written first,
                # even when its delay (jitter) makes a later one ready sooner.
                if self._outbox and self._outbox[0].write_at <= now:
                    item = heapq.heappop(self._outbox)
                else:
                    wake = now + _POLL_S
                    if next_sample is not None:
                        wake = min(wake, next_sample)
                    if self._outbox:
                        wake = min(wake, self._outbox[0].write_at)
                    self._tx_wake.wait(max(wake - now, 0.0))
                    continue
            self._transmit(item)

    def _transmit(self, item: _Outgoing) -> None:
        """
        Write one packet with its faults, and record it in the ground truth.

        The lock is held throughout, so that a host that has read a packet and
        then looks at ``truth`` always finds it there, complete.
        """
        reply = item.reply
        with self.lock:
            faults = self._faults
            rng = self._fault_rng
            lqi, rssi = self.sensor.link_quality()
            packet = framing.encode_data_packet(item.address, reply.data, lqi, rssi)
            fault = None
            if self._stalled(item.send):
                fault = flt.FAULT_STALL
            elif faults.drop_probability and rng.random() < faults.drop_probability:
                fault = flt.FAULT_DROPPED
            elif self.config.limit_to_line_rate and item.source == 'stream' \
                    and item.send < self._line_free_at - 1e-9:
                # The device's UART is still sending the previous packet when this
                # record is ready: the device skips it. Judged on the device's own
                # schedule (send times), never on when this thread happened to run.
                fault = flt.FAULT_LINE_RATE
            if fault is not None:
                self._add_truth(reply, None, packet, item.address, False, fault, item.source)
                return
            if self.config.limit_to_line_rate:
                self._line_free_at = (max(item.send, self._line_free_at)
                                      + len(packet) / LINE_BYTES_PER_SECOND)
            if faults.garbage_probability and rng.random() < faults.garbage_probability:
                garbage = self._garbage(faults)
                self._write_packet(garbage)
                self._stats.garbage_bytes += len(garbage)
                self._stats.garbage_bursts += 1
            if faults.foreign_probability and rng.random() < faults.foreign_probability:
                self._transmit_foreign(reply.code, item.send)
            if faults.corrupt_checksum_probability \
                    and rng.random() < faults.corrupt_checksum_probability:
                packet, fault = self._flip_bit(packet), flt.FAULT_CHECKSUM
            elif faults.corrupt_length_probability \
                    and rng.random() < faults.corrupt_length_probability:
                packet, fault = self._bad_length(packet), flt.FAULT_LENGTH
            error, write_time = self._write_packet(packet)
            valid = fault is None and error is None
            self._add_truth(reply, write_time, packet, item.address, valid, fault or error,
                            item.source)

    def _transmit_foreign(self, code: int, send: float) -> None:
        """Write a well-formed packet of another sensor (lock held)."""
        other = self._foreign.record_at(
            code if code in sns.STREAMABLE else lay.ACCEL_ANG_RATE, send)
        lqi, rssi = self._foreign.link_quality()
        packet = framing.encode_data_packet(self._foreign.address, other.data, lqi, rssi)
        error, write_time = self._write_packet(packet)
        self._add_truth(other, write_time, packet, self._foreign.address, False,
                        flt.FAULT_FOREIGN if error is None else error, 'foreign')

    def _garbage(self, faults: FaultConfig) -> bytes:
        rng = self._fault_rng
        out = bytearray()
        for _ in range(rng.randint(1, faults.garbage_max_bytes)):
            byte = rng.randrange(256)
            while faults.garbage_safe and byte in flt.SIGNIFICANT_BYTES:
                byte = rng.randrange(256)
            out.append(byte)
        return bytes(out)

    def _flip_bit(self, packet: bytes) -> bytes:
        """Flip one bit the checksum covers (record data) or of the checksum itself."""
        rng = self._fault_rng
        data = bytearray(packet)
        record_end = len(data) - 4
        positions = [*range(framing.HEADER_SIZE + 1, record_end), len(data) - 2, len(data) - 1]
        data[rng.choice(positions)] ^= 1 << rng.randrange(8)
        return bytes(data)

    def _bad_length(self, packet: bytes) -> bytes:
        data = bytearray(packet)
        data[5] = (data[5] + self._fault_rng.randint(1, 255)) & 0xFF
        return bytes(data)

    def _add_truth(self, reply: Reply, write_time: float | None, packet: bytes,
                   address: int, valid: bool, fault: str | None, source: str) -> None:
        """Record one data packet in the ground truth and the counters (lock held)."""
        entry = SentRecord(self._truth_index, reply.sample_time, write_time,
                           getattr(reply.record, 'timer', None), reply.record, packet,
                           address, valid, fault, source)
        self._truth_index += 1
        if self._truth is not None:
            self._truth.append(entry)
        stats = self._stats
        if write_time is not None:
            stats.packets_written += 1
        if valid:
            if source == 'stream':
                stats.records_sent += 1
            else:
                stats.replies_sent += 1
        counter = _FAULT_COUNTERS.get(fault)
        if counter is not None:
            setattr(stats, counter, getattr(stats, counter) + 1)
        self._changed.notify_all()

    def _split(self, data: bytes) -> list[bytes]:
        low, high = self.config.chunks
        count = min(self._chunk_rng.randint(low, high), len(data))
        if count <= 1:
            return [data]
        cuts = sorted(self._chunk_rng.sample(range(1, len(data)), count - 1))
        return [data[a:b] for a, b in itertools.pairwise([0, *cuts, len(data)])]

    def _write_packet(self, data: bytes) -> tuple[str | None, float | None]:
        """Write one packet in chunks; return (fault or None, time after its last byte)."""
        chunks = self._split(data)
        gap = self.config.chunk_gap_s
        written = 0
        with self._io_lock:
            master = self._master
            if master is None:
                return flt.FAULT_UNPLUGGED, None
            try:
                for index, chunk in enumerate(chunks):
                    if index and gap:
                        time.sleep(gap)
                    view = memoryview(chunk)
                    while view:
                        count = os.write(master, view)
                        written += count
                        view = view[count:]
            except OSError:
                pass  # the buffer is full (nobody reads): the rest is lost
            write_time = time.time()
        with self.lock:
            self._stats.bytes_written += written
            if written < len(data):
                self._stats.overflow_bytes += len(data) - written
        if written < len(data):
            return flt.FAULT_OVERFLOW, None
        return None, write_time

    def _write_raw(self, data: bytes) -> bool:
        """Write a base-station byte (ACK, NACK, ping answer) between packets."""
        with self._io_lock:
            if self._master is None:
                return False
            try:
                written = os.write(self._master, data)
            except OSError:
                written = 0
        with self.lock:
            self._stats.bytes_written += written
            if written < len(data):
                self._stats.overflow_bytes += len(data) - written
        return written == len(data)


_FAULT_COUNTERS = {
    flt.FAULT_CHECKSUM: 'corrupted_checksum',
    flt.FAULT_LENGTH: 'corrupted_length',
    flt.FAULT_FOREIGN: 'foreign',
    flt.FAULT_DROPPED: 'dropped',
    flt.FAULT_STALL: 'stalled',
    flt.FAULT_UNPLUGGED: 'unplugged_lost',
    flt.FAULT_OVERFLOW: 'overflow_packets',
    flt.FAULT_LINE_RATE: 'line_rate_skipped',
}
