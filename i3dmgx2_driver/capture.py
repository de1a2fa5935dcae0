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

r"""
Raw captures of the byte stream from the port, and the real-records fixture.

A capture keeps the bytes exactly as each read returned them, with the host
time of the read, so that a session can be replayed into a pseudo-terminal
(``tools.replay``) with its original pacing and fragmentation, or decoded
later (``tools.plot``) with a parser that did not exist when it was made.
Nothing here knows ROS or serial ports: bytes and times in, bytes and times
out.

The format (version 1), chosen to be appendable, crash-tolerant and readable
with ``head -2``::

    GX2CAP 1\n                        magic line: name and format version
    {"port": ..., ...}\n              one JSON object on one line (the header)
    chunk*                            until the end of the file

    chunk = struct '>dI' (receive time: float64 seconds since the epoch,
            byte count: uint32) followed by that many bytes, as read

Header keys the writer always fills: ``port``, ``address``, ``baud``,
``wireless``, ``start_time`` (seconds since the epoch), ``tool_version``,
``notes``; any other JSON value may be added. A crash while writing can
only cut the last chunk short: the reader yields what is there and warns.

The node's raw capture (:class:`RawCapture`) is such a capture of every
byte the reader reads, with its receive time. The device layer calls
:meth:`RawCapture.on_bytes` from the reader thread right after each read,
before parsing, so the capture holds exactly what came off the port,
garbage and all, and can be replayed into a pseudo-terminal or decoded by a
later parser (``tools``). A capture is a convenience, never a reason to stop
the driver: if the file cannot be opened or written (disk full, permission,
a size limit), that is logged once and capture turns itself off while the
stream goes on.

The fault capture (:class:`FaultCapture`) is the capture nobody has to
leave on: the last seconds of the same reads are kept in memory
(:class:`RecentBytes`, bounded by age and by size), always, and written as
a capture file of this format when something goes wrong (a stall, a
disconnect, a device reset, a burst of corrupted packets, a refused
command) or when asked, so that a fault seen in the field can be replayed
offline.
"""

from collections import deque
from collections.abc import Callable, Iterable, Iterator
import datetime
import json
import math
import os
import random
import re
import struct
import threading
import time
from typing import Any, BinaryIO, NamedTuple, Union
import warnings

from . import __version__
from .codec.commands import decode_record
from .codec.framing import encode_data_packet
from .codec.records import TICKS_PER_SECOND
from .codec.timer import TIMER_MODULUS

PathLike = Union[str, 'os.PathLike[str]']
Chunk = tuple[float, bytes]

#: First line of every capture; the number is the format version.
MAGIC = b'GX2CAP 1\n'
#: Prefix shared by every version of the format, to name a newer one.
MAGIC_PREFIX = b'GX2CAP '
#: Format version this module reads and writes.
FORMAT_VERSION = 1
#: Chunk header: host receive time (float64, s since epoch), byte count (uint32).
CHUNK_HEADER = struct.Struct('>dI')
#: No read from a serial port returns more than this; a larger count is corruption.
MAX_CHUNK_SIZE = 1 << 24
#: The writer flushes at least this often (s), so that a crash loses little.
FLUSH_INTERVAL = 1.0
#: Longest header line accepted, so that a wrong file is not read whole.
MAX_HEADER_SIZE = 1 << 20
#: Default serial speed of the sensor and base station.
DEFAULT_BAUD = 115200

#: Node address given to fixture records (the fixture did not record one).
FIXTURE_ADDRESS = 95
#: Where fixture-made captures start (2016-05-01 00:00 UTC, when it was recorded).
FIXTURE_EPOCH = 1462060800.0
#: Silence put between the fixture's captures, whose timers do not continue
#: (the sensor was re-posed by hand, and possibly power-cycled, in between).
FIXTURE_GAP = 30.0


class CaptureFormatError(ValueError):
    """A file that is not a capture, or a capture corrupted beyond its tail."""


class TruncatedCaptureWarning(UserWarning):
    """A capture whose last chunk was cut short, as a crash while writing leaves it."""


def default_header(**overrides: Any) -> dict[str, Any]:
    """Return a header with every standard key, updated with ``overrides``."""
    header: dict[str, Any] = {
        'port': None,
        'address': None,
        'baud': DEFAULT_BAUD,
        'wireless': True,
        'start_time': time.time(),
        'tool_version': f'i3dmgx2_driver {__version__}',
        'notes': '',
    }
    header.update(overrides)
    return header


