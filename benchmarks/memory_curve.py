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
Issue #18: a node's memory against the faults it has met, to see whether it levels off.

The long soak's managed processes meet about 180 faults an hour and grow
by 1-2 MiB/h of anonymous memory; whether that is a warm-up (it levels
off) or a leak (it keeps its pace) needs many more faults than that. Here
one driver node (its own process, the instrumented one, which writes its
heaps in use; ``--managed``: the managed node, configured and activated,
and taken through deactivate / cleanup / configure / activate every
``--cycle-every`` faults, as the soak's legs take it) reads the simulator
(in this process) streaming ``full`` at 100 Hz, and meets faults in turn:
an unplug, a power cycle, a stall long enough for a reconnect, and a burst
of garbage, corrupted and foreign packets. Each fault ends, and the node's
messages come back (received here, by a subscriber) before the next one,
which starts ``--every`` seconds after the last at the soonest. Every
``--row-every`` seconds a row: faults so far, anonymous RSS, the C heap in
use (and its chunks mapped alone), glibc's arenas, CPython's blocks, the
names CPython's type cache alone keeps (bounded at 4,096:
``harness/type_cache.py``), and the blocks right after the node's last full
collection with the cache's names then (garbage in reference cycles waits
for a full collection, which comes seldom: the blocks at any moment rise and
fall by thousands with it); at the end, the slopes of each by thirds of the
run, per hour and per 100 faults, with their standard errors. A warm-up
shows as thirds that fall off to nothing; a leak as thirds alike.

The node keeps no list of port events by default: the soak's rig keeps
its newest 4,096 for its checks, and here, at about one a fault, that list
grows through the first 4,000 faults (two CPython blocks an event: about
half of what the plain node's curve gained in the last third of its 3,000
faults): the rig's memory, not the node's. ``--events`` keeps it, as the
runs before 2026-11-27 did.

``--tracemalloc DIR``: the node traces its allocations and writes
snapshots to ``DIR`` every minute (``harness/instrumented_node.py``), and
``DIR/faults.csv`` says when each row was taken (``time.time()``) and the
faults met by then; ``benchmarks/heap_sites.py DIR`` reads them.

``--mappings FILE``: at every row, the node's mappings too (from
``/proc/PID/smaps``: start, size, name, anonymous KiB), as JSON lines;
``--mappings-diff FILE [--from-faults N]`` says which of them gained
anonymous memory from N faults on, and when each last changed: a region
added, or pages touched for the first time in one that exists.

``--csv`` writes the rows, ``--plot`` draws them (matplotlib, an optional
extra); ``--replot`` draws the CSVs of earlier runs without running.

Prints numbers; passes or fails nothing.
"""

import argparse
import itertools
import json
import math
import os
import signal
import statistics
import sys
import tempfile
import threading
import time
from typing import NamedTuple

import bench_common  # noqa: F401 - puts the repository on the path
from harness.instrumented_node import (
    EVENTS_ENV, HEAP_COLLECT_ENV, HEAP_DETAIL_ENV, STATS_ENV, TRACEMALLOC_ENV,
)
from harness.process_sampler import append_mappings, mapping_changes, rss_kinds
from harness.processes import (
    ADDRESS, isolate_ros_domain, LifecycleClient, Listener, NodeProcess, ros_env,
)
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
from i3dmgx2_driver.tools.figures import agg_figure

#: The faults, in turn.
KINDS = ('unplug', 'power cycle', 'stall', 'noise')
#: Messages received after a fault ended that say the stream is back.
BACK_AFTER = 10
#: How long a stream may take to come back before the run says so (s).
BACK_WITHIN = 20.0
#: The CSV's columns.
COLUMNS = ('seconds', 'faults', 'cycles', 'anon_kib', 'c_heap_kib', 'python_blocks',
           'mmapped_kib', 'type_cache_names', 'arenas', 'full_collections',
           'blocks_after_gc', 'cache_after_gc', 'threads_started')
#: A figure the node did not give (a CSV of an earlier run, or not glibc / CPython 3.11).
UNKNOWN = -1


class Row(NamedTuple):
    """One sample of the node's memory."""

    seconds: float
    faults: int
    cycles: int
    anon_kib: int
    c_heap_kib: int
    python_blocks: int
    #: The part of the C heap in chunks with a mapping of their own (large buffers).
    mmapped_kib: int = UNKNOWN
    #: The blocks CPython's type cache alone keeps (harness/type_cache.py; at most 4,096).
    type_cache_names: int = UNKNOWN
    #: glibc's arenas (at most 8 per core by default).
    arenas: int = UNKNOWN
    #: The node's full collections so far (generation 2; its own, none run by the rig).
    full_collections: int = UNKNOWN
    #: CPython's blocks right after the last of them: no garbage waiting for the collector.
    blocks_after_gc: int = UNKNOWN
    #: The type cache's own names then.
    cache_after_gc: int = UNKNOWN
    #: Python threads the node started so far (its first ones counted as running at import).
    threads_started: int = UNKNOWN

    @property
    def blocks_besides_cache(self) -> int:
        """Return CPython's blocks less those only the type cache keeps (UNKNOWN if not known)."""
        if self.type_cache_names == UNKNOWN:
            return UNKNOWN
        return self.python_blocks - self.type_cache_names

    @property
    def kept_after_gc(self) -> int:
        """Return the blocks after the last full collection, less the type cache's then."""
        if UNKNOWN in (self.blocks_after_gc, self.cache_after_gc):
            return UNKNOWN
        return self.blocks_after_gc - self.cache_after_gc


