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
Latency: where the time from a packet's last byte to a subscriber goes.

Every run starts three processes: the simulated device (``sim_process.py``),
a subscriber (``subscriber.py``) and the real driver process with its
hot-path timings on (``I3DMGX2_TIMINGS``, device/hot_path.py: the package
reports its own stage times, nothing of it is replaced). The figures:

- end to end: the simulator's ``time.time()`` right after it wrote a
  packet's last byte, to right after ``publish()`` returned in the node;
- kernel: that write to the driver's ``read()`` returned (pty wake-up);
- driver (its share): ``read()`` returned to ``publish()`` returned, and
  the time off the CPU; ``stages`` (a configuration) has the parse and the
  stamp marked too, for the time of each stage (parsed, stamped, packed,
  published): two marks more a record than the floor carries, so the
  ratios to the floor are ``default``'s;
- subscriber: the write to the callback of a subscriber in another process;
- the node's CPU (% of one core), its garbage collections in the window.

Configurations are arguments, measured interleaved: every round runs each
once, in an order that changes from round to round, so that the machine's
other load falls on all of them alike; the figures pool every round and
the ratios set side by side come from the same run. ``--line usb`` has the
simulator hand the port each packet as a USB adapter in low-latency mode
does, a piece a millisecond (bench_common.line_pieces); the default, ``pty``,
in one to three pieces at once. ``floor`` is
``floor_node.py``, a process that only reads the port and publishes fixed
bytes: what no rclpy driver goes below on this machine. ``cpu`` is the
driver with its timings off, for its CPU alone (the figure of docs/cpu.md);
``--against DIR`` runs every configuration chosen once more on the driver
of another checkout (``git worktree add /tmp/before <commit>``), interleaved
with this one's: a change's effect on CPU is a few tenths of a percent, less
than a busy machine moves from one window to the next.