def _header_line(header: dict[str, Any]) -> bytes:
    if not isinstance(header, dict):
        raise TypeError(f'a capture header is a dict, got {type(header).__name__}')
    full = default_header()
    full.update(header)
    try:
        # ASCII and no indent: one line whatever the strings contain.
        text = json.dumps(full, sort_keys=True, ensure_ascii=True, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'capture header is not plain JSON: {exc}') from None
    return text.encode('ascii') + b'\n'


class CaptureWriter:
    """
    Append chunks to a new capture file, from any number of threads.

    Writes go through a buffer, so that a port read of a few bytes does not
    cost a system call each; a background thread flushes the buffer at least
    every ``flush_interval`` seconds, so that a crash (or a kill) loses at
    most that much of the stream. ``fsync`` also asks the OS to put each
    flush on disk, for captures that must survive a power cut.
    ``flush_interval`` None starts no thread, for a file written whole at
    once and closed (a fault capture): a thread started per file would cost
    memory that stays (device/reader_threads.py says how).
    """

    def __init__(self, path: PathLike, header: dict[str, Any] | None = None,
                 flush_interval: float | None = FLUSH_INTERVAL, fsync: bool = False) -> None:
        if flush_interval is not None and not flush_interval > 0:
            raise ValueError(f'flush_interval must be positive, got {flush_interval!r}')
        line = _header_line(header or {})
        self.path = os.fspath(path)
        self.chunks = 0
        self.bytes = 0
        self._fsync = fsync
        self._interval = flush_interval
        self._lock = threading.Lock()
        self._dirty = False
        self._closed = False
        # Open for the writer's lifetime, closed by close() (or __exit__).
        self._file: BinaryIO = open(self.path, 'wb', buffering=64 * 1024)  # noqa: SIM115
        try:
            self._file.write(MAGIC + line)
            self._flush_locked()
        except BaseException:
            self._file.close()
            raise
        self._stop = threading.Event()
        self._flusher: threading.Thread | None = None
        if flush_interval is not None:
            self._flusher = threading.Thread(
                target=self._flush_loop, name='capture-flush', daemon=True)
            self._flusher.start()

    def __enter__(self) -> 'CaptureWriter':
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        """Tell whether :meth:`close` has run."""
        return self._closed

    def write(self, data: bytes, receive_time: float | None = None) -> None:
        """
        Append one read's bytes and the host time they arrived (now if None).

        Empty reads (timeouts) carry nothing to replay and are not stored.
        """
        if receive_time is None:
            receive_time = time.time()
        if not math.isfinite(receive_time):
            raise ValueError(f'receive time must be finite, got {receive_time!r}')
        data = bytes(data)
        if len(data) > MAX_CHUNK_SIZE:
            raise ValueError(f'a chunk is at most {MAX_CHUNK_SIZE} bytes, got {len(data)}')
        if not data:
            return
        with self._lock:
            if self._closed:
                raise ValueError('write to a closed capture')
            # One write call per chunk: a crash can tear only the last chunk.
            self._file.write(CHUNK_HEADER.pack(receive_time, len(data)) + data)
            self._dirty = True
            self.chunks += 1
            self.bytes += len(data)

    def flush(self) -> None:
        """Push buffered chunks to the OS now."""
        with self._lock:
            if not self._closed:
                self._flush_locked()

    def close(self) -> None:
        """Flush, stop the flusher thread and close the file; idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._flush_locked()
            finally:
                self._file.close()
        self._stop.set()
        if self._flusher is not None and self._flusher is not threading.current_thread():
            self._flusher.join()

    def _flush_locked(self) -> None:
        self._file.flush()
        if self._fsync:
            os.fsync(self._file.fileno())
        self._dirty = False

    def _flush_loop(self) -> None:
        while not self._stop.wait(self._interval):
            with self._lock:
                if self._closed:
                    return
                if self._dirty:
                    self._flush_locked()


def _read_header(f: BinaryIO, path: str) -> dict[str, Any]:
    magic = f.read(len(MAGIC))
    if magic != MAGIC:
        if magic.startswith(MAGIC_PREFIX):
            version = magic[len(MAGIC_PREFIX):].strip().decode('ascii', 'replace')
            raise CaptureFormatError(
                f'{path}: capture format version {version}; this tool reads version '
                f'{FORMAT_VERSION}')
        raise CaptureFormatError(f'{path}: not a capture file (no {MAGIC[:-1]!r} line)')
    line = f.readline(MAX_HEADER_SIZE)
    if not line.endswith(b'\n'):
        raise CaptureFormatError(f'{path}: header line missing or cut short')
    try:
        header = json.loads(line.decode('utf-8'))
    except (UnicodeDecodeError, ValueError) as exc:
        raise CaptureFormatError(f'{path}: header is not JSON: {exc}') from None
    if not isinstance(header, dict):
        raise CaptureFormatError(f'{path}: header is not a JSON object')
    return header


def _iter_chunks(path: str, offset: int) -> Iterator[Chunk]:
    with open(path, 'rb') as f:
        f.seek(offset)
        while True:
            start = f.tell()
            head = f.read(CHUNK_HEADER.size)
            if not head:
                return
            if len(head) < CHUNK_HEADER.size:
                warnings.warn(
                    f'{path}: capture ends inside a chunk header at byte {start} '
                    f'({len(head)} of {CHUNK_HEADER.size} bytes); the writer was probably '
                    f'killed; the chunks before it are intact', TruncatedCaptureWarning,
                    stacklevel=2)
                return
            receive_time, count = CHUNK_HEADER.unpack(head)
            if count > MAX_CHUNK_SIZE or not math.isfinite(receive_time):
                raise CaptureFormatError(
                    f'{path}: corrupted chunk at byte {start} (time {receive_time!r}, '
                    f'{count} bytes)')
            data = f.read(count)
            if len(data) < count:
                warnings.warn(
                    f'{path}: last chunk (byte {start}) cut short: {len(data)} of {count} '
                    f'bytes; the writer was probably killed; yielding what is there',
                    TruncatedCaptureWarning, stacklevel=2)
                if data:
                    yield receive_time, data
                return
            yield receive_time, data


def read_capture(path: PathLike) -> tuple[dict[str, Any], Iterator[Chunk]]:
    """
    Read a capture: its header now, its ``(receive_time, bytes)`` chunks lazily.

    The chunks are read as they are iterated, so an hour-long capture does not
    sit in memory. A truncated last chunk ends the iteration with a
    :class:`TruncatedCaptureWarning`; it is yielded if any of its bytes are
    there, since they did arrive. Anything else wrong raises
    :class:`CaptureFormatError`.
    """
    path = os.fspath(path)
    with open(path, 'rb') as f:
        header = _read_header(f, path)
        offset = f.tell()
    return header, _iter_chunks(path, offset)


def is_capture(path: PathLike) -> bool:
    """Tell a capture from another file (a CSV) by its magic line."""
    with open(path, 'rb') as f:
        return f.read(len(MAGIC_PREFIX)) == MAGIC_PREFIX


# The real-records fixture ---------------------------------------------------


class FixtureSet(NamedTuple):
    """One of the fixture's captures: a pose name and its records, as bytes."""

    name: str
    description: str
    records: list[bytes]