def inflict(sim: PtySimulator, kind: str) -> None:
    """Inflict one fault and return once it has ended."""
    if kind == 'unplug':
        sim.unplug(None)
        time.sleep(0.5)
        sim.replug()
    elif kind == 'power cycle':
        sim.power_cycle(0.3)
    elif kind == 'stall':
        sim.stall(1.5)
        time.sleep(1.5)
    else:  # noise
        sim.set_faults(garbage_probability=0.1, corrupt_checksum_probability=0.05,
                       foreign_probability=0.05)
        time.sleep(1.0)
        sim.set_faults(FaultConfig())


def _heap(path: str) -> dict:
    """Return the heap figures the node last wrote (harness/instrumented_node.HeapFigures)."""
    for _ in range(20):
        try:
            with open(path) as handle:
                return json.load(handle)['heap']
        except (OSError, ValueError, KeyError):
            time.sleep(0.1)
    raise RuntimeError(f'the node wrote no heap figures to {path}')


class Messages:
    """Counts the node's Imu messages, received by a subscriber in this process."""

    def __init__(self, listener: Listener, topic: str = 'imu/raw_data') -> None:
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import Imu

        self.count = 0
        self._changed = threading.Condition()
        listener.node.create_subscription(Imu, topic, self._on_message, qos_profile_sensor_data)

    def _on_message(self, _msg: object) -> None:
        with self._changed:
            self.count += 1
            self._changed.notify_all()

    def wait_past(self, count: int, timeout: float = BACK_WITHIN) -> bool:
        """Wait for ``BACK_AFTER`` messages after the ``count``-th; tell whether they came."""
        with self._changed:
            return self._changed.wait_for(lambda: self.count >= count + BACK_AFTER, timeout)


def _node_env(plan: 'Run', path: str) -> dict[str, str]:
    """Return what the node's environment adds: where its figures go, and the options."""
    env = {STATS_ENV: path, HEAP_DETAIL_ENV: '1'}
    if plan.arena_max:
        env['MALLOC_ARENA_MAX'] = str(plan.arena_max)
    if not plan.events:
        env[EVENTS_ENV] = '0'
    if plan.tracemalloc:
        env[TRACEMALLOC_ENV] = plan.tracemalloc
    if plan.collect_every:
        env[HEAP_COLLECT_ENV] = str(plan.collect_every)
    return env


