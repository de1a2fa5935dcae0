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
RSS, descriptors and threads of long-lived processes, sampled, and their slopes.

A leak shows as a slope against time, not as a final value: the long soak
(``long_soak.py``) keeps its managed node processes for the whole run and
hands them to the :class:`Sampler`; :func:`fit_slopes` turns the samples into
lines of the report and, for a run long enough, checks.
"""

import itertools
import json
import os
import statistics
import threading
import time

from harness.campaign import read_json
from harness.campaign_result import Check
from harness.soak_plan import LongSoakConfig


def slope_per_hour(samples: list[tuple[float, float]]) -> float | None:
    """Least-squares slope of (time s, value) samples, in value per hour; None if too few."""
    if len(samples) < 3:
        return None
    ts = [t for t, _ in samples]
    vs = [v for _, v in samples]
    mt, mv = statistics.fmean(ts), statistics.fmean(vs)
    den = sum((t - mt) ** 2 for t in ts)
    if den == 0:
        return None
    return sum((t - mt) * (v - mv) for t, v in zip(ts, vs, strict=True)) / den * 3600.0


def halves_per_hour(samples: list[tuple[float, float]]) -> tuple[float, float] | None:
    """Slopes per hour of the first and the second half of the samples (by time); None if few."""
    if len(samples) < 6:
        return None
    middle = (samples[0][0] + samples[-1][0]) / 2.0
    first = slope_per_hour([s for s in samples if s[0] <= middle])
    second = slope_per_hour([s for s in samples if s[0] >= middle])
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


def anon_by_mapping(pid: int) -> dict[str, tuple[int, str, int]] | None:
    """
    Return a process's mappings as {start address: (size KiB, name, anonymous KiB)}.

    Anonymous RSS that keeps rising after a warm-up is either a region
    added (a new arena, a buffer mapped alone) or pages touched for the first
    time inside regions that exist: the mappings, read from
    ``/proc/<pid>/smaps``, tell which (a glibc thread heap keeps its start as
    it grows into its reserve). None if the process is gone.
    """
    found: dict[str, tuple[int, str, int]] = {}
    start = ''
    try:
        with open(f'/proc/{pid}/smaps') as handle:
            for line in handle:
                head = line.split(maxsplit=5)
                if '-' in head[0] and not head[0].endswith(':'):
                    begin, _, end = head[0].partition('-')
                    start = begin
                    name = head[5].strip() if len(head) > 5 else ''
                    found[start] = ((int(end, 16) - int(begin, 16)) // 1024, name, 0)
                elif head[0] == 'Anonymous:':
                    size, name, _ = found[start]
                    found[start] = (size, name, int(head[1]))
    except OSError:
        return None
    return found


def append_mappings(path: str, pid: int, seconds: float, faults: int) -> None:
    """Append a process's mappings (:func:`anon_by_mapping`) to ``path`` as one JSON line."""
    with open(path, 'a') as out:
        out.write(json.dumps({'seconds': round(seconds, 1), 'faults': faults,
                              'maps': anon_by_mapping(pid)}) + '\n')


#: A mapping absent from a row: no size, no name, nothing resident.
_ABSENT = (0, '', 0)


def _anon(row: dict, start: str) -> int:
    """Return the anonymous KiB of the mapping at ``start`` in a --mappings row (0: none)."""
    return row['maps'].get(start, _ABSENT)[2]


def mapping_changes(path: str, from_faults: int = 0) -> list[str]:
    """
    Say which mappings of an :func:`append_mappings` file gained anonymous memory.

    From the first row at ``from_faults`` faults or more to the last: each
    mapping whose anonymous KiB changed, by how much, its size and name, and
    the faults met when it last changed, so that a region that stopped
    growing is told from one that still grows.
    """
    with open(path) as source:
        rows = [json.loads(line) for line in source if line.strip()]
    rows = [r for r in rows if r['maps']]
    base = next((i for i, r in enumerate(rows) if r['faults'] >= from_faults), len(rows) - 1)
    first, last = rows[base]['maps'], rows[-1]['maps']
    lines = [f'{len(rows)} rows; mappings from {rows[base]["faults"]} faults '
             f'({rows[base]["seconds"] / 60:.1f} min) to {rows[-1]["faults"]} '
             f'({rows[-1]["seconds"] / 60:.1f} min):']
    for start in sorted(set(first) | set(last)):
        before, after = first.get(start, _ABSENT), last.get(start, _ABSENT)
        if before[2] == after[2]:
            continue  # a heap's reserve moves as the heap grows into it: never touched
        changed = rows[base]['faults']
        for earlier, later in itertools.pairwise(rows[base:]):
            if _anon(earlier, start) != _anon(later, start):
                changed = later['faults']
        lines.append(f'  {after[2] - before[2]:+6d} KiB  {start}  {before[0]}->{after[0]} KiB '
                     f'{after[1] or before[1] or "[anonymous]"}  ({before[2]} -> {after[2]}; '
                     f'last changed at {changed} faults)')
    total = [sum(v[2] for v in maps.values()) for maps in (first, last)]
    lines.append(f'  anonymous in all mappings: {total[0]} -> {total[1]} KiB')
    return lines


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
        #: Every sample, whatever the state (a leg's own RSS check).
        self.all_samples: dict[str, list[tuple[float, int, int, int]]] = {}
        self.first_release: dict[str, float] = {}
        self._pids: dict[str, int] = {}
        #: Heap figures the node wrote (instrumented_node.heap_figures), sampled as
        #: ``samples`` are: (time, Python blocks, C heap in use KiB).
        self.heaps: dict[str, list[tuple[float, int, int | None]]] = {}
        #: RSS by kind (:func:`rss_kinds`), sampled as ``samples`` are: (time, anon, file, shmem).
        self.kinds: dict[str, list[tuple[float, int, int, int]]] = {}
        self._stats: dict[str, str] = {}
        self._lock = threading.Lock()
        self._halt = threading.Event()

    def watch(self, name: str, pid: int, stats_path: str | None = None) -> None:
        """Start sampling process ``pid`` as ``name`` (its heap from ``stats_path``)."""
        with self._lock:
            self._pids[name] = pid
            if stats_path is not None:
                self._stats[name] = stats_path
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
                    self._sample_heap(name)

    def _sample_heap(self, name: str) -> None:
        path = self._stats.get(name)
        heap = (read_json(path) or {}).get('heap') if path is not None else None
        if heap:
            self.heaps.setdefault(name, []).append(
                (time.time(), heap['python_blocks'], heap['malloc_in_use_kib']))

    def stop(self) -> None:
        """Stop sampling."""
        self._halt.set()
        self.join(5.0)