Targets (issue #12), about the driver at 100 Hz: its share p99 <= 0.1 ms and
max <= 0.5 ms; end to end p99 <= 1.5 x the kernel's own p99 in the same run.
The original C++ node: 0.99 ms mean, 1.16 ms max.

    python benchmarks/latency.py --configs default,fifo,floor,floor-fifo --rounds 4
    python benchmarks/latency.py --configs default,floor --rate line-max --rounds 2
    python benchmarks/latency.py --configs cpu --against /tmp/before --rounds 4 --seconds 40
    python benchmarks/latency.py --configs default,floor --line usb --rounds 4
"""

import argparse
import gc
import os
from pathlib import Path
import random
import statistics
import sys
import time
from typing import Any, NamedTuple

from bench_common import (
    emit, LINE_MAX_RATE_HZ, line_pieces, machine_table, percentile, RunNote, stamp_key,
    summarise, Summary, TimedNodeProcess,
)
from harness.processes import (
    isolate_ros_domain, process_cpu_seconds, SimProcess, SubscriberProcess, thread_switches,
    wakes_per_second,
)

from i3dmgx2_driver.device.hot_path import ROW_FIELDS
from i3dmgx2_driver.ros.conversions import stamp_parts

#: Seconds of streaming left out at the start (start-up, DDS discovery).
WARM_UP_S = 3.0
#: The driver's share at 100 Hz: p99 and max (s); end to end p99 over the kernel's p99.
TARGET_DRIVER_P99_S = 0.1e-3
TARGET_DRIVER_MAX_S = 0.5e-3
TARGET_KERNEL_RATIO = 1.5
#: The thread that reads the port: it wakes for every sample, and no other thread should.
READER_THREAD = 'gx2-reader'
#: How the DDS library (Fast DDS) names its own threads.
DDS_THREADS = 'dds.'


class Config(NamedTuple):
    """
    One configuration: which process, its parameters, whether anyone subscribes.

    ``timed``: with the hot-path timings (off: only the CPU is measured);
    ``tree``: the driver of another checkout.
    """

    description: str
    script: str = ''
    params: tuple[tuple[str, Any], ...] = ()
    subscribed: bool = True
    timed: bool = True
    tree: Path | None = None
    stages: bool = False


CONFIGS = {
    'default': Config('the driver as shipped'),
    'stages': Config('the driver, its parse and stamp marked too (the stage table)', stages=True),
    'fifo': Config('reader thread SCHED_FIFO 50', params=(('realtime_priority', 50),)),
    'unsubscribed': Config('the driver as shipped, nobody subscribed', subscribed=False),
    'floor': Config('a process that only reads and publishes fixed bytes',
                    script='floor_node.py'),
    'floor-fifo': Config('floor, SCHED_FIFO 50', script='floor_node.py',
                         params=(('realtime_priority', 50),)),
    # qos_depth (deprecated, warned about) rather than qos_overrides: another tree
    # (--against) may predate the standard parameters, and every tree takes this name.
    'cpu': Config('the driver as shipped, its timings off: CPU only',
                  params=(('qos_depth', 1000),), timed=False),
}
_F = {name: i for i, name in enumerate(ROW_FIELDS)}
#: The driver's stages: name, the row's field it starts at and the field it ends at.
STAGES = (('read returned -> parsed (capture hook, parser, checksum, record)', 'read', 'parsed'),
          ('parsed -> stamped (dispatch, lock, timer unwrap, sample clock)', 'parsed', 'stamped'),
          ('stamped -> packed (orientation, CDR bytes)', 'stamped', 'packed'),
          ('packed -> publish() returned (rclpy, DDS)', 'packed', 'published'))
OFF_CPU = ('of read returned -> publish() returned: the reader thread not running '
           '(preempted, waiting for the interpreter lock or a lock)')


class RunResult(NamedTuple):
    """One configuration's run: latencies (s), stages, CPU and collections."""

    end_to_end: list[float]
    kernel: list[float]
    driver: list[float]
    subscriber: list[float]
    stages: dict[str, list[float]]
    cpu_percent: float
    collections: list[tuple]
    reader: dict[str, Any]
    full_collection: float
    wakes: dict[str, float]


def run_once(config: Config, seconds: float, rate_hz: float, line: str = 'pty') -> RunResult:
    """Run one configuration for ``seconds`` after the warm-up; return its figures."""
    floor = bool(config.script)
    sim = SimProcess(rate_hz=rate_hz, streaming_at_start=floor, **line_pieces(line))
    subscriber = SubscriberProcess() if config.subscribed else None
    node = None
    try:
        node = TimedNodeProcess(sim.port, config.script, config.timed, config.tree,
                                stages=config.stages, **dict(config.params))
        time.sleep(WARM_UP_S)
        switches0 = thread_switches(node.pid)
        t0, cpu0 = time.time(), process_cpu_seconds(node.pid)
        time.sleep(seconds)
        t1, cpu1 = time.time(), process_cpu_seconds(node.pid)
        switches1 = thread_switches(node.pid)
        sim.silence()
        time.sleep(0.3)
    finally:
        if node is not None:
            node.stop()
        received = subscriber.stop() if subscriber is not None else []
        sim.stop()
    written = {e.timer: e.write_time for e in sim.written_stream()}  # by the device timer
    published, timer, read = _F['published'], _F['timer'], _F['read']
    rows = [r for r in node.rows if t0 <= r[published] <= t1 and r[timer] in written]
    end_to_end = [r[published] - written[r[timer]] for r in rows]
    kernel = [r[read] - written[r[timer]] for r in rows]
    driver = [r[published] - r[read] for r in rows]
    stages: dict[str, list[float]] = {}
    if config.stages:
        for label, start, end in STAGES:
            stages[label] = [r[_F[end]] - r[_F[start]] for r in rows]
    if config.timed and not floor:
        stages[OFF_CPU] = [(r[published] - r[read])
                           - (r[_F['cpu_published']] - r[_F['cpu_read']]) for r in rows]
    # The floor publishes one fixed stamp: only the driver's messages can be matched.
    to_subscriber = []
    if not floor:
        timer_of = {stamp_key(*stamp_parts(r[_F['stamp']])): r[timer] for r in rows}
        for sec, nanosec, when in received:
            matched = timer_of.get(stamp_key(sec, nanosec))
            if matched is not None:
                to_subscriber.append(when - written[matched])
    collections = [e for e in node.collections if t0 <= e[1] <= t1]
    return RunResult(end_to_end, kernel, driver, to_subscriber, stages,
                     100.0 * (cpu1 - cpu0) / (t1 - t0), collections, node.reader,
                     node.full_collection, wakes_per_second(switches0, switches1, t1 - t0))


def _ms(summary: Summary) -> str:
    if not summary.n:
        return '-'
    return f'{summary.p50 * 1e3:.3f} / {summary.p99 * 1e3:.3f} / {summary.max_ * 1e3:.3f}'


def _reader_policy(reader: dict[str, Any]) -> str:
    if not reader:
        return '?'
    names = {os.SCHED_OTHER: 'OTHER', os.SCHED_FIFO: 'FIFO'}
    policy = names.get(reader['policy'], str(reader['policy']))
    return f'{policy} {reader["priority"]}, CPUs {",".join(map(str, reader["cpus"]))}'


def _pooled(runs: list[RunResult], field: str) -> Summary:
    return summarise([v for r in runs for v in getattr(r, field)])


def tables(configs: dict[str, Config], results: dict[str, list[RunResult]],
           rate_hz: float) -> list[str]:
    """Return the Markdown lines: configurations, ratios, stages and targets."""
    floor_p99 = {name: _pooled(runs, 'driver').p99 for name, runs in results.items()
                 if configs[name].script}
    lines = ['| configuration | end to end p50 / p99 / max (ms) | kernel p50 / p99 / max | '
             'driver p50 / p99 / max | driver p99 per round | to a subscriber p50 / p99 / max | '
             'e2e p99 / kernel p99 | driver p99 / floor driver p99 | CPU %: mean (each round) | '
             'collections: gen 0/1/2 (longest ms) | a full collection (ms) | reader thread |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for name, runs in results.items():
        cpu = [r.cpu_percent for r in runs]
        cpu_text = f'{statistics.fmean(cpu):.2f} ({", ".join(f"{c:.2f}" for c in cpu)})'
        if not configs[name].timed:  # the CPU alone: nothing else was recorded
            lines.append(f'| {name}: {configs[name].description} | - | - | - | - | - | - | - | '
                         f'{cpu_text} | - | - | - |')
            continue
        e2e, kernel, driver = (_pooled(runs, f) for f in ('end_to_end', 'kernel', 'driver'))
        per_round = ' '.join(f'{percentile(r.driver, 99) * 1e3:.3f}' for r in runs)
        floors = ' · '.join(f'{driver.p99 / p99:.2f} ({floor})' for floor, p99 in
                            floor_p99.items() if floor != name) or '-'
        collections = [e for r in runs for e in r.collections]
        longest = max((e[2] for e in collections), default=0.0)
        by_generation = '/'.join(str(sum(1 for e in collections if e[0] == g)) for g in range(3))
        full = sorted(r.full_collection for r in runs)[len(runs) // 2]
        lines.append(
            f'| {name}: {configs[name].description} | {_ms(e2e)} | {_ms(kernel)} | '
            f'{_ms(driver)} | {per_round} | {_ms(_pooled(runs, "subscriber"))} | '
            f'{e2e.p99 / kernel.p99:.2f} | {floors} | '
            f'{cpu_text} | '
            f'{by_generation} ({longest * 1e3:.2f}) | {full * 1e3:.2f} | '
            f'{_reader_policy(runs[-1].reader)} |')
    stage_rows = [(name, label, summarise([v for r in runs for v in r.stages[label]]))
                  for name, runs in results.items()
                  for label in (*(s[0] for s in STAGES), OFF_CPU) if label in runs[0].stages]
    if stage_rows:
        lines += ['', '| stage of one sample | p50 / p99 / max (ms) | mean (ms) |',
                  '|---|---|---|']
        lines += [f'| {name}: {label} | {_ms(s)} | {s.mean * 1e3:.4f} |'
                  for name, label, s in stage_rows]
    lines += ['', *wake_table(results)]
    lines += ['', f'Targets (issue #12, at 100 Hz; this run at {rate_hz:.1f} Hz):']
    for name, runs in results.items():
        if configs[name].script or not configs[name].timed:
            continue
        driver, e2e, kernel = (_pooled(runs, f) for f in ('driver', 'end_to_end', 'kernel'))
        share_met = driver.p99 <= TARGET_DRIVER_P99_S and driver.max_ <= TARGET_DRIVER_MAX_S
        ratio = e2e.p99 / kernel.p99
        lines.append(
            f'- {name}: driver share p99 {driver.p99 * 1e3:.3f} ms, max '
            f'{driver.max_ * 1e3:.3f} ms (target <= {TARGET_DRIVER_P99_S * 1e3:g} / '
            f'{TARGET_DRIVER_MAX_S * 1e3:g} ms: {"met" if share_met else "not met"}); '
            f'end to end p99 {ratio:.2f} x the kernel p99 (target <= {TARGET_KERNEL_RATIO:g}: '
            f'{"met" if ratio <= TARGET_KERNEL_RATIO else "not met"})')
    return lines


def wake_table(results: dict[str, list[RunResult]]) -> list[str]:
    """
    Return the Markdown lines: how often each of the process's threads wakes (per s).

    Threads of one name are added up (the executor's workers); the mean of
    the rounds. Idle costs nothing when every thread of the node but the
    reader blocks until it has work: issue #51's target is at most 5 wakes a
    second for them all together at 100 Hz. The DDS library's own threads
    (``dds.*``: its event thread wakes for every message sent) are shown
    apart: the floor has them too.
    """
    lines = ['| configuration | wakes per second: thread (mean of the rounds) | '
             "the node's threads but the reader | DDS's threads |", '|---|---|---|---|']
    for name, runs in results.items():
        by_thread: dict[str, float] = {}
        for run in runs:
            for key, rate in run.wakes.items():
                thread = key.rsplit('#', 1)[0]
                by_thread[thread] = by_thread.get(thread, 0.0) + rate / len(runs)
        dds = sum(rate for thread, rate in by_thread.items() if thread.startswith(DDS_THREADS))
        others = sum(by_thread.values()) - dds - by_thread.get(READER_THREAD, 0.0)
        shown = ', '.join(f'{thread} {rate:.1f}' for thread, rate in
                          sorted(by_thread.items(), key=lambda item: -item[1]))
        lines.append(f'| {name} | {shown} | {others:.1f} | {dds:.1f} |')
    return lines


def measure(configs: dict[str, Config], rounds: int, seconds: float, rate_hz: float,
            seed: int = 1, line: str = 'pty') -> dict[str, list[RunResult]]:
    """Run every configuration once a round, in an order that changes; return the runs."""
    order_rng = random.Random(seed)
    results: dict[str, list[RunResult]] = {c: [] for c in configs}
    for round_ in range(rounds):
        order = list(configs)
        order_rng.shuffle(order)
        for name in order:
            print(f'-- round {round_ + 1}/{rounds}: {name}', file=sys.stderr, flush=True)
            result = run_once(configs[name], seconds, rate_hz, line)
            results[name].append(result)
            print(f'   driver p50/p99/max {_ms(summarise(result.driver))} ms, '
                  f'end to end {_ms(summarise(result.end_to_end))} ms, '
                  f'CPU {result.cpu_percent:.2f} %', file=sys.stderr, flush=True)
            gc.collect()
    return results


def main(argv: list[str] | None = None) -> int:
    """Run the rounds; print and save the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--configs', default='default,fifo,floor,floor-fifo',
                        help=f'comma-separated, of: {", ".join(CONFIGS)}')
    parser.add_argument('--rounds', type=int, default=4)
    parser.add_argument('--seconds', type=float, default=20.0, help='measured s per run')
    parser.add_argument('--rate', default='100',
                        help='data rate (Hz), or line-max: the most a 115200-baud line carries')
    parser.add_argument('--line', choices=('pty', 'usb'), default='pty',
                        help="how the port hands over a packet: the simulator's pty, 1 to 3 "
                             'pieces at once; usb, a piece a millisecond as a USB adapter does')
    parser.add_argument('--against', type=Path, metavar='DIR',
                        help='also run every configuration on the driver of this checkout')
    args = parser.parse_args(argv)
    names = [c for c in args.configs.split(',') if c]
    unknown = [c for c in names if c not in CONFIGS]
    if unknown:
        parser.error(f'unknown configs: {", ".join(unknown)}')
    configs = {name: CONFIGS[name] for name in names}
    if args.against is not None:
        tree = args.against.resolve()
        configs.update({f'{name} @ {tree}': config._replace(
            description=f'{config.description}, the driver of {tree}', tree=tree)
            for name, config in configs.items()})
    rate_hz = LINE_MAX_RATE_HZ if args.rate == 'line-max' else float(args.rate)
    isolate_ros_domain()
    note = RunNote('latency.py', argv)
    results = measure(configs, args.rounds, args.seconds, rate_hz, line=args.line)
    lines = [f'## Latency, {rate_hz:.1f} Hz, {args.line} line', '', machine_table(), '',
             *tables(configs, results, rate_hz), '',
             note.text(f'{args.rounds} rounds x {len(configs)} configurations, '
                       f'{args.seconds:g} s measured per run after {WARM_UP_S:g} s; '),
             '- Original C++ node (thesis): 0.99 ms mean, 1.16 ms max.']
    emit('\n'.join(lines) + '\n', 'latency.md')
    return 0


if __name__ == '__main__':
    sys.exit(main())