class Run(NamedTuple):
    """What a run is asked to do."""

    minutes: float
    faults: int | None
    every: float
    warm_up: float
    managed: bool
    cycle_every: int
    row_every: float
    #: glibc's ``MALLOC_ARENA_MAX`` for the node (None: glibc's default, 8 per core).
    arena_max: int | None = None
    #: Whether the node keeps the rig's list of port events (the soak's checks read it;
    #: nothing here does, and it grows through the first 4,000 faults).
    events: bool = False
    #: Whether the node keeps its fault capture ring and writes its files (the default).
    fault_capture: bool = True
    #: A directory for the node's tracemalloc snapshots (None: not traced).
    tracemalloc: str | None = None
    #: Seconds between full collections the node is asked to run (0: only its own).
    collect_every: float = 0.0
    #: Whether the node publishes its log on /rosout (the default; False:
    #: ``--disable-rosout-logs``, to tell that publisher's memory from the rest).
    rosout: bool = True
    #: A file for the node's mappings at every row, as JSON lines (None: not read).
    mappings: str | None = None


def run(plan: Run) -> list[Row]:
    """Stream ``warm_up`` s, then fault after fault until the end; return the rows."""
    isolate_ros_domain()
    kinds = itertools.cycle(KINDS)
    rows: list[Row] = []
    command = (sys.executable, '-m', 'harness.instrumented_node') + (
        ('--lifecycle',) if plan.managed else ())
    with tempfile.TemporaryDirectory(prefix='i3dmgx2-memory-') as workdir, \
            PtySimulator(SimulatorConfig(address=ADDRESS, seed=3, rate_hz=100)) as sim, \
            Listener({}) as listener:
        # rclpy.init took SIGINT for its contexts: Ctrl-C stops the run again.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        path = os.path.join(workdir, 'stats.json')
        if plan.tracemalloc:
            os.makedirs(plan.tracemalloc, exist_ok=True)
        messages = Messages(listener)
        parameters = {'port': sim.port, 'address': ADDRESS}
        if not plan.fault_capture:
            parameters['fault_capture_dir'] = "''"
        node = NodeProcess(parameters, () if plan.rosout else ('--disable-rosout-logs',),
                           command=command, env=ros_env(_node_env(plan, path)))
        client = LifecycleClient(listener) if plan.managed else None
        try:
            if client is not None and not (client.wait_ready(60.0) and client.change('configure')
                                           and client.change('activate')):
                raise RuntimeError('the managed node did not activate: ' + node.output()[-2000:])
            if not messages.wait_past(0, timeout=60.0):
                raise RuntimeError('the node did not stream: ' + node.output()[-2000:])
            time.sleep(plan.warm_up)
            print(f'{"min":>5} {"faults":>6} {"cycles":>6} {"anon KiB":>9} {"C heap KiB":>10} '
                  f'{"mmapped":>7} {"arenas":>6} {"blocks":>7} {"cache":>5} {"GCs":>4} '
                  f'{"after GC":>7} {"cache":>5} {"threads":>7}', flush=True)
            start = time.monotonic()
            faults = cycles = late = 0
            next_row = start
            while True:
                now = time.monotonic()
                done = (plan.faults is not None and faults >= plan.faults) \
                    or now - start >= plan.minutes * 60.0
                if now >= next_row or done:
                    heap = _heap(path)
                    anon = (rss_kinds(node.proc.pid) or (0, 0, 0))[0]
                    after = heap.get('after_full_gc') or {}
                    row = Row(now - start, faults, cycles, anon, heap['malloc_in_use_kib'] or 0,
                              heap['python_blocks'], *(
                                  UNKNOWN if value is None else value for value in (
                                      heap.get('malloc_mmapped_kib'),
                                      heap.get('type_cache_names'), heap.get('malloc_arenas'),
                                      after.get('full_collections'), after.get('blocks'),
                                      after.get('type_cache'), heap.get('threads_started'))))
                    rows.append(row)
                    print(f'{(now - start) / 60:5.1f} {faults:6d} {cycles:6d} {anon:9d} '
                          f'{row.c_heap_kib:10d} {row.mmapped_kib:7d} {row.arenas:6d} '
                          f'{row.python_blocks:7d} {row.type_cache_names:5d} '
                          f'{row.full_collections:4d} {row.blocks_after_gc:7d} '
                          f'{row.cache_after_gc:5d} {row.threads_started:7d}', flush=True)
                    if plan.mappings:
                        append_mappings(plan.mappings, node.proc.pid, row.seconds, faults)
                    if plan.tracemalloc:
                        with open(os.path.join(plan.tracemalloc, 'faults.csv'), 'a') as out:
                            out.write(f'{time.time():.3f},{faults}\n')
                    next_row += plan.row_every
                    if done:
                        break
                began = time.monotonic()
                if client is not None and plan.cycle_every and faults \
                        and faults // plan.cycle_every > cycles:
                    cycles += 1
                    mark = messages.count
                    if not all(client.change(step) for step in (
                            'deactivate', 'cleanup', 'configure', 'activate')):
                        raise RuntimeError(f'lifecycle cycle {cycles} failed: '
                                           + node.output()[-2000:])
                    messages.wait_past(mark)
                kind = next(kinds)
                inflict(sim, kind)
                faults += 1
                if not messages.wait_past(messages.count):
                    late += 1
                    print(f'fault {faults} ({kind}): the stream was not back within '
                          f'{BACK_WITHIN:g} s', flush=True)
                time.sleep(max(0.0, plan.every - (time.monotonic() - began)))
        finally:
            node.stop()
            node.close()
    print(f'{faults} faults, {cycles} lifecycle cycles in {rows[-1].seconds / 60:.1f} min; '
          f'{late} returns slower than {BACK_WITHIN:g} s')
    return rows


