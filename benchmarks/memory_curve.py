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
Issue #18: a node's memory, descriptors and threads against the faults it has met.

The long soak's managed processes meet about 180 faults an hour; whether
their memory levels off (a warm-up) or keeps its pace (a leak) needs many
more faults than that. Here one driver node (its own process, the
instrumented one of ``harness/instrumented_node.py``; ``--managed``: the
managed node, configured and activated, and taken through deactivate /
cleanup / configure / activate every 45 faults, about as often as the soak's
legs take it) reads the simulator (in this process) streaming ``full`` at
100 Hz, and meets faults in turn: an unplug, a power cycle, a stall long
enough for a reconnect, and a burst of garbage, corrupted and foreign
packets. Each fault ends, and the node's messages come back (received here,
by a subscriber) before the next one, which starts ``--every`` seconds after
the last at the soonest.

After two minutes of streaming (the start-up's own growth), every minute a
row: faults so far, and the node's anonymous RSS (its heaps: what a leak
grows; the file-backed rest is the libraries paged in, bounded by their
size), open descriptors and threads
(read from ``/proc``: ``harness/process_sampler.py``); at the end, the slope
of each by thirds of the run, per hour and per 100 faults, with its
standard error. A warm-up shows as thirds that fall off to nothing; a leak
as thirds alike. The node keeps no list of port events (the
soak's checks read it; here it would be the rig's memory, not the node's).

``--csv`` writes the rows, ``--plot`` draws them (matplotlib, an optional
extra); ``--replot`` draws the CSVs of earlier runs without running.

Prints numbers; passes or fails nothing.
"""

import argparse
import itertools
import os
import signal
import sys
import tempfile
import threading
import time
from typing import NamedTuple

import bench_common  # noqa: F401 - puts the repository on the path
from harness.instrumented_node import EVENTS_ENV, STATS_ENV
from harness.process_sampler import by_time, fit, process_sample, rss_kinds
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
#: Seconds of streaming before the first row (the start-up's own), and between rows.
WARM_UP_S = 120.0
ROW_EVERY_S = 60.0
#: The managed node's lifecycle cycle, every this many faults.
CYCLE_EVERY = 45


class Row(NamedTuple):
    """One sample of the node, ``seconds`` after the warm-up."""

    seconds: float
    faults: int
    cycles: int
    anon_kib: int
    descriptors: int
    threads: int


#: The figures a row samples: (field, name, scale, unit) as the slopes and the plot say them.
FIGURES = (('anon_kib', 'anonymous RSS', 1 / 1024, 'MiB'),
           ('descriptors', 'descriptors', 1.0, ''),
           ('threads', 'threads', 1.0, ''))


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


class Messages(Listener):
    """Counts the node's Imu messages, received (best effort, as sensor data) in this process."""

    def __init__(self) -> None:
        from sensor_msgs.msg import Imu

        self.count = 0
        self._changed = threading.Condition()
        super().__init__({'imu/raw_data': Imu}, reliable=False, depth=5)

    def _store(self, topic: str, msg: object) -> None:
        with self._changed:
            self.count += 1
            self._changed.notify_all()

    def wait_past(self, count: int, timeout: float = BACK_WITHIN) -> bool:
        """Wait for ``BACK_AFTER`` messages after the ``count``-th; tell whether they came."""
        with self._changed:
            return self._changed.wait_for(lambda: self.count >= count + BACK_AFTER, timeout)


def run(minutes: float, most: int | None, every: float, managed: bool) -> list[Row]:
    """Stream ``WARM_UP_S``, then fault after fault (``most`` at most) until the end."""
    isolate_ros_domain()
    kinds = itertools.cycle(KINDS)
    rows: list[Row] = []
    command = (sys.executable, '-m', 'harness.instrumented_node') + (
        ('--lifecycle',) if managed else ())
    with tempfile.TemporaryDirectory(prefix='i3dmgx2-memory-') as workdir, \
            PtySimulator(SimulatorConfig(address=ADDRESS, seed=3, rate_hz=100)) as sim, \
            Messages() as messages:
        # rclpy.init took SIGINT for its contexts: Ctrl-C stops the run again.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        env = ros_env({STATS_ENV: os.path.join(workdir, 'stats.json'), EVENTS_ENV: '0'})
        node = NodeProcess({'port': sim.port, 'address': ADDRESS}, command=command, env=env)
        client = LifecycleClient(messages) if managed else None
        try:
            if client is not None and not (client.wait_ready(60.0) and client.change('configure')
                                           and client.change('activate')):
                raise RuntimeError('the managed node did not activate: ' + node.output()[-2000:])
            if not messages.wait_past(0, timeout=60.0):
                raise RuntimeError('the node did not stream: ' + node.output()[-2000:])
            time.sleep(WARM_UP_S)
            print(f'{"min":>5} {"faults":>6} {"cycles":>6} {"anon KiB":>8} {"fds":>4} '
                  f'{"threads":>7}', flush=True)
            start = time.monotonic()
            faults = cycles = late = 0
            next_row = start
            while True:
                now = time.monotonic()
                done = (most is not None and faults >= most) or now - start >= minutes * 60.0
                if now >= next_row or done:
                    sample, memory = process_sample(node.proc.pid), rss_kinds(node.proc.pid)
                    if sample is None or memory is None:
                        raise RuntimeError('the node exited: ' + node.output()[-2000:])
                    row = Row(now - start, faults, cycles, memory[0], *sample[1:])
                    rows.append(row)
                    print(f'{row.seconds / 60:5.1f} {faults:6d} {cycles:6d} {row.anon_kib:8d} '
                          f'{row.descriptors:4d} {row.threads:7d}', flush=True)
                    next_row += ROW_EVERY_S
                    if done:
                        break
                began = time.monotonic()
                if client is not None and faults and faults // CYCLE_EVERY > cycles:
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
                time.sleep(max(0.0, every - (time.monotonic() - began)))
        finally:
            node.stop()
            node.close()
    print(f'{faults} faults, {cycles} lifecycle cycles in {rows[-1].seconds / 60:.1f} min; '
          f'{late} returns slower than {BACK_WITHIN:g} s')
    return rows


def slopes(rows: list[Row]) -> list[str]:
    """Return the lines that give each figure's slope by thirds: per hour and per 100 faults."""
    lines = ['slopes by thirds of the run (per hour | per 100 faults, \u00b1 standard error):']
    parts = by_time(rows, 3)
    spans = [f'{p[0].faults}-{p[-1].faults}' if p else '-' for p in parts]
    lines.append(f'  {"faults met":14s} ' + ';  '.join(spans))
    for field, name, scale, unit in FIGURES:
        said = []
        for part in parts:
            hourly = fit([(r.seconds / 3600, getattr(r, field) * scale) for r in part])
            per_fault = fit([(r.faults / 100, getattr(r, field) * scale) for r in part])
            said.append('n/a' if hourly is None or per_fault is None else
                        f'{hourly[0]:+.3f}\u00b1{hourly[1]:.3f}{unit} | '
                        f'{per_fault[0]:+.3f}\u00b1{per_fault[1]:.3f}{unit}')
        lines.append(f'  {name:14s} ' + ';  '.join(said))
    for field, name, scale, unit in FIGURES:
        values = [getattr(r, field) * scale for r in rows]
        highest = max(values)
        digits = 2 if unit else 0
        lines.append(f'{name}: first {values[0]:.{digits}f}, highest {highest:.{digits}f} '
                     f'(after {rows[values.index(highest)].faults} faults), last '
                     f'{values[-1]:.{digits}f} {unit}'.rstrip())
    return lines


def write_csv(path: str, rows: list[Row], label: str) -> None:
    """Write the rows, the run's label as a comment line first."""
    with open(path, 'w') as out:
        out.write(f'# {label}\n{",".join(Row._fields)}\n')
        for row in rows:
            out.write(f'{row.seconds:.1f},' + ','.join(str(v) for v in row[1:]) + '\n')


def read_csv(path: str) -> tuple[str, list[Row]]:
    """Read what :func:`write_csv` wrote: (label, rows)."""
    with open(path) as source:
        lines = [line.strip() for line in source if line.strip()]
    label = lines[0][1:].strip() if lines[0].startswith('#') else os.path.basename(path)
    return label, [Row(float(seconds), *map(int, counts)) for seconds, *counts in
                   (line.split(',') for line in lines if line[0].isdigit())]


def plot(runs: list[tuple[str, list[Row]]], output: str) -> None:
    """Draw the node's memory, descriptors and threads against the faults met, a line per run."""
    fig = agg_figure(figsize=(8, 7), dpi=90)
    panels = fig.subplots(len(FIGURES), 1, sharex=True)
    for label, rows in runs:
        faults = [r.faults for r in rows]
        colour = None
        for axes, (field, _, scale, _) in zip(panels, FIGURES, strict=True):
            line, = axes.plot(faults, [getattr(r, field) * scale for r in rows], '.-',
                              markersize=3, color=colour, label=label)
            colour = line.get_color()
        last = by_time(rows, 3)[2]
        if last:
            panels[0].axvspan(last[0].faults, last[-1].faults, color=colour, alpha=0.08)
    for axes, (_, name, _, unit) in zip(panels, FIGURES, strict=True):
        axes.set_ylabel(f'{name} ({unit})' if unit else name)
        axes.grid(True, alpha=0.3)
    panels[-1].set_xlabel('faults met (after the warm-up; shaded: the last third)')
    panels[0].legend(loc='lower right', fontsize='small')
    fig.suptitle("A driver node's memory, descriptors and threads against the faults met",
                 fontsize='medium')
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
    parser.add_argument('--managed', action='store_true',
                        help='run the managed node (configured and activated) instead')
    parser.add_argument('--csv', metavar='PATH', help='write the rows here')
    parser.add_argument('--plot', metavar='PNG', help='draw the rows here')
    parser.add_argument('--replot', metavar='CSV', nargs='+',
                        help='draw these CSVs to --plot, without running')
    args = parser.parse_args()
    if args.replot:
        runs = [read_csv(path) for path in args.replot]
        for label, rows in runs:
            print(label)
            print('\n'.join(slopes(rows)))
        if args.plot:
            plot(runs, args.plot)
        return
    rows = run(args.minutes, args.faults, args.every, args.managed)
    print('\n'.join(slopes(rows)))
    label = (f'managed node, a lifecycle cycle every {CYCLE_EVERY} faults'
             if args.managed else 'plain node')
    if args.csv:
        write_csv(args.csv, rows, label)
    if args.plot:
        plot([(label, rows)], args.plot)


if __name__ == '__main__':
    main()