def load_fixture(path: PathLike) -> list[FixtureSet]:
    """
    Read the real-records fixture: ``## set NAME: description`` lines, hex records.

    Every record is decoded once here, so that a damaged fixture fails loudly
    rather than turning into a capture the parser silently skips.
    """
    sets: list[FixtureSet] = []
    with open(path, encoding='utf-8') as f:
        for number, raw in enumerate(f, 1):
            line = raw.strip()
            if line.startswith('## set'):
                name, _, description = line[len('## set'):].partition(':')
                sets.append(FixtureSet(name.strip(), description.strip(), []))
                continue
            if not line or line.startswith('#'):
                continue
            try:
                record = bytes.fromhex(line)
                decode_record(record)
            except ValueError as exc:
                raise ValueError(f'{path}:{number}: not a record: {exc}') from None
            if not sets:
                sets.append(FixtureSet('records', '', []))
            sets[-1].records.append(record)
    return [s for s in sets if s.records]


def record_timer(record: bytes) -> int:
    """Return the timer of a record: its last four bytes, big-endian."""
    return int.from_bytes(record[-4:], 'big')


def timeline(sets: Iterable[FixtureSet],
             gap: float = FIXTURE_GAP) -> list[tuple[float, int, bytes]]:
    """
    Place the fixture's records on one time line: ``(seconds, set index, record)``.

    Within a set the timer never restarts, so each step is taken forward
    modulo 2^32: that unwraps the rollover, and it also keeps the one pause in
    set1 that is longer than half the timer's period (168.5 s), which a
    general-purpose unwrapper must take for a reset. Between sets the timer
    jumps arbitrarily, so ``gap`` seconds of silence stand in for the time the
    sensor was being re-posed. The line starts at 0.
    """
    out: list[tuple[float, int, bytes]] = []
    offset = 0.0
    for index, fixture_set in enumerate(sets):
        first = record_timer(fixture_set.records[0])
        ticks = 0
        last = first
        for record in fixture_set.records:
            raw = record_timer(record)
            ticks += (raw - last) % TIMER_MODULUS
            last = raw
            out.append((offset + ticks / TICKS_PER_SECOND, index, record))
        if out:
            offset = out[-1][0] + gap
    return out


