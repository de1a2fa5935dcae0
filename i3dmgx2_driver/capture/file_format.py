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
The capture file: the reads of a port and their times, as a file.

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
"""

from collections.abc import Iterator
import json
import math
import os
import struct
import threading
import time
from typing import Any, BinaryIO, Union
import warnings

from .. import __version__

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


class CaptureFormatError(ValueError):
    """A file that is not a capture, or a capture corrupted beyond its tail."""


class TruncatedCaptureWarning(UserWarning):
    """A capture whose last chunk was cut short, as a crash while writing leaves it."""


def default_header(**overrides: Any) -> dict[str, Any]:
    """Return a header with every standard key, updated with ``overrides``."""
    return {'port': None, 'address': None, 'baud': DEFAULT_BAUD, 'wireless': True,
            'start_time': time.time(), 'tool_version': f'i3dmgx2_driver {__version__}',
            'notes': '', **overrides}


def _header_line(header: dict[str, Any]) -> bytes:
    if not isinstance(header, dict):
        raise TypeError(f'a capture header is a dict, got {type(header).__name__}')
    try:
        # ASCII and no indent: one line whatever the strings contain.
        text = json.dumps({**default_header(), **header}, sort_keys=True, ensure_ascii=True,
                          allow_nan=False)
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
        self.chunks = self.bytes = 0
        self._fsync = fsync
        self._interval = flush_interval
        self._lock = threading.Lock()
        self._dirty = self._closed = False
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

    def write(self, data: bytes, receive_time: float | None = None) -> None:
        """
        Append one read's bytes and the host time they arrived (now if None).

        Empty reads (timeouts) carry nothing to replay and are not stored.
        """
        receive_time = time.time() if receive_time is None else receive_time
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
                warnings.warn(f'{path}: capture ends inside a chunk header at byte {start} '
                              f'({len(head)} of {CHUNK_HEADER.size} bytes); the writer was '
                              f'probably killed; the chunks before it are intact',
                              TruncatedCaptureWarning, stacklevel=2)
                return
            receive_time, count = CHUNK_HEADER.unpack(head)
            if count > MAX_CHUNK_SIZE or not math.isfinite(receive_time):
                raise CaptureFormatError(f'{path}: corrupted chunk at byte {start} (time '
                                         f'{receive_time!r}, {count} bytes)')
            data = f.read(count)
            if len(data) < count:
                warnings.warn(f'{path}: last chunk (byte {start}) cut short: {len(data)} of '
                              f'{count} bytes; the writer was probably killed; yielding what '
                              'is there', TruncatedCaptureWarning, stacklevel=2)
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
