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
Where a sample's time goes: the hot path's stages, reported to an observer when asked.

A sample's path runs in the reader thread: the port's bytes are read, the
parser turns them into records, the sample clock stamps each record, the
message is packed and published. :class:`HotPathObserver` is told each
stage boundary as it passes, so a benchmark or a test times the real path
without replacing any of its functions. The link reports the read and the
parse (the codec knows bytes only and is timed from around its call), the
driver core the stamp, the pack and the publish.

There is one observer for the process, :data:`timings`, here and nowhere
else, installed once before the node starts (:func:`observe`). Off (the
default, None), the path is not touched: the reader and the record publisher
look once, when they start, and only then wrap what marks a stage
(:func:`marked`, :func:`timed_read`); nothing of it runs for a record.
The node turns it on only when asked: ``main.py`` reads :data:`TIMINGS_ENV`
through :func:`recorder_from_environment` and, if it names a file, records
every sample's stage times with :class:`TimingsRecorder` and writes them
there at shutdown.
"""

from collections.abc import Callable
import gc
import json
import os
import time
from typing import Any, Protocol

#: Environment variable naming the JSON file the node writes its hot-path timings to.
TIMINGS_ENV = 'I3DMGX2_TIMINGS'
#: Set to 1, the parse and the stamp are marked too (:attr:`HotPathObserver.stages`).
STAGES_ENV = 'I3DMGX2_TIMINGS_STAGES'


class HotPathObserver(Protocol):
    """
    Told every stage boundary of a sample's path, in the reader thread, as it passes.

    Each method must return at once and must not raise: it runs on the
    latency path. Several records parsed from one read share the read and
    the parse; each then gets its own stamp, pack and publish.

    The read, the pack and the publish are told always; the parse and the
    stamp only when :attr:`stages` is true: two marks more a record, which
    the floor (benchmarks/floor_node.py) does not carry, so that a CPU
    compared with the floor's carries the floor's marks alone.
    """

    #: Whether :meth:`parsed` and :meth:`stamped` are told.
    stages: bool

    def read(self, nbytes: int, read_time: float) -> None:
        """Note that a read returned ``nbytes`` bytes, at ``read_time`` (system clock)."""

    def parsed(self) -> None:
        """Note that the parser returned what those bytes completed."""

    def stamped(self) -> None:
        """Note that the sample clock stamped a record."""

    def packed(self, timer: int) -> None:
        """Note that the Imu message of the record with ``timer`` was packed."""

    def published(self, stamp: float) -> None:
        """Note that ``publish()`` returned for that Imu message, stamped ``stamp``."""


#: The fields of :attr:`TimingsRecorder.rows`, in order.
ROW_FIELDS = ('timer', 'stamp', 'read', 'parsed', 'stamped', 'packed', 'published',
              'cpu_read', 'cpu_published')


class TimingsRecorder:
    """
    A :class:`HotPathObserver` that keeps every sample's stage times, for benchmarks.

    Each published Imu message adds one row (:data:`ROW_FIELDS`): the record's
    timer and its message's stamp, the system-clock time of its read, of its
    parse and stamp (None unless ``stages``), pack and ``publish()`` returned,
    and the reader thread's CPU time at the read and after the publish (their
    difference against the wall clock's is the time the thread did not run).
    It also notes every garbage collection and the reader thread's
    scheduling; :meth:`save` writes it all as JSON.
    """

    def __init__(self, clock: Any = time.time, cpu_clock: Any = time.thread_time,
                 stages: bool = False) -> None:
        self._clock, self._cpu_clock = clock, cpu_clock
        self.stages = stages
        #: One row per published message (:data:`ROW_FIELDS`).
        self.rows: list[tuple] = []
        #: Every garbage collection: (generation, start, duration).
        self.collections: list[tuple[int, float, float]] = []
        #: The reader thread's scheduling, noted at its first read: policy, priority, CPUs.
        self.reader: dict[str, Any] = {}
        self._marks: list[Any] = [0.0, 0.0 if stages else None, 0.0 if stages else None,
                                  0.0, 0.0, 0]
        self._gc_start = 0.0
        gc.callbacks.append(self._on_gc)

    # -- the observer ------------------------------------------------------------------

    def read(self, nbytes: int, read_time: float) -> None:
        """Note the read's time and the thread's CPU time."""
        self._marks[0], self._marks[4] = read_time, self._cpu_clock()
        if not self.reader:
            self.reader = {'policy': os.sched_getscheduler(0),
                           'priority': os.sched_getparam(0).sched_priority,
                           'cpus': sorted(os.sched_getaffinity(0))}

    def parsed(self) -> None:
        """Note the parse's end."""
        self._marks[1] = self._clock()

    def stamped(self) -> None:
        """Note the stamp's end."""
        self._marks[2] = self._clock()

    def packed(self, timer: int) -> None:
        """Note the pack's end, and the record's timer."""
        self._marks[3], self._marks[5] = self._clock(), timer

    def published(self, stamp: float) -> None:
        """Add the row of this message."""
        now = self._clock()
        m = self._marks
        self.rows.append((m[5], stamp, m[0], m[1], m[2], m[3], now, m[4], self._cpu_clock()))

    # -- the rest ----------------------------------------------------------------------

    def _on_gc(self, phase: str, info: dict) -> None:
        now = self._clock()
        if phase == 'start':
            self._gc_start = now
        else:
            self.collections.append((info['generation'], self._gc_start,
                                     now - self._gc_start))

    def save(self, path: str) -> None:
        """Stop noting collections; write everything as JSON to ``path``."""
        if self._on_gc in gc.callbacks:
            gc.callbacks.remove(self._on_gc)
        # What a full collection costs now: what one would add to a sample it delays.
        start = time.perf_counter()
        gc.collect()
        full_collection = time.perf_counter() - start
        document = {'fields': list(ROW_FIELDS), 'rows': self.rows,
                    'collections': self.collections, 'reader': self.reader,
                    'gc_frozen': gc.get_freeze_count(),
                    'full_collection': full_collection, 'pid': os.getpid()}
        with open(path, 'w') as handle:
            json.dump(document, handle)