def fit(points: list[tuple[float, float]]) -> tuple[float, float] | None:
    """Least-squares slope of (x, y) points and its standard error; None if too few."""
    if len(points) < 4:
        return None
    xs, ys = [x for x, _ in points], [y for _, y in points]
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    if sxx == 0:
        return None
    slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sxx
    residual = sum((y - my - slope * (x - mx)) ** 2 for x, y in zip(xs, ys, strict=True))
    return slope, math.sqrt(residual / (len(xs) - 2) / sxx)


def thirds(rows: list[Row]) -> list[list[Row]]:
    """Split the rows into thirds of the run's time (a row on a boundary in both)."""
    third = rows[-1].seconds / 3.0
    return [[r for r in rows if k * third <= r.seconds <= (k + 1) * third] for k in range(3)]


def slopes(rows: list[Row]) -> list[str]:
    """Return the lines that give each figure's slope by thirds: per hour and per 100 faults."""
    lines = ['slopes by thirds of the run (per hour | per 100 faults, \u00b1 standard error):']
    parts = thirds(rows)
    spans = [f'{p[0].faults}-{p[-1].faults}' if p else '-' for p in parts]
    lines.append('  faults met      ' + ';  '.join(spans))
    for field, name, scale, unit in (('anon_kib', 'anonymous RSS', 1 / 1024, ' MiB'),
                                     ('c_heap_kib', 'C heap', 1 / 1024, ' MiB'),
                                     ('mmapped_kib', ' mapped alone', 1 / 1024, ' MiB'),
                                     ('python_blocks', 'CPython blocks', 1.0, ''),
                                     ('type_cache_names', ' type cache', 1.0, ''),
                                     ('blocks_besides_cache', ' the rest', 1.0, ''),
                                     ('blocks_after_gc', 'after full GC', 1.0, ''),
                                     ('kept_after_gc', ' less the cache', 1.0, '')):
        if all(getattr(r, field) == UNKNOWN for r in rows):
            continue  # an earlier run's CSV, or a figure the node could not give
        said = []
        for part in parts:
            known = [r for r in part if getattr(r, field) != UNKNOWN]  # none before a full GC
            hourly = fit([(r.seconds / 3600, getattr(r, field) * scale) for r in known])
            per_fault = fit([(r.faults / 100, getattr(r, field) * scale) for r in known])
            said.append('n/a' if hourly is None or per_fault is None else
                        f'{hourly[0]:+.3f}\u00b1{hourly[1]:.3f}{unit} | '
                        f'{per_fault[0]:+.3f}\u00b1{per_fault[1]:.3f}{unit}')
        lines.append(f'  {name:15s} ' + ';  '.join(said))
    if all(r.arenas != UNKNOWN for r in rows):
        lines.append(f'glibc arenas: {rows[0].arenas} at first, {max(r.arenas for r in rows)} '
                     f'at most, {rows[-1].arenas} last')
    if all(r.full_collections != UNKNOWN for r in rows):
        lines.append(f"the node's full collections: {rows[-1].full_collections}")
    if all(r.threads_started != UNKNOWN for r in rows):
        parts = [p for p in thirds(rows) if p]
        lines.append('threads the node started: ' + ', '.join(
            f'{p[-1].threads_started - p[0].threads_started} over faults '
            f'{p[0].faults}-{p[-1].faults}' for p in parts)
            + f' ({rows[-1].threads_started} in all)')
    anon = [r.anon_kib / 1024 for r in rows]
    lines.append(f'anonymous RSS: first {anon[0]:.2f} MiB, highest {max(anon):.2f} MiB '
                 f'(after {rows[anon.index(max(anon))].faults} faults), last {anon[-1]:.2f} MiB')
    return lines


