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
The fault capture: the capture nobody has to leave on.

The last seconds of the port's reads, those the raw capture would write, are
kept in memory (:class:`RecentBytes`, bounded by age and by size), always, and
written as a capture file when something goes wrong (a stall, a
disconnect, a device reset, a burst of corrupted packets, a refused
command) or when asked, so that a fault seen in the field can be replayed
offline.
"""

from collections import deque
from collections.abc import Callable, Iterable
import contextlib
import datetime
import math
import os
import re
import threading
import time
from typing import Any

from .file_format import CaptureWriter, Chunk, DEFAULT_BAUD, default_header
from .. import __version__
from ..codec.line_budget import line_bytes_per_second

#: What one kept read costs in memory beyond its bytes (the tuple, the float, the
#: bytes object's header, the deque's slot), counted against the ring's cap.
CHUNK_COST = 120
#: The ring's cap in bytes is this many times the line's bytes per second at the
#: baud times its seconds: room for the data and CHUNK_COST per read at any rate
#: the line carries, while a flood of one-byte reads still cannot grow it further.
RING_BUDGET_FACTOR = 4
#: Seconds of the stream after a fault kept in its file: the recovery, or not.
FAULT_AFTER = 2.0
#: How often the writer thread asks what went wrong (s): once a second wakes it seldom, and
#: the file is written FAULT_AFTER s after the fault is seen, with the seconds before it.
FAULT_POLL = 1.0
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
                 after: float = FAULT_AFTER, poll: float = FAULT_POLL, **header: Any) -> None:
        self.directory = os.path.expanduser(directory) if directory else ''
        self.seconds = seconds
        self.kept = kept
        self.min_gap = seconds if min_gap is None else min_gap
        self.after = after
        self._poll = poll
        self._log = log
        self._header = dict(header, baud=baud)
        #: The ring (None when off).
        budget = int(seconds * line_bytes_per_second(baud) * RING_BUDGET_FACTOR)
        self.ring = RecentBytes(seconds, budget) if self.directory else None
        #: Files written so far, the last one's path and cause; why the last write failed.
        self.written, self.last_path, self.last_cause, self.error = 0, '', '', ''
        self._lock, self._write_lock = threading.Lock(), threading.Lock()
        self._causes: list[str] = []
        self._due: float | None = None
        self._last_write = -math.inf
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
        self._thread = threading.Thread(target=self._run, args=(watch,), name='gx2-fault-capture',
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
        failed = f'last write failed: {self.error}; ' if self.error else ''
        last = f'{self.written} written, the last {self.last_path} ({self.last_cause})' \
            if self.written else 'none written yet'
        return (f'keeping the last {self.seconds:g} s ({reads} reads, {held // 1024} KiB) '
                f'for {self.directory}; {failed}{last}')

    def close(self) -> None:
        """Stop the writer thread (at shutdown: an episode not yet written is dropped)."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(2.0)

    def _run(self, watch: Callable[[], Iterable[str]]) -> None:
        watch_failed = False
        while not self._stop.wait(self._poll):
            try:
                for cause in watch():
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
            start_time=chunks[0][0], driver_version=__version__, cause=cause, written_time=now,
            notes=(f'fault capture by the i3dmgx2_driver node: the last {self.seconds:g} s '
                   f'of reads before it was written ({cause}), as read'), **self._header)
        with CaptureWriter(path, header, flush_interval=None) as writer:
            for receive_time, data in chunks:
                writer.write(data, receive_time)
        return path

    def _prune(self) -> None:
        """Delete the oldest fault captures beyond ``kept`` (the names sort by time)."""
        names = sorted(name for name in os.listdir(self.directory)
                       if name.startswith(FAULT_PREFIX) and name.endswith(FAULT_SUFFIX))
        for name in names[:max(0, len(names) - self.kept)]:
            with contextlib.suppress(FileNotFoundError):  # another driver pruned it first
                os.remove(os.path.join(self.directory, name))
