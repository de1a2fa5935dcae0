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
RSS, descriptors and threads of a process, sampled, and the slopes fitted to them.

A leak shows as a slope against time (or against the faults met), not as a
final value: the long soak (``long_soak.py``) hands its long-lived node
processes to a :class:`Sampler` and fits the slopes at the end (its legs,
the campaign's among them, read their RSS from it), and
``benchmarks/memory_curve.py`` samples a node's anonymous RSS, descriptors
and threads against the faults it met, with :func:`process_sample`,
:func:`rss_kinds` and :func:`fit`. Read from ``/proc``: nothing in the
process is asked or changed.
"""

import os
import statistics
import threading
import time
from typing import TypeVar

#: A sample: a tuple whose first field is its time.
Sample = TypeVar('Sample', bound=tuple)


def fit(points: list[tuple[float, float]]) -> tuple[float, float] | None:
    """
    Return the least-squares slope of (x, y) points and its standard error.

    None for fewer than three points, or all at one x: no line to fit.
    """
    if len(points) < 3:
        return None
    xs, ys = [x for x, _ in points], [y for _, y in points]
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    if sxx == 0:
        return None
    slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sxx
    residual = sum((y - my - slope * (x - mx)) ** 2 for x, y in zip(xs, ys, strict=True))
    return slope, (residual / (len(xs) - 2) / sxx) ** 0.5


def slope_per_hour(samples: list[tuple[float, float]]) -> float | None:
    """Least-squares slope of (time s, value) samples, in value per hour; None if too few."""
    line = fit(samples)
    return None if line is None else line[0] * 3600.0


def by_time(samples: list[Sample], parts: int) -> list[list[Sample]]:
    """
    Split samples into ``parts`` equal spans of their time, a sample on a boundary in both.

    A sample is a tuple, its time first.

    A warm-up slows down from one span to the next (the slope falls off),
    a leak keeps its pace: the spans tell them apart where one slope cannot.
    """
    first, last = samples[0][0], samples[-1][0]
    span = (last - first) / parts
    return [[s for s in samples if first + k * span <= s[0] <= first + (k + 1) * span]
            for k in range(parts)]


def halves_per_hour(samples: list[tuple[float, float]]) -> tuple[float, float] | None:
    """Slopes per hour of the first and the second half of the samples (by time); None if few."""
    if len(samples) < 6:
        return None
    first, second = (slope_per_hour(half) for half in by_time(samples, 2))
    if first is None or second is None:
        return None
    return first, second


#: The parts of RSS /proc tells apart, as named in its status file.
RSS_KINDS = ('RssAnon', 'RssFile', 'RssShmem')


def _status_fields(pid: int, keys: tuple[str, ...]) -> dict[str, int] | None:
    """Return the ``keys`` of /proc/<pid>/status (their first number), None if it is gone."""
    found: dict[str, int] = {}
    try:
        with open(f'/proc/{pid}/status') as handle:
            for line in handle:
                key, _, value = line.partition(':')
                if key in keys:
                    found[key] = int(value.split()[0])
    except OSError:
        return None
    return found if len(found) == len(keys) else None


def process_sample(pid: int) -> tuple[int, int, int] | None:
    """Return (RSS KiB, open descriptors, threads) of a process, None if it is gone."""
    status = _status_fields(pid, ('VmRSS', 'Threads'))
    if status is None:
        return None
    try:
        fds = len(os.listdir(f'/proc/{pid}/fd'))
    except OSError:
        return None
    return status['VmRSS'], fds, status['Threads']


def rss_kinds(pid: int) -> tuple[int, int, int] | None:
    """
    Return a process's RSS as (anonymous, file-backed, shared memory) KiB, None if gone.

    A heap that grows is anonymous memory; library code paged in on the
    first use of a path (a fault handler run for the first time) is
    file-backed and bounded by the libraries' size: the kinds tell a leak
    from a warm-up that RSS alone mixes.
    """
    status = _status_fields(pid, RSS_KINDS)
    return None if status is None else tuple(status[k] for k in RSS_KINDS)


class Sampler(threading.Thread):
    """
    Sample RSS, descriptors and threads of the processes it is given, all run long.

    A managed node has more descriptors and threads while configured (the
    port, the reader and supervisor threads) than while unconfigured, so
    its samples are taken only while it is unconfigured: a leak is then a
    slope, not a change of state.
    """

    def __init__(self, period: float) -> None:
        super().__init__(name='soak-sampler', daemon=True)
        self.period = period
        self.samples: dict[str, list[tuple[float, int, int, int]]] = {}
        self.born: dict[str, float] = {}
        #: Processes configured now (not sampled: compared in one state, unconfigured),
        #: and when each was first released (its warm-up ends then).
        self.busy: set[str] = set()
        self.first_release: dict[str, float] = {}
        #: Every sample, whatever the state (a leg's own RSS check).
        self.all_samples: dict[str, list[tuple[float, int, int, int]]] = {}
        #: RSS by kind (:func:`rss_kinds`), sampled as ``samples`` are: (time, anon, file, shmem).
        self.kinds: dict[str, list[tuple[float, int, int, int]]] = {}
        self._pids: dict[str, int] = {}
        self._lock = threading.Lock()
        self._halt = threading.Event()

    def watch(self, name: str, pid: int) -> None:
        """Start sampling process ``pid`` as ``name``."""
        with self._lock:
            self._pids[name] = pid
            self.born.setdefault(name, time.time())
            self.samples.setdefault(name, [])

    def forget(self, name: str) -> None:
        """Stop sampling ``name`` (its process ended)."""
        with self._lock:
            self._pids.pop(name, None)

    def run(self) -> None:
        """Sample until stopped."""
        while not self._halt.wait(self.period):
            with self._lock:
                pids = dict(self._pids)
            for name, pid in pids.items():
                got = process_sample(pid)
                if got is None:
                    continue
                self.all_samples.setdefault(name, []).append((time.time(), *got))
                if name not in self.busy:  # configured: more descriptors and threads
                    self.samples[name].append((time.time(), *got))
                    kinds = rss_kinds(pid)
                    if kinds is not None:
                        self.kinds.setdefault(name, []).append((time.time(), *kinds))

    def stop(self) -> None:
        """Stop sampling."""
        self._halt.set()
        self.join(5.0)