def fixture_chunks(path: PathLike, address: int = FIXTURE_ADDRESS,
                   start_time: float = FIXTURE_EPOCH, gap: float = FIXTURE_GAP,
                   seed: int = 2016) -> Iterator[Chunk]:
    """
    Turn the fixture into the chunks a host would have read from the base station.

    One data packet per read, as at the fixture's ~3 Hz polling, received at
    ``start_time`` plus the record's place on :func:`timeline`. LQI and RSSI
    were not recorded: they are drawn, reproducibly from ``seed``, from a
    good, steady link (the sensor sat still near the base station).
    """
    rng = random.Random(seed)
    for seconds, _, record in timeline(load_fixture(path), gap):
        lqi = min(255, max(0, round(rng.gauss(228, 6))))
        rssi = min(255, max(0, round(rng.gauss(190, 4))))
        yield start_time + seconds, encode_data_packet(address, record, lqi, rssi)


def fixture_to_capture(fixture_path: PathLike, capture_path: PathLike,
                       address: int = FIXTURE_ADDRESS, start_time: float = FIXTURE_EPOCH,
                       gap: float = FIXTURE_GAP) -> dict[str, Any]:
    """
    Write the real-records fixture as a capture; return the header written.

    The header's ``segments`` list names each of the fixture's captures and
    the receive time of its first record, so a plot can label them.
    """
    sets = load_fixture(fixture_path)
    places = timeline(sets, gap)
    segments = []
    seen = set()
    for seconds, index, _ in places:
        if index not in seen:
            seen.add(index)
            segments.append({'label': f'{sets[index].name}: {sets[index].description}',
                             'start_time': start_time + seconds})
    header = default_header(
        port='fixture', address=address, baud=DEFAULT_BAUD, wireless=True,
        start_time=start_time,
        notes=(f'Made from {os.path.basename(os.fspath(fixture_path))}: real 0xCC records '
               f'({len(places)}) polled at ~3 Hz; wireless envelope, LQI and RSSI '
               f'synthesised; receive times from the device timer; {gap:g} s inserted '
               f"between the fixture's captures, whose timers do not continue."),
        segments=segments)
    with CaptureWriter(capture_path, header, flush_interval=None) as writer:
        for receive_time, packet in fixture_chunks(fixture_path, address, start_time, gap):
            writer.write(packet, receive_time)
    return header


# -- the node's raw capture ---------------------------------------------------

class _Writer(CaptureWriter):
    """
    A CaptureWriter whose background flush keeps its error instead of dying with it.

    The base class flushes from its own thread; an I/O error there would end
    that thread with a traceback and leave the reader to find out only when
    the buffer fills. Here the error is kept, and the next write reports it.
    """

    error: Exception | None = None

    def _flush_loop(self) -> None:
        try:
            super()._flush_loop()
        except (OSError, ValueError) as exc:
            self.error = exc