def fit_slopes(cfg: LongSoakConfig, sampler: Sampler, processes: list[tuple[str, str]],
               minutes: float) -> tuple[list[Check], list[str]]:
    """
    Fit RSS, descriptors and threads against time for each long-lived process.

    ``processes`` are (name in the report, name in the sampler) pairs.
    """
    checks, lines = [], []
    asserted = minutes >= cfg.slope_min_minutes
    lines.append(f'slopes per hour, while unconfigured, after the first {cfg.slope_after:g} s '
                 f'and the first leg of each managed process '
                 f'({"asserted" if asserted else "not asserted"}: run of '
                 f'{minutes:.1f} min, asserted from {cfg.slope_min_minutes:g} min):')
    for name, key in processes:
        born = sampler.born.get(key, 0.0)
        # After the first 5 minutes and after the process's first leg (its first
        # activation loads what it keeps: a warm-up, not a leak).
        since = max(born + cfg.slope_after, sampler.first_release.get(key, born))
        samples = [s for s in sampler.samples.get(key, []) if s[0] >= since]
        rss = slope_per_hour([(t, kib / 1024.0) for t, kib, _, _ in samples])
        fds = slope_per_hour([(t, n) for t, _, n, _ in samples])
        threads = slope_per_hour([(t, n) for t, _, _, n in samples])
        first = samples[0][1:] if samples else None
        last = samples[-1][1:] if samples else None
        heaps = [h for h in sampler.heaps.get(key, []) if h[0] >= since]
        blocks = slope_per_hour([(t, n) for t, n, _ in heaps])
        native = slope_per_hour([(t, kib / 1024.0) for t, _, kib in heaps if kib is not None])
        lines.append(f'  {name:22s} RSS {_per_hour(rss, "MiB")}, descriptors '
                     f'{_per_hour(fds, "")}, threads {_per_hour(threads, "")}; '
                     f'{len(samples)} samples; first {first}, last {last} '
                     f'(RSS KiB, fds, threads)')
        halves = halves_per_hour([(t, kib / 1024.0) for t, kib, _, _ in samples])
        if halves is not None:
            # Not asserted: a warm-up slows down (the second half's slope is smaller),
            # a leak keeps its pace.
            lines.append(f'  {"":22s} RSS by halves of the fit: first '
                         f'{_per_hour(halves[0], "MiB")}, second {_per_hour(halves[1], "MiB")}')
        kinds = [k for k in sampler.kinds.get(key, []) if k[0] >= since]
        if kinds:
            # Not asserted: which memory the slope is (a leak is anonymous).
            per_kind = [slope_per_hour([(k[0], k[i] / 1024.0) for k in kinds])
                        for i in (1, 2, 3)]
            lines.append(f'  {"":22s} RSS by kind: anonymous {_per_hour(per_kind[0], "MiB")}, '
                         f'file-backed {_per_hour(per_kind[1], "MiB")}, shared memory '
                         f'{_per_hour(per_kind[2], "MiB")}; first {kinds[0][1:]}, last '
                         f'{kinds[-1][1:]} (KiB)')
        if heaps:
            # Not asserted: what tells a leak (these grow too) from an allocator
            # that keeps freed memory (RSS alone grows).
            lines.append(f'  {"":22s} heap in use: Python objects '
                         f'{_per_hour(blocks, "blocks")}, C heap {_per_hour(native, "MiB")}; '
                         f'first {heaps[0][1:]}, last {heaps[-1][1:]} (blocks, KiB)')
        if asserted:
            ok = (rss is not None and rss < cfg.rss_slope_limit
                  and fds is not None and abs(fds) <= cfg.count_slope_limit
                  and threads is not None and abs(threads) <= cfg.count_slope_limit)
            checks.append(Check(
                f'managed {name}: no leak', ok,
                f'RSS {_per_hour(rss, "MiB")} (limit {cfg.rss_slope_limit:g}), descriptors '
                f'{_per_hour(fds, "")}, threads {_per_hour(threads, "")} (limit '
                f'\u00b1{cfg.count_slope_limit:g})'))
    return checks, lines


def _per_hour(value: float | None, unit: str) -> str:
    return 'n/a' if value is None else f'{value:+.3f} {unit}/h'
