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
Where a sample's time goes, and what each latency lever changes (issue #12).

Every run starts three processes: the simulated device
(``harness/sim_process.py``, 100 Hz by default), a subscriber
(``harness/subscriber.py``) and the real driver process timed from inside
(``latency_node.py``). The figures per run:

- end to end: the simulator's ``time.time()`` right after it wrote a
  packet's last byte, to right after ``publish()`` returned in the node;
- kernel: that write to the driver's ``read()`` returned (pty wake-up);
- driver: ``read()`` returned to ``publish()`` returned;
- the node's CPU (% of one core) over the measured window, and the garbage
  collections that ran in it.

``--stages`` adds the breakdown of one sample's path (select returned, read
returned, parsed, stamped, packed, published; the wrappers that time it add
about a microsecond). The levers are measured A/B in the same run: every
round runs each configuration once, in an order that changes from round to
round, so that the machine's other load falls on all of them alike; the
figures pool every round, and the spread of the per-round p99 is shown.

    python benchmarks/latency_levers.py --rounds 4 --seconds 20
    python benchmarks/latency_levers.py --stages --rounds 2 --configs default
    python benchmarks/latency_levers.py --load params --configs default,switch-0.5ms
"""

import argparse
import gc
import itertools
import os
import random
import statistics
import sys
import time
from typing import Any, NamedTuple

from bench_common import emit, LoadProcess, machine_table, RunNote, TimedNodeProcess, written_times
from harness.percentiles import percentile, summarise, Summary
from harness.processes import (
    isolate_ros_domain, process_cpu_seconds, SimProcess, SubscriberProcess,
)

#: Seconds of streaming left out at the start (start-up, DDS discovery).
WARM_UP_S = 3.0

#: name -> (flags of the timed process, node parameters, what it is). Flags starting with
#: ``script=`` name another process than latency_node.py; 'floor' configurations need a
#: simulator that streams from power-up.
CONFIGS: dict[str, tuple[tuple[str, ...], dict[str, Any], str]] = {
    'default': ((), {}, 'the driver as shipped'),
    'no-gc-freeze': (('--no-gc-freeze',), {}, 'start-up heap not frozen'),
    'switch-0.5ms': (('--switch-interval', '0.0005'), {}, 'lock switch interval 0.5 ms'),
    'fifo': ((), {'realtime_priority': 50}, 'reader thread SCHED_FIFO 50'),
    'cpu1': (('--reader-cpu', '1'), {}, 'reader thread on CPU 1'),
    'fifo-cpu1': (('--reader-cpu', '1'), {'realtime_priority': 50},
                  'reader thread SCHED_FIFO 50 on CPU 1'),
    'fifo-no-gc-freeze': (('--no-gc-freeze',), {'realtime_priority': 50},
                          'SCHED_FIFO 50, start-up heap not frozen'),
    'fifo-switch-0.5ms': (('--switch-interval', '0.0005'), {'realtime_priority': 50},
                          'SCHED_FIFO 50, lock switch interval 0.5 ms'),
    'floor': (('script=publish_floor.py',), {},
              'floor: a thread that only reads and publishes fixed bytes'),
    'floor-fifo': (('script=publish_floor.py', '--realtime-priority', '50'), {},
                   'floor, SCHED_FIFO 50'),
}
STAGE_NAMES = ('select', 'read', 'parse', 'stamp', 'pack', 'publish', 'off_cpu')


class RunResult(NamedTuple):
    """One configuration's run: latencies (s), CPU and collections."""

    end_to_end: list[float]
    kernel: list[float]
    driver: list[float]
    stages: dict[str, list[float]]
    cpu_percent: float
    collections: list[tuple[int, float, float]]
    threads: dict[str, dict]
    gc_frozen: int
    full_collection: float