def write_csv(path: str, rows: list[Row], label: str) -> None:
    """Write the rows, the run's label as a comment line first."""
    with open(path, 'w') as out:
        out.write(f'# {label}\n{",".join(COLUMNS)}\n')
        for row in rows:
            out.write(f'{row.seconds:.1f},' + ','.join(str(v) for v in row[1:]) + '\n')


def read_csv(path: str) -> tuple[str, list[Row]]:
    """Read what :func:`write_csv` wrote: (label, rows)."""
    label, rows, columns = os.path.basename(path), [], COLUMNS
    with open(path) as source:
        for line in source:
            if line.startswith('#'):
                label = line[1:].strip()
            elif line.startswith(COLUMNS[0]):
                columns = tuple(line.strip().split(','))  # an earlier run's CSV has fewer
            elif line.strip():
                seconds, *counts = line.strip().split(',')
                rows.append(Row(float(seconds), **dict(zip(
                    columns[1:], (int(c) for c in counts), strict=True))))
    return label, rows


def plot(runs: list[tuple[str, list[Row]]], output: str) -> None:
    """
    Draw the node's memory against faults met, one line per run.

    Anonymous RSS, the C heap in use, and CPython's blocks: all of them, and
    (dashed, for runs that counted them) those alive right after the node's
    last full collection less the type cache's names then: neither garbage
    waiting for the collector nor the bounded cache hides whether the rest
    is flat. Only where the node collected more than once: a run with its
    start-up collection alone would draw a level line that says nothing.
    """
    fig = agg_figure(figsize=(8, 7), dpi=90)
    top = fig.add_subplot(3, 1, 1)
    middle = fig.add_subplot(3, 1, 2, sharex=top)
    bottom = fig.add_subplot(3, 1, 3, sharex=top)
    for label, rows in runs:
        faults = [r.faults for r in rows]
        line, = top.plot(faults, [r.anon_kib / 1024 for r in rows], '.-', markersize=3,
                         label=label)
        colour = line.get_color()
        middle.plot(faults, [r.c_heap_kib / 1024 for r in rows], '.-', markersize=3,
                    color=colour)
        bottom.plot(faults, [r.python_blocks / 1000 for r in rows], '.-', markersize=3,
                    color=colour)
        kept = [r for r in rows if r.kept_after_gc != UNKNOWN]
        if len({r.full_collections for r in kept}) > 1:
            bottom.plot([r.faults for r in kept], [r.kept_after_gc / 1000 for r in kept], '--',
                        color=colour, label=f'{label}: after a full collection, less the '
                                            'type cache')
        last = thirds(rows)[2]
        if last:
            top.axvspan(last[0].faults, last[-1].faults, color=colour, alpha=0.08)
    top.set_ylabel('anonymous RSS (MiB)')
    middle.set_ylabel('C heap in use (MiB)')
    bottom.set_ylabel('CPython blocks (1000s)')
    bottom.set_xlabel('faults met (after 2 min of streaming; shaded: the last third)')
    for axes in (top, middle, bottom):
        axes.grid(True, alpha=0.3)
    top.legend(loc='lower right', fontsize='small')
    if bottom.get_legend_handles_labels()[0]:
        bottom.legend(loc='lower right', fontsize='small')
    fig.suptitle("A driver node's memory against the faults it has met", fontsize='medium')
    fig.tight_layout()
    fig.savefig(output)