#: The hot path's one observer, None while off: read at every stage boundary.
timings: HotPathObserver | None = None


def observe(observer: HotPathObserver | None) -> None:
    """
    Make ``observer`` the hot path's observer from now on (None: off).

    Once, before the node starts: a reader already reading keeps the one it
    found when it started.
    """
    global timings  # noqa: PLW0603 - the process's one hook, set before the node starts
    timings = observer


def marked(fn: Callable[..., Any], stage: str) -> Callable[..., Any]:
    """Return ``fn`` telling the observer ``stage`` (``'parsed'``, ...) once it returned."""
    mark = getattr(timings, stage)

    def timed(*args: Any) -> Any:
        out = fn(*args)
        mark()
        return out
    return timed


def timed_read(read: Callable[[float], bytes]) -> Callable[[float], bytes]:
    """Return the port's ``read`` telling the observer what it returned, and when."""
    note = timings.read

    def timed(timeout: float) -> bytes:
        data = read(timeout)
        note(len(data), time.time())
        return data
    return timed


def recorder_from_environment() -> tuple[TimingsRecorder | None, str]:
    """
    Return a recorder, installed as the observer, and its file if :data:`TIMINGS_ENV` names one.

    It marks the parse and the stamp too when :data:`STAGES_ENV` is 1. Without
    the variable: (None, '') and the observer is left as it is.
    """
    path = os.environ.get(TIMINGS_ENV, '')
    recorder = TimingsRecorder(stages=os.environ.get(STAGES_ENV) == '1') if path else None
    if recorder is not None:
        observe(recorder)
    return recorder, path