def run_once(config: str, seconds: float, rate_hz: float, stages: bool,
             load: str = '') -> RunResult:
    """Run one configuration for ``seconds`` after the warm-up; return its figures."""
    flags, params, _ = CONFIGS[config]
    if stages and not any(f.startswith('script=') for f in flags):
        flags = (*flags, '--stages')
    script = next((f.split('=', 1)[1] for f in flags if f.startswith('script=')),
                  'latency_node.py')
    flags = tuple(f for f in flags if not f.startswith('script='))
    floor = script != 'latency_node.py'
    sim = SimProcess(rate_hz=rate_hz, streaming_at_start=floor)
    subscriber = SubscriberProcess()
    node = None
    busy = LoadProcess() if load == 'params' else None
    try:
        node = TimedNodeProcess(sim.port, flags, script=script, **params)
        time.sleep(WARM_UP_S)
        if busy is not None:
            busy.start()
        t0, cpu0 = time.time(), process_cpu_seconds(node.pid)
        time.sleep(seconds)
        t1, cpu1 = time.time(), process_cpu_seconds(node.pid)
        if busy is not None:
            busy.stop()
        sim.silence()
        time.sleep(0.3)
    finally:
        if node is not None:
            node.stop()
        subscriber.stop()
        sim.stop()
    written = written_times(sim.truth)
    rows = [r for r in node.rows if t0 <= r[2] <= t1 and r[0] in written]
    end_to_end = [r[2] - written[r[0]] for r in rows]
    kernel = [r[1] - written[r[0]] for r in rows]
    driver = [r[2] - r[1] for r in rows]
    by_stage: dict[str, list[float]] = {name: [] for name in STAGE_NAMES}
    if stages and len(rows[0] if rows else ()) > 3:
        for r in rows:
            select_t, read_t, parse_t, stamp_t, pack_t, cpu_select, cpu_published = r[3:10]
            marks = (written[r[0]], select_t, read_t, parse_t, stamp_t, pack_t, r[2])
            if not all(marks) or not select_t <= read_t <= parse_t <= stamp_t <= pack_t:
                continue  # a mark from another read (two packets in one read)
            for name, (a, b) in zip(STAGE_NAMES, itertools.pairwise(marks), strict=False):
                by_stage[name].append(b - a)
            # Of select() returned -> publish() returned, the time the thread did not run.
            by_stage['off_cpu'].append((r[2] - select_t) - (cpu_published - cpu_select))
    collections = [e for e in node.gc if t0 <= e[1] <= t1]
    return RunResult(end_to_end, kernel, driver, by_stage,
                     100.0 * (cpu1 - cpu0) / (t1 - t0), collections, node.threads,
                     node.gc_frozen, node.full_collection)


def _ms(summary: Summary) -> str:
    return f'{summary.p50 * 1e3:.3f} / {summary.p99 * 1e3:.3f} / {summary.max_ * 1e3:.3f}'


def _reader_policy(threads: dict[str, dict]) -> str:
    reader = threads.get('gx2-reader')
    if reader is None:
        return '?'
    names = {os.SCHED_OTHER: 'OTHER', os.SCHED_FIFO: 'FIFO'}
    policy = names.get(reader['policy'], str(reader['policy']))
    return f'{policy} {reader["priority"]}, CPUs {",".join(map(str, reader["cpus"]))}'