def main() -> None:
    """Run from the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=45.0,
                        help='minutes of faults at most')
    parser.add_argument('--faults', type=int, default=None,
                        help='stop after this many faults (default: when the minutes end)')
    parser.add_argument('--every', type=float, default=3.0,
                        help='seconds from one fault to the next at the soonest (each waits '
                             'for the stream to come back)')
    parser.add_argument('--warm-up', type=float, default=120.0,
                        help="seconds of streaming before the first row (the start-up's own)")
    parser.add_argument('--managed', action='store_true',
                        help='run the managed node (configured and activated) instead')
    parser.add_argument('--cycle-every', type=int, default=45,
                        help='managed: deactivate, clean up, configure and activate it every '
                             'this many faults (0: never; the soak: about 45 a leg)')
    parser.add_argument('--row-every', type=float, default=60.0, help='seconds between rows')
    parser.add_argument('--arena-max', type=int, default=None,
                        help="the node's MALLOC_ARENA_MAX (glibc's default: 8 per core)")
    parser.add_argument('--events', action='store_true',
                        help="the node keeps the soak's list of port events (read by its "
                             'checks, not here; about one a fault, 4,096 at most), as the '
                             'runs before 2026-11-27 did')
    parser.add_argument('--no-events', action='store_true',
                        help='the node keeps no list of port events: the default')
    parser.add_argument('--no-fault-capture', action='store_true',
                        help='the node keeps no fault capture ring and writes no capture '
                             "(fault_capture_dir ''): its memory without that feature")
    parser.add_argument('--no-rosout', action='store_true',
                        help='the node does not publish its log on /rosout '
                             '(--disable-rosout-logs): its memory without that publisher, '
                             'whose history keeps each buffer at the largest it held')
    parser.add_argument('--tracemalloc', metavar='DIR',
                        help="trace the node's allocations: snapshots and faults.csv in DIR "
                             '(benchmarks/heap_sites.py reads them)')
    parser.add_argument('--collect-every', type=float, default=0.0, metavar='S',
                        help='the node runs a full collection every S seconds, so that the '
                             'level right after one, what it keeps alive, is taken often '
                             '(default: only its own collections, which come seldom)')
    parser.add_argument('--mappings', metavar='PATH',
                        help="append the node's mappings at every row (/proc/PID/smaps: start, "
                             'size, name, anonymous KiB) here, as JSON lines')
    parser.add_argument('--mappings-diff', metavar='PATH',
                        help='say which mappings of a --mappings file gained anonymous memory, '
                             'without running')
    parser.add_argument('--from-faults', type=int, default=0, metavar='N',
                        help='with --mappings-diff: from the first row at N faults or more')
    parser.add_argument('--csv', metavar='PATH', help='write the rows here')
    parser.add_argument('--plot', metavar='PNG', help='draw the rows here')
    parser.add_argument('--replot', metavar='CSV', nargs='+',
                        help='draw these CSVs to --plot, without running')
    args = parser.parse_args()
    if args.mappings_diff:
        print('\n'.join(mapping_changes(args.mappings_diff, args.from_faults)))
        return
    if args.replot:
        runs = [read_csv(path) for path in args.replot]
        for label, rows in runs:
            print(label)
            print('\n'.join(slopes(rows)))
        if args.plot:
            plot(runs, args.plot)
        return
    rows = run(Run(args.minutes, args.faults, args.every, args.warm_up, args.managed,
                   args.cycle_every if args.managed else 0, args.row_every, args.arena_max,
                   args.events and not args.no_events, not args.no_fault_capture,
                   os.path.abspath(args.tracemalloc) if args.tracemalloc else None,
                   args.collect_every, not args.no_rosout,
                   os.path.abspath(args.mappings) if args.mappings else None))
    print('\n'.join(slopes(rows)))
    label = (f'managed node, a lifecycle cycle every {args.cycle_every} faults'
             if args.managed else 'plain node') + (
                 f', MALLOC_ARENA_MAX={args.arena_max}' if args.arena_max else '') + (
                 ', port events kept' if args.events and not args.no_events else '') + (
                 f', a full collection every {args.collect_every:g} s'
                 if args.collect_every else '') + (
                 ', no fault capture' if args.no_fault_capture else '') + (
                 ', no /rosout' if args.no_rosout else '')
    if args.csv:
        write_csv(args.csv, rows, label)
    if args.plot:
        plot([(label, rows)], args.plot)


if __name__ == '__main__':
    main()