class RawCapture:
    """
    Write what the reader reads to ``path`` ('' or None: do nothing).

    ``log`` is any logger with ``info``/``error``. ``header`` values are
    added to the capture's header (port, address, baud, wireless...).
    """

    def __init__(self, path: str | None, log: Any, **header: Any) -> None:
        self.path = os.path.expanduser(path) if path else ''
        self._log = log
        self._writer: _Writer | None = None
        self._lock = threading.Lock()
        #: '' while fine (or off), else why capture stopped.
        self.error = ''
        if not self.path:
            return
        existed = os.path.exists(self.path)
        try:
            self._writer = _Writer(self.path, default_header(
                start_time=time.time(), tool_version=f'i3dmgx2_driver {__version__}',
                driver_version=__version__,
                notes='raw capture by the i3dmgx2_driver node: every read, as read',
                **header))
        except (OSError, ValueError) as exc:
            self._fail(f'cannot write the raw capture {self.path}: {exc}')
            return
        self._log.info(f'raw capture to {self.path}'
                       + (' (the existing file was overwritten)' if existed else ''))

    @property
    def active(self) -> bool:
        """Whether bytes are being written now."""
        return self._writer is not None

    def describe(self) -> str:
        """One line for diagnostics: off, the file and its size, or why it stopped."""
        writer = self._writer
        if writer is not None:
            return f'{self.path}: {writer.chunks} reads, {writer.bytes} bytes'
        if self.error:
            return f'stopped: {self.error}'
        return 'off'

    def on_bytes(self, data: bytes, receive_time: float) -> None:
        """Store one read (called from the reader thread; never raises)."""
        writer = self._writer
        if writer is None:
            return
        try:
            if writer.error is not None:
                raise writer.error
            writer.write(data, receive_time)
        except (OSError, ValueError) as exc:
            self._fail(f'raw capture to {self.path} failed, capture is off: {exc}')

    def _fail(self, message: str) -> None:
        """Log once, stop writing, and let the file go (away from the reader thread)."""
        with self._lock:
            if self.error:
                return
            self.error = message
            writer, self._writer = self._writer, None
        self._log.error(message + '; the driver keeps running without it')
        if writer is not None:
            threading.Thread(target=self._close_quietly, args=(writer,),
                             name='gx2-capture-close', daemon=True).start()

    @staticmethod
    def _close_quietly(writer: CaptureWriter) -> None:
        try:
            writer.close()
        except (OSError, ValueError):
            pass  # the error that stopped it was already logged

    def close(self) -> None:
        """Flush and close the file (at shutdown, after the reader stopped)."""
        with self._lock:
            writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            if writer.error is not None:
                raise writer.error
            writer.close()
        except (OSError, ValueError) as exc:
            self.error = str(exc)
            self._log.error(f'raw capture to {self.path}: closing failed: {exc}')
            self._close_quietly(writer)


def bytes_sink(*sinks: Callable[[bytes, float], None] | None
               ) -> Callable[[bytes, float], None] | None:
    """
    Return one ``on_bytes`` callback that hands each read to every sink given.

    None when no sink is given (the reader then does nothing per read), the
    one sink itself when only one is, so that a single capture costs what it
    always did.
    """
    live = [sink for sink in sinks if sink is not None]
    if not live:
        return None
    if len(live) == 1:
        return live[0]

    def every(data: bytes, receive_time: float) -> None:
        for sink in live:
            sink(data, receive_time)
    return every


# -- the fault capture: the last seconds, kept always -------------------------------

#: What one kept read costs in memory beyond its bytes (the tuple, the float, the
#: bytes object's header, the deque's slot), counted against the ring's cap.
CHUNK_COST = 120
#: The ring's cap in bytes is this many times the line's bytes per second at the
#: baud times its seconds: room for the data and CHUNK_COST per read at any rate
#: the line carries, while a flood of one-byte reads still cannot grow it further.
RING_BUDGET_FACTOR = 4
#: Seconds of the stream after a fault kept in its file: the recovery, or not.
FAULT_AFTER = 2.0
#: How often the writer thread asks what went wrong (s).
FAULT_POLL = 0.25
#: Name of every fault capture file: prefix, UTC time to the millisecond, cause.
FAULT_PREFIX = 'i3dmgx2_'
FAULT_SUFFIX = '.gx2cap'