def main(argv: list[str] | None = None) -> int:
    """Run the rounds; print and save the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--rounds', type=int, default=4)
    parser.add_argument('--seconds', type=float, default=20.0, help='measured s per run')
    parser.add_argument('--rate', type=float, default=100.0, help='data rate (Hz)')
    parser.add_argument('--configs', default=','.join(CONFIGS),
                        help=f'comma-separated, of: {", ".join(CONFIGS)}')
    parser.add_argument('--stages', action='store_true', help='time every stage of the path')
    parser.add_argument('--seed', type=int, default=1, help='seed of the run order')
    parser.add_argument('--load', choices=('', 'params'), default='',
                        help='params: parameter requests kept in flight against the node from '
                             'another process while measuring (its executor threads then '
                             'want the interpreter lock all the time)')
    parser.add_argument('--output', default='latency_levers.md')
    args = parser.parse_args(argv)
    configs = [c for c in args.configs.split(',') if c]
    unknown = [c for c in configs if c not in CONFIGS]
    if unknown:
        parser.error(f'unknown configs: {", ".join(unknown)}')
    isolate_ros_domain()
    note = RunNote('latency_levers.py', argv)
    order_rng = random.Random(args.seed)
    results: dict[str, list[RunResult]] = {c: [] for c in configs}
    for round_ in range(args.rounds):
        order = list(configs)
        order_rng.shuffle(order)
        for config in order:
            print(f'-- round {round_ + 1}/{args.rounds}: {config}', file=sys.stderr, flush=True)
            result = run_once(config, args.seconds, args.rate, args.stages, args.load)
            results[config].append(result)
            print(f'   driver p50/p99/max {_ms(summarise(result.driver))} ms, '
                  f'end to end {_ms(summarise(result.end_to_end))} ms, '
                  f'CPU {result.cpu_percent:.2f} %', file=sys.stderr, flush=True)
            gc.collect()
    title = f'## Latency levers, {args.rate:g} Hz' + (', parameter flood' if args.load else '')
    lines = [title, '', machine_table(), '',
             '| configuration | end to end p50 / p99 / max (ms) | kernel p50 / p99 / max | '
             'driver p50 / p99 / max | driver p99 per round | end to end p99 per round | '
             'e2e p99 / kernel p99 | '
             'CPU % | collections: gen 0/1/2 (longest ms) | a full collection (ms) | '
             'reader thread |',
             '|---|---|---|---|---|---|---|---|---|---|---|']
    for config in configs:
        runs = results[config]
        e2e = summarise([v for r in runs for v in r.end_to_end])
        kernel = summarise([v for r in runs for v in r.kernel])
        driver = summarise([v for r in runs for v in r.driver])
        per_round = ' '.join(f'{percentile(r.driver, 99) * 1e3:.3f}' for r in runs)
        e2e_rounds = ' '.join(f'{percentile(r.end_to_end, 99) * 1e3:.3f}' for r in runs)
        cpu = sum(r.cpu_percent for r in runs) / len(runs)
        collections = [e for r in runs for e in r.collections]
        longest = max((e[2] for e in collections), default=0.0)
        by_generation = '/'.join(str(sum(1 for e in collections if e[0] == g)) for g in range(3))
        full = statistics.median(r.full_collection for r in runs)
        lines.append(
            f'| {config}: {CONFIGS[config][2]} | {_ms(e2e)} | {_ms(kernel)} | {_ms(driver)} | '
            f'{per_round} | {e2e_rounds} | {e2e.p99 / kernel.p99:.2f} | {cpu:.2f} | '
            f'{by_generation} ({longest * 1e3:.2f}) | {full * 1e3:.2f} | '
            f'{_reader_policy(runs[-1].threads)} |')
    if args.stages:
        lines += ['', '| stage (one sample) | p50 / p99 / max (ms) | mean (ms) |', '|---|---|---|']
        labels = {'select': 'last byte written -> select() returned (kernel wake-up, GIL)',
                  'read': 'select() returned -> os.read() returned',
                  'parse': 'read returned -> parsed (time.time, capture hook, parser)',
                  'stamp': 'parsed -> stamped (dispatch, lock, unwrap, device clock)',
                  'pack': 'stamped -> packed (orientation, CDR bytes)',
                  'publish': 'packed -> publish() returned (rclpy, DDS)',
                  'off_cpu': 'of select() returned -> publish() returned: not running '
                             '(preempted, waiting for the GIL or a lock)'}
        for config in configs:
            for name in STAGE_NAMES:
                values = [v for r in results[config] for v in r.stages[name]]
                if values:
                    s = summarise(values)
                    lines.append(f'| {config}: {labels[name]} | {_ms(s)} | '
                                 f'{s.mean * 1e3:.4f} |')
    lines += ['', note.text(f'{args.rounds} rounds x {len(configs)} configurations, '
                            f'{args.seconds:g} s measured per run after {WARM_UP_S:g} s; ')]
    emit('\n'.join(lines) + '\n', args.output)
    return 0


if __name__ == '__main__':
    sys.exit(main())