class RecentBytes:
    """
    The last ``seconds`` of reads, ``(receive_time, bytes)``, in memory.

    The reader thread appends each read as it is (the chunk is kept by
    reference, not copied) and drops the oldest that are older than
    ``seconds`` or beyond ``max_bytes`` (each read counted with
    :data:`CHUNK_COST`), so the memory held is bounded whatever the line
    does (a system clock stepped back, which keeps the age from trimming,
    included). One uncontended lock per read keeps :meth:`snapshot` (another
    thread) from seeing the deques change under it.

    The times and the chunks are kept in two deques rather than one of
    ``(time, bytes)`` tuples: a float and a bytes object are not tracked by
    the garbage collector, a tuple is, so a ring of tuples would leave one
    tracked object behind per read for ``seconds`` and bring back the
    collections the sample's path is built to avoid
    (test/test_hot_path_allocation.py).
    """

    def __init__(self, seconds: float, max_bytes: int) -> None:
        if not seconds > 0 or max_bytes <= 0:
            raise ValueError(f'a ring needs seconds and bytes, got {seconds!r}, {max_bytes!r}')
        self.seconds = seconds
        self.max_bytes = max_bytes
        self._times: deque[float] = deque()
        self._data: deque[bytes] = deque()
        self._held = 0
        self._lock = threading.Lock()

    def on_bytes(self, data: bytes, receive_time: float) -> None:
        """Keep one read and forget what is now too old (the reader thread; never raises)."""
        with self._lock:
            times, chunks = self._times, self._data
            times.append(receive_time)
            chunks.append(data)
            self._held += len(data) + CHUNK_COST
            oldest = receive_time - self.seconds
            while times and (times[0] < oldest or self._held > self.max_bytes):
                times.popleft()
                self._held -= len(chunks.popleft()) + CHUNK_COST

    def snapshot(self) -> list[Chunk]:
        """Return the reads kept now, oldest first."""
        with self._lock:
            return list(zip(self._times, self._data, strict=True))

    @property
    def held(self) -> tuple[int, int]:
        """Return the reads kept and the bytes counted for them (data and CHUNK_COST)."""
        with self._lock:
            return len(self._times), self._held


class FaultCapture:
    """
    Keep the last ``seconds`` of the port; write them to ``directory`` when something goes wrong.

    ``directory`` '' or None: off (nothing kept, nothing written). ``log``
    has ``info``/``warning``/``error``; ``header`` values go into every
    file's header (port, address, baud, wireless, node). The ring is fed by
    :meth:`on_bytes` from the reader thread. :meth:`start` starts the
    ``gx2-fault-capture`` thread, which asks ``watch`` every
    :data:`FAULT_POLL` s what went wrong since it last asked (a list of
    causes) and writes the file: the writing never runs in the reader
    thread. A file is written :data:`FAULT_AFTER` s after the fault that
    opened its episode (so that the recovery, or its failure, is in it too);
    the faults seen meanwhile, and within ``min_gap`` s (default
    ``seconds``) of the last file, join the same episode and its name, so
    that a storm (a corrupted packet after another, a port that keeps
    failing) writes one file per ``min_gap``, not one per fault, and those
    files together still hold every byte of it. At most ``kept`` files are
    kept in the directory; the oldest go first. :meth:`save` writes one now
    (the ``~/save_capture`` service). Like the raw capture, it is a
    convenience, never a reason to stop the driver: a file that cannot be
    written is logged and the ring goes on.
    """

    def __init__(self, directory: str | None, seconds: float, kept: int, log: Any, *,
                 baud: int = DEFAULT_BAUD, min_gap: float | None = None,
                 after: float = FAULT_AFTER, poll: float = FAULT_POLL,
                 **header: Any) -> None:
        self.directory = os.path.expanduser(directory) if directory else ''
        self.seconds = seconds
        self.kept = kept
        self.min_gap = seconds if min_gap is None else min_gap
        self.after = after
        self._poll = poll
        self._log = log
        self._header = dict(header, baud=baud)
        #: The ring (None when off).
        self.ring: RecentBytes | None = None
        if self.directory:
            self.ring = RecentBytes(seconds, int(seconds * baud / 10 * RING_BUDGET_FACTOR))
        #: Files written so far, the last one's path and cause; why the last write failed.
        self.written = 0
        self.last_path = ''
        self.last_cause = ''
        self.error = ''
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._causes: list[str] = []
        self._due: float | None = None
        self._last_write = -math.inf
        self._watch: Callable[[], Iterable[str]] = list
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def active(self) -> bool:
        """Whether the last seconds are kept (a directory is set)."""
        return self.ring is not None

    @property
    def on_bytes(self) -> Callable[[bytes, float], None] | None:
        """Return the reader's callback that feeds the ring (None when off)."""
        return self.ring.on_bytes if self.ring is not None else None

    def start(self, watch: Callable[[], Iterable[str]]) -> None:
        """Start the writer thread, which asks ``watch`` what went wrong (once; when on)."""
        if self.ring is None or self._thread is not None:
            return
        self._watch = watch
        self._thread = threading.Thread(target=self._run, name='gx2-fault-capture',
                                        daemon=True)
        self._thread.start()

    def trigger(self, cause: str, now: float | None = None) -> None:
        """Note a fault (any thread): it opens an episode, or joins the one open."""
        if self.ring is None:
            return
        now = time.monotonic() if now is None else now
        with self._lock:
            if cause not in self._causes:
                self._causes.append(cause)
            if self._due is None:
                self._due = max(now + self.after, self._last_write + self.min_gap)

    def due(self, now: float | None = None) -> str:
        """Return the causes of the episode to write now, '' if none (the writer's question)."""
        now = time.monotonic() if now is None else now
        with self._lock:
            if self._due is None or now < self._due:
                return ''
            cause = '+'.join(self._causes)
            self._causes, self._due, self._last_write = [], None, now
            return cause

    def save(self, cause: str = 'request') -> str:
        """
        Write the last seconds now; return the file's path.

        Raises OSError (or ValueError: off, nothing read yet) with why not.
        Not counted as an episode: a fault right after still gets its file.
        """
        if self.ring is None:
            raise ValueError('fault capture is off (fault_capture_dir is empty)')
        chunks = self.ring.snapshot()
        if not chunks:
            raise ValueError('nothing read from the port yet')
        with self._write_lock:
            path = self._write(cause, chunks)
            self._prune()
        with self._lock:
            self.written += 1
            self.last_path, self.last_cause, self.error = path, cause, ''
        return path

    def describe(self) -> str:
        """One line for diagnostics: off, what is kept, and the last file written."""
        if self.ring is None:
            return 'off'
        reads, held = self.ring.held
        text = (f'keeping the last {self.seconds:g} s ({reads} reads, {held // 1024} KiB) '
                f'for {self.directory}; ')
        if self.error:
            text += f'last write failed: {self.error}; '
        if self.written:
            return text + f'{self.written} written, the last {self.last_path} ({self.last_cause})'
        return text + 'none written yet'

    def close(self) -> None:
        """Stop the writer thread (at shutdown: an episode not yet written is dropped)."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(2.0)

    def _run(self) -> None:
        watch_failed = False
        while not self._stop.wait(self._poll):
            try:
                for cause in self._watch():
                    self.trigger(cause)
            except Exception as exc:  # noqa: BLE001 - a convenience must not end its thread
                if not watch_failed:
                    watch_failed = True
                    self._log.error(f'fault capture: cannot tell what went wrong: {exc!r}')
            cause = self.due()
            if not cause:
                continue
            try:
                path = self.save(cause)
            except (OSError, ValueError) as exc:
                self.error = str(exc)
                self._log.error(f'fault capture ({cause}) not written: {exc}; the driver '
                                'keeps running without it')
                continue
            self._log.warning(f'fault capture ({cause}): the last {self.seconds:g} s of the '
                              f'port written to {path}')

    def _write(self, cause: str, chunks: list[Chunk]) -> str:
        os.makedirs(self.directory, exist_ok=True)
        now = time.time()
        stamp = datetime.datetime.fromtimestamp(now, datetime.timezone.utc)
        name = (f'{FAULT_PREFIX}{stamp:%Y%m%dT%H%M%S}.{stamp.microsecond // 1000:03d}Z_'
                f"{re.sub(r'[^A-Za-z0-9_+-]', '_', cause)}")
        path = os.path.join(self.directory, name + FAULT_SUFFIX)
        again = 1
        while os.path.exists(path):  # two in one millisecond: neither overwrites the other
            again += 1
            path = os.path.join(self.directory, f'{name}-{again}{FAULT_SUFFIX}')
        header = default_header(
            start_time=chunks[0][0], driver_version=__version__, cause=cause,
            written_time=now,
            notes=(f'fault capture by the i3dmgx2_driver node: the last {self.seconds:g} s '
                   f'of reads before it was written ({cause}), as read'),
            **self._header)
        with CaptureWriter(path, header, flush_interval=None) as writer:
            for receive_time, data in chunks:
                writer.write(data, receive_time)
        return path

    def _prune(self) -> None:
        """Delete the oldest fault captures beyond ``kept`` (the names sort by time)."""
        names = sorted(name for name in os.listdir(self.directory)
                       if name.startswith(FAULT_PREFIX) and name.endswith(FAULT_SUFFIX))
        for name in names[:max(0, len(names) - self.kept)]:
            try:
                os.remove(os.path.join(self.directory, name))
            except FileNotFoundError:
                pass  # another driver writing here pruned it first
