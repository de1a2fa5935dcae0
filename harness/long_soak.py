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
The long soak: every stream, every fault, both node kinds, for an hour or more.

What breaks a driver in the field shows after an hour (a slow leak, a state
never left), so this run keeps its node processes for the whole of it. One
simulated base station (``harness/campaign.py``'s faults, its line rate
honoured) serves, in turn, *legs* of a few minutes: each leg is one stream
at the highest rate its line budget allows (``data_rate``: the node writes
the divider), the faults of the campaign at seeded random times, a quiet
phase in which the stream must come back, and the checks of the campaign on
what was published (matched to the simulator's truth by exact values).

The legs go round the streams several times. Most legs run a managed node:
one process per stream, started at the beginning and kept to the end, taken
through configure / activate (the leg) / deactivate / cleanup each time its
stream's turn comes, so that every managed process lives the whole run and
its RSS, descriptors and threads can be fitted against time (a leak is a
slope, not a final value). Every ``plain_every``-th leg runs the plain node
instead, a fresh process stopped with SIGINT at the leg's end (shifted by
one each round, so that every stream runs on both kinds). At the end
every managed process is taken to a random state and shut down with SIGINT.

Per leg and per stream: records sent, published, received by a subscriber
in this process (another than the node's), missing, duplicated, corrupted,
the longest time from the end of each fault to the next message received,
the node's CPU; overall: the slopes. Targets: everything the campaign
checks, data back within ``recovery_limit`` after every fault that ends,
and (for runs of at least ``slope_min_minutes``) RSS slope below
``rss_slope_limit`` MiB/h and descriptors and threads flat after the first
``slope_after`` seconds. ``benchmarks/soak.py --every-stream`` runs it,
``test/test_soak_every_stream.py`` for a minute in CI.
"""

import bisect
import collections
import dataclasses
import json
import os
import random
import shutil
import statistics
import sys
import tempfile
import threading
import time
import traceback
from typing import Any, NamedTuple

from harness.campaign import (
    analyse, CampaignConfig, Check, FaultDriver, FaultEvent, RunData, Subscriber,
    TruthCollector)
from harness.instrumented_node import STATS_ENV
from harness.processes import (
    isolate_ros_domain, LifecycleClient, NodeProcess, process_cpu_seconds, ros_env)
from i3dmgx2_driver.codec import line_budget
from i3dmgx2_driver.codec.data_rate import divider_for_rate
from i3dmgx2_driver.codec.streams import STREAMS
from i3dmgx2_driver.device.timeouts import REQUEST_TIMEOUT
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.sensor import FACTORY_DIVIDER, RATE_DIVIDER_ADDRESS

NODE_MODULE = (sys.executable, '-m', 'harness.instrumented_node')
BAUD = 115200
#: What one more try costs the dialogue when a command or its answer is lost: the
#: request's timeout, then the shortest wait for the first record
#: (``SensorDialogue.start_continuous``).
TRY_COST = REQUEST_TIMEOUT + 0.3
#: Seconds a leg takes besides its faults and quiet phase (transitions, draining), roughly.
LEG_OVERHEAD = 15.0


@dataclasses.dataclass
class LongSoakConfig:
    """How long, how rough, and what counts as a pass."""

    #: Length of the whole run (min): legs follow one another until it is over.
    minutes: float = 60.0
    #: Length of each leg's fault phase (min); a quiet phase follows.
    leg_minutes: float = 2.5
    #: How many legs (None: as many as fit in ``minutes``).
    legs: int | None = None
    #: The streams the legs go round (names; empty: every stream).
    streams: tuple[str, ...] = ()
    seed: int = 1
    address: int = 95
    #: Every this many legs, the plain node runs the leg instead of a managed one (0: never);
    #: shifted by one leg each round of the streams.
    plain_every: int = 3
    #: Seconds between fault events (the campaign's FaultDriver).
    event_gap: tuple[float, float] = (1.0, 4.0)
    #: Quiet seconds at the end of each leg, in which the stream must come back.
    quiet: float = 4.0
    read_timeout: float = 0.3
    reconnect_interval: float = 0.2
    temperature_period: float = 1.0
    #: Seconds from the end of a fault to the next message received, at most.
    recovery_limit: float = 1.0
    #: Slopes are fitted from this many seconds after the start of each process.
    slope_after: float = 300.0
    #: Slopes are asserted only for runs at least this long (min).
    slope_min_minutes: float = 30.0
    #: Most RSS slope allowed (MiB per hour), and descriptors / threads (per hour).
    rss_slope_limit: float = 1.0
    count_slope_limit: float = 1.0
    #: Seconds between samples of RSS, descriptors and threads.
    sample_period: float = 5.0
    log: Any = print


class Leg(NamedTuple):
    """One stream, one node kind, one stretch of faults."""

    number: int
    stream: str
    rate_hz: float
    kind: str


class LegResult(NamedTuple):
    """What one leg came to."""

    leg: Leg
    checks: list[Check]
    figures: dict
    #: (fault kind, seconds from its end to the next message (None: none came), its limit).
    recoveries: list[tuple[str, float | None, float]]
    cpu_percent: float
    seconds: float
    report: str


def plan_legs(cfg: LongSoakConfig) -> list[Leg]:
    """Return the legs: the streams in turn, each at its line-budget maximum rate."""
    leg_seconds = cfg.leg_minutes * 60.0 + cfg.quiet + LEG_OVERHEAD
    count = cfg.legs or max(1, round(cfg.minutes * 60.0 / leg_seconds))
    chosen = [s for s in STREAMS if not cfg.streams or s.name in cfg.streams]
    legs = []
    for number in range(count):
        stream = chosen[number % len(chosen)]
        rate = line_budget.max_rate(stream.code, BAUD, wireless=True)
        # Shifted by one each round of the streams, so that every stream meets both kinds.
        turn = number + number // len(chosen)
        plain = cfg.plain_every and (turn + 1) % cfg.plain_every == 0
        # Rounded down to 0.1 Hz: the parameter's text must map to the same divider.
        legs.append(Leg(number, stream.name, int(rate * 10) / 10.0,
                        'plain' if plain else 'managed'))
    return legs


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


def process_sample(pid: int) -> tuple[int, int, int] | None:
    """Return (RSS KiB, open descriptors, threads) of a process, None if it is gone."""
    try:
        rss = threads = None
        with open(f'/proc/{pid}/status') as handle:
            for line in handle:
                if line.startswith('VmRSS:'):
                    rss = int(line.split()[1])
                elif line.startswith('Threads:'):
                    threads = int(line.split()[1])
        fds = len(os.listdir(f'/proc/{pid}/fd'))
    except OSError:
        return None
    if rss is None or threads is None:
        return None
    return rss, fds, threads


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
                    self._sample_heap(name)

    def _sample_heap(self, name: str) -> None:
        path = self._stats.get(name)
        heap = (_read_json(path) or {}).get('heap') if path is not None else None
        if heap:
            self.heaps.setdefault(name, []).append(
                (time.time(), heap['python_blocks'], heap['malloc_in_use_kib']))

    def stop(self) -> None:
        """Stop sampling."""
        self._halt.set()
        self.join(5.0)


def _read_json(path: str) -> dict | None:
    try:
        with open(path) as handle:
            return json.load(handle)
    except (OSError, ValueError):
        return None


def _topic(namespace: str) -> str:
    return f'/{namespace}/imu/raw_data'


class LongSoak:
    """The run: the simulator, the processes, the legs, the report."""

    def __init__(self, cfg: LongSoakConfig) -> None:
        self.cfg = cfg
        self.log = cfg.log or (lambda text: None)
        self.legs = plan_legs(cfg)
        self.workdir = tempfile.mkdtemp(prefix='i3dmgx2-long-soak-')
        self.sim: PtySimulator | None = None
        self.collector: TruthCollector | None = None
        self.subscriber: Subscriber | None = None
        self.sampler = Sampler(cfg.sample_period)
        self.managed: dict[str, NodeProcess] = {}
        self.clients: dict[str, LifecycleClient] = {}
        self.results: list[LegResult] = []
        self.end_checks: list[Check] = []
        self.end_lines: list[str] = []
        self.rng = random.Random(cfg.seed * 104729 + 3)
        self.eeprom_writes: int | None = None

    # -- processes -------------------------------------------------------------------------

    def _params(self, name: str, leg_stream: str, rate: float) -> dict:
        cfg = self.cfg
        qos = f'qos_overrides.{_topic(name)}.publisher'
        return {'port': self.sim.port, 'address': cfg.address,
                'read_timeout': cfg.read_timeout, 'reconnect_interval': cfg.reconnect_interval,
                f'{qos}.depth': 1000, f'{qos}.reliability': 'reliable',
                'temperature_period': cfg.temperature_period, 'stream': leg_stream,
                'data_rate': rate}

    def _stats_path(self, name: str) -> str:
        return os.path.join(self.workdir, f'{name}.json')

    def _start_node(self, name: str, stream: str, rate: float, lifecycle: bool) -> NodeProcess:
        command = NODE_MODULE + (('--lifecycle',) if lifecycle else ())
        node = NodeProcess(self._params(name, stream, rate), extra_args=['-r', f'__ns:=/{name}'],
                           command=command,
                           env=ros_env({STATS_ENV: self._stats_path(name)}))
        self.sampler.watch(name, node.proc.pid, self._stats_path(name))
        return node

    def _wait_publisher(self, topic: str, node: NodeProcess, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while self.subscriber.node.count_publishers(topic) < 1:
            if node.proc.poll() is not None:
                raise RuntimeError(f'the node exited:\n{node.output()[-3000:]}')
            if time.monotonic() > deadline:
                raise RuntimeError(f'no publisher of {topic} within {timeout:g} s')
            time.sleep(0.1)

    def _wait_messages(self, count: int, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while self.subscriber.count < count and time.monotonic() < deadline:
            time.sleep(0.05)
        return self.subscriber.count >= count

    def _take_rows(self) -> list:
        rows, self.subscriber.rows = self.subscriber.rows, []
        return rows

    def _take_truth(self) -> tuple[list, int]:
        self.collector.collect()
        with self.collector._lock:
            entries, self.collector.entries = self.collector.entries, []
            missed, self.collector.missed = self.collector.missed, 0
        return entries, missed

    def _final_stats(self, path: str, after: float, published: int | None = None,
                     timeout: float = 10.0) -> dict:
        """Return the node's counters written after ``after`` (with ``published``, if given)."""
        deadline = time.monotonic() + timeout
        got: dict = {}
        while time.monotonic() < deadline:
            got = _read_json(path) or {}
            if got.get('time', 0.0) > after and (
                    published is None or got.get('stats', {}).get('published') == published):
                break
            time.sleep(0.1)
        return got

    # -- one leg ---------------------------------------------------------------------------

    def _faults(self, leg: Leg, started: float) -> FaultDriver:
        """Run the fault phase of a leg; return the driver (its events)."""
        cfg = self.cfg
        campaign = CampaignConfig(event_gap=cfg.event_gap, long_stalls=True, log=None)
        driver = FaultDriver(self.sim, campaign, random.Random(cfg.seed * 7919 + leg.number))
        driver.start()
        end = started + cfg.leg_minutes * 60.0
        while time.time() < end:
            time.sleep(0.5)
        driver.stop()
        return driver

    def _recoveries(self, events: list[FaultEvent], rows: list, truth: list
                    ) -> list[tuple[str, float | None, float]]:
        """
        For each fault that ends: (kind, seconds to the next message received, the limit).

        The limit is ``recovery_limit``, plus :data:`TRY_COST` for every
        command the radio lost, stalled or the sensor ignored, and every reply
        the radio dropped, from one try before the fault ended to the
        message: each costs the dialogue one more try, by design. A fault
        followed by the next one before the data came back is left out (the
        recovery was cut short, not slow).
        """
        times = sorted(row[3] for row in rows)
        misses = sorted([h.time for h in self.sim.host_log
                         if h.outcome in ('lost', 'ignored', 'stalled', 'ping failed')
                         or h.outcome.startswith('rejected')]
                        + [s.sample_time for s in truth
                           if s.source == 'reply' and s.fault is not None])
        starts = sorted(e.start for e in events)
        out = []
        for event in events:
            if event.kind in {'noise', 'quirks'}:
                continue  # they change the line's odds until the next change; all_off ends them
            i = bisect.bisect_right(times, event.end)
            back = times[i] if i < len(times) else None
            j = bisect.bisect_right(starts, event.end)
            if j < len(starts) and (back is None or starts[j] < back):
                continue  # the next fault began before the data came back: not a recovery
            retries = (bisect.bisect_right(misses, back)
                       - bisect.bisect_left(misses, event.end - TRY_COST)
                       if back is not None else 0)
            limit = self.cfg.recovery_limit + retries * TRY_COST
            gap = back - event.end if back is not None else None
            out.append((event.kind, gap, limit))
            if gap is None or gap > limit:
                self._explain(event, back)
        return out

    def _explain(self, event: FaultEvent, back: float | None) -> None:
        """Log what the host sent and the sensor made of it while the data did not come."""
        stop = back if back is not None else event.end + 10.0
        self.log(f'  slow recovery after {event.kind} ({event.detail}) at {event.end:.3f}:')
        for h in self.sim.host_log:
            if event.start - 1.0 <= h.time <= stop:
                code = f'0x{h.raw[0]:02X}' if h.raw else '-'
                self.log(f'    {h.time - event.end:+.3f} s host {h.kind} {code} {h.outcome}')

    def run_leg(self, leg: Leg) -> LegResult:
        """Bring the leg's node up, fault it, bring it down; analyse what it published."""
        cfg = self.cfg
        name = f'soak_{leg.stream}' if leg.kind == 'managed' else f'soak_plain_{leg.number}'
        path = self._stats_path(name)
        self._take_rows()
        self._take_truth()
        begin = time.time()
        plain = None
        if leg.kind == 'managed':
            node = self.managed[leg.stream]
            client = self.clients[leg.stream]
            self.sampler.busy.add(name)
            if not client.change('configure'):
                raise RuntimeError(f'leg {leg.number}: configure failed:\n'
                                   f'{node.output()[-3000:]}')
            self._wait_publisher(_topic(name), node)
            time.sleep(0.5)
            if not client.change('activate'):
                raise RuntimeError(f'leg {leg.number}: activate failed:\n'
                                   f'{node.output()[-3000:]}')
        else:
            self.sim.unplug(None)
            plain = node = self._start_node(name, leg.stream, leg.rate_hz, lifecycle=False)
            self._wait_publisher(_topic(name), node)
            time.sleep(1.0)
            self.sim.replug()
        if not self._wait_messages(1, 60.0):
            raise RuntimeError(f'leg {leg.number}: no message within 60 s:\n'
                               f'{node.output()[-3000:]}')
        started = time.time()
        cpu_start = process_cpu_seconds(node.proc.pid)
        self.log(f'leg {leg.number}: {leg.kind} node, stream {leg.stream} at {leg.rate_hz:g} '
                 f'Hz, {cfg.leg_minutes:g} min of faults')
        driver = self._faults(leg, started)
        fault_end = time.time()
        before = self.subscriber.count
        time.sleep(cfg.quiet)
        recovered = self.subscriber.count - before
        alive = node.proc.poll() is None
        cpu = process_cpu_seconds(node.proc.pid) - cpu_start if alive else 0.0
        stopped = time.time()
        exit_code, exit_seconds = 0, 0.0
        if leg.kind == 'managed':
            client.change('deactivate')
            done = time.time()
            stats = self._final_stats(path, done)
            published = stats.get('stats', {}).get('published')
            if published is not None:
                self._wait_messages(published, 15.0)
            stats = self._final_stats(path, done, published)
            client.change('cleanup')
            time.sleep(0.5)  # the port closed, the threads joined
            self.sampler.first_release.setdefault(name, time.time())
            self.sampler.busy.discard(name)
        else:
            exit_code, exit_seconds = plain.stop(timeout=15.0)
            self.sampler.forget(name)
            stats = self._final_stats(path, stopped)
            if not stats.get('final'):
                stats = self._final_stats(path, stopped, timeout=5.0)
            published = stats.get('stats', {}).get('published')
            if published is not None:
                self._wait_messages(published, 15.0)
        time.sleep(0.3)
        rows = self._take_rows()
        truth, missed = self._take_truth()
        events = [e for e in stats.get('port_events', []) if e[1] >= begin
                  and (leg.kind == 'plain' or e[1] < stopped)]
        stats = dict(stats, port_events=events)
        with self.sim.lock:
            divider = self.sim.sensor.eeprom.get(RATE_DIVIDER_ADDRESS, 512)
        rss = [(t, kib) for t, kib, _, _ in self.sampler.all_samples.get(name, [])
               if t >= started]
        data = RunData(
            cfg=CampaignConfig(minutes=cfg.leg_minutes, rate_hz=None, stream=leg.stream,
                               data_rate=leg.rate_hz, seed=cfg.seed, address=cfg.address,
                               read_timeout=cfg.read_timeout,
                               reconnect_interval=cfg.reconnect_interval,
                               quiet=cfg.quiet, temperature_period=cfg.temperature_period,
                               warmup_min=10.0, log=None),
            truth=truth, truth_missed=missed, messages=rows, events=list(driver.events),
            node_stats=stats, sim_stats=self.sim.stats.as_dict(), host_log=self.sim.host_log,
            rss=rss, warmup_end=started + 10.0, fault_end=fault_end, alive_at_end=alive,
            exit_code=exit_code, exit_seconds=exit_seconds, recovered=recovered,
            unsafe_garbage_bytes=driver.unsafe_garbage_bytes,
            unsafe_garbage_bursts=driver.unsafe_garbage_bursts, divider=divider,
            power_ups=list(driver.power_ups), node_output=node.output()[-5000:],
            started=started, end=stopped if leg.kind == 'managed' else None)
        result = analyse(data)
        # A managed node does not exit at a leg's end (its exit is checked at the run's),
        # and counts as unpublished what it reads while inactive, by design.
        checks = [c for c in result.checks if not (leg.kind == 'managed' and c.name in (
            'clean exit on SIGINT', 'nothing left unpublished'))]
        recoveries = self._recoveries(driver.events, rows, truth)
        slow = [(k, g, lim) for k, g, lim in recoveries if g is None or g > lim]
        worst = max((g for _, g, _ in recoveries if g is not None), default=0.0)
        retried = sum(1 for _, _, lim in recoveries if lim > cfg.recovery_limit)
        checks.append(Check(
            'data back after every fault that ends', not slow,
            f'{len(recoveries)} faults ended; longest wait for the next message '
            f'{worst:.3f} s (limit {cfg.recovery_limit:g} s, plus {TRY_COST:g} s for '
            f'each command or reply lost or ignored meanwhile: {retried} such)'
            + ('; over: ' + ', '.join(f'{k} {g if g is None else round(g, 3)} (limit '
                                      f'{lim:g})' for k, g, lim in slow[:8])
               if slow else '')))
        seconds = stopped - started
        legresult = LegResult(leg, checks, result.figures, recoveries,
                              100.0 * cpu / seconds if seconds > 0 else 0.0, seconds,
                              result.report)
        failed = [c.name for c in checks if not c.ok]
        self.log(f'leg {leg.number}: {result.figures.get("published")} published, '
                 f'{result.figures.get("missing")} missing, {len(driver.events)} faults, '
                 f'worst recovery {worst:.3f} s, CPU {legresult.cpu_percent:.1f} %: '
                 + ('PASS' if not failed else 'FAIL ' + ', '.join(failed)))
        if failed:
            self.log(result.report)
        return legresult

    # -- the run ---------------------------------------------------------------------------

    def start(self) -> None:
        """Start the simulator, the subscriber and the managed node processes."""
        cfg = self.cfg
        isolate_ros_domain()
        self.sim = PtySimulator(SimulatorConfig(
            address=cfg.address, seed=cfg.seed, rate_hz=None, limit_to_line_rate=True,
            truth_limit=400 * 120 + 20000))
        self.sim.start()
        self.collector = TruthCollector(self.sim)
        self.collector.start()
        kinds = {leg.stream for leg in self.legs if leg.kind == 'managed'}
        topics = [_topic(f'soak_{s.name}') for s in STREAMS if s.name in kinds]
        topics += [_topic(f'soak_plain_{leg.number}') for leg in self.legs
                   if leg.kind == 'plain']
        self.subscriber = Subscriber(topics=tuple(topics))
        self.sampler.start()
        for stream in STREAMS:
            if stream.name not in kinds:
                continue
            rate = next(leg.rate_hz for leg in self.legs if leg.stream == stream.name)
            name = f'soak_{stream.name}'
            self.managed[stream.name] = self._start_node(name, stream.name, rate, True)
            self.clients[stream.name] = LifecycleClient(self.subscriber,
                                                        f'/{name}/i3dmgx2_driver')
        for stream, client in self.clients.items():
            if not client.wait_ready(60.0):
                raise RuntimeError(f'managed node {stream}: lifecycle services not ready:\n'
                                   f'{self.managed[stream].output()[-3000:]}')

    def finish(self) -> None:
        """Take the managed nodes to random states, then SIGINT them; check their exits."""
        if not self.managed:
            return
        names = sorted(self.managed)
        chosen = self.rng.choice(names)
        target = self.rng.choice(('unconfigured', 'inactive', 'active'))
        steps = {'unconfigured': (), 'inactive': ('configure',),
                 'active': ('configure', 'activate')}[target]
        reached = all(self.clients[chosen].change(step) for step in steps)
        states = {name: (target if name == chosen else 'unconfigured') for name in names}
        self.end_lines.append(f'shutdown: {chosen} taken to {target} '
                              f'({"reached" if reached else "NOT reached"}), the others '
                              f'unconfigured; then SIGINT to every managed process')
        for name in names:
            node = self.managed[name]
            alive = node.proc.poll() is None
            code, seconds = node.stop(timeout=15.0)
            self.sampler.forget(f'soak_{name}')
            ok = alive and code == 0 and seconds < 5.0
            self.end_checks.append(Check(
                f'managed {name}: clean exit on SIGINT from {states[name]}', ok,
                f'alive until the end: {alive}; exit code {code} after {seconds:.2f} s'
                + ('' if ok else f'\n{node.output()[-3000:]}')))

    def close(self) -> None:
        """Stop everything that still runs."""
        steps = [self.sampler.stop]
        steps += [node.close for node in self.managed.values()]
        if self.subscriber is not None:
            steps.append(self.subscriber.close)
        if self.collector is not None:
            steps.append(lambda: self.collector.is_alive() and self.collector.stop())
        if self.sim is not None:
            steps.append(self.sim.stop)
        steps.append(lambda: shutil.rmtree(self.workdir, ignore_errors=True))
        for step in steps:
            try:
                step()
            except Exception as exc:  # keep cleaning up; say what went wrong
                print(f'long soak cleanup: {type(exc).__name__}: {exc}', file=sys.stderr)

    def slopes(self, minutes: float) -> tuple[list[Check], list[str]]:
        """Fit RSS, descriptors and threads against time for each long-lived process."""
        cfg = self.cfg
        checks, lines = [], []
        asserted = minutes >= cfg.slope_min_minutes
        lines.append(f'slopes per hour, while unconfigured, after the first {cfg.slope_after:g} s '
                     f'and the first leg of each managed process '
                     f'({"asserted" if asserted else "not asserted"}: run of '
                     f'{minutes:.1f} min, asserted from {cfg.slope_min_minutes:g} min):')
        for name in sorted(self.managed):
            key = f'soak_{name}'
            born = self.sampler.born.get(key, 0.0)
            # After the first 5 minutes and after the process's first leg (its first
            # activation loads what it keeps: a warm-up, not a leak).
            since = max(born + cfg.slope_after, self.sampler.first_release.get(key, born))
            samples = [s for s in self.sampler.samples.get(key, []) if s[0] >= since]
            rss = slope_per_hour([(t, kib / 1024.0) for t, kib, _, _ in samples])
            fds = slope_per_hour([(t, n) for t, _, n, _ in samples])
            threads = slope_per_hour([(t, n) for t, _, _, n in samples])
            first = samples[0][1:] if samples else None
            last = samples[-1][1:] if samples else None
            heaps = [h for h in self.sampler.heaps.get(key, []) if h[0] >= since]
            blocks = slope_per_hour([(t, n) for t, n, _ in heaps])
            native = slope_per_hour([(t, kib / 1024.0) for t, _, kib in heaps if kib is not None])

            def text(value: float | None, unit: str) -> str:
                return 'n/a' if value is None else f'{value:+.3f} {unit}/h'

            lines.append(f'  {name:22s} RSS {text(rss, "MiB")}, descriptors {text(fds, "")}, '
                         f'threads {text(threads, "")}; {len(samples)} samples; first '
                         f'{first}, last {last} (RSS KiB, fds, threads)')
            if heaps:
                # Not asserted: what tells a leak (these grow too) from an allocator
                # that keeps freed memory (RSS alone grows).
                lines.append(f'  {"":22s} heap in use: Python objects '
                             f'{text(blocks, "blocks")}, C heap {text(native, "MiB")}; first '
                             f'{heaps[0][1:]}, last {heaps[-1][1:]} (blocks, KiB)')
            if asserted:
                ok = (rss is not None and rss < cfg.rss_slope_limit
                      and fds is not None and abs(fds) <= cfg.count_slope_limit
                      and threads is not None and abs(threads) <= cfg.count_slope_limit)
                checks.append(Check(
                    f'managed {name}: no leak', ok,
                    f'RSS {text(rss, "MiB")} (limit {cfg.rss_slope_limit:g}), descriptors '
                    f'{text(fds, "")}, threads {text(threads, "")} (limit '
                    f'\u00b1{cfg.count_slope_limit:g})'))
        return checks, lines

    def run(self) -> 'LongSoakResult':
        """Run every leg, then the end; return the verdict and the report."""
        cfg = self.cfg
        began = time.time()
        try:
            self.start()
            self.log(f'long soak: {len(self.legs)} legs over {cfg.minutes:g} min, domain '
                     f'{os.environ.get("ROS_DOMAIN_ID")}, seed {cfg.seed}')
            for leg in self.legs:
                self.results.append(self.run_leg(leg))
            self.eeprom_writes = len(self.sim.eeprom_writes())
            self.finish()
        except Exception:  # the run could not go on: a failed check with the reason
            self.end_checks.append(Check('run completed', False, traceback.format_exc()))
        finally:
            minutes = (time.time() - began) / 60.0
            slope_checks, slope_lines = self.slopes(minutes)
            self.close()
        return report(self, minutes, slope_checks, slope_lines)


@dataclasses.dataclass
class LongSoakResult:
    """The verdicts and the report of one long run."""

    checks: list[Check]
    report: str

    @property
    def ok(self) -> bool:
        """Whether every check passed."""
        return bool(self.checks) and all(check.ok for check in self.checks)


def report(run: LongSoak, minutes: float, slope_checks: list[Check],
           slope_lines: list[str]) -> LongSoakResult:
    """Build the per-stream and overall tables and the list of checks."""
    cfg = run.cfg
    lines = ['== i3dmgx2 long soak: every stream, every fault, both node kinds ==',
             f'{minutes:.1f} min, {len(run.results)} legs of {cfg.leg_minutes:g} min of faults '
             f'+ {cfg.quiet:g} s quiet, seed {cfg.seed}, 115200 baud, wireless; the simulator '
             f'honours the line rate']
    head = ('| leg | node | stream | rate (Hz) | sent | published | received | missing | '
            'duplicated | corrupted | faults | longest recovery (s) | node CPU (%) | result |')
    lines += ['', head, '|' + '---|' * 14]
    checks: list[Check] = []
    per_stream: dict[str, dict] = {}
    for r in run.results:
        f = r.figures
        worst = max((g for _, g, _ in r.recoveries if g is not None), default=0.0)
        ok = all(c.ok for c in r.checks)
        lines.append(f'| {r.leg.number} | {r.leg.kind} | {r.leg.stream} | {r.leg.rate_hz:g} | '
                     f'{f.get("sent")} | {f.get("published")} | {f.get("received")} | '
                     f'{f.get("missing")} | {f.get("duplicated")} | {f.get("corrupted")} | '
                     f'{f.get("events")} | {worst:.3f} | {r.cpu_percent:.1f} | '
                     f'{"PASS" if ok else "FAIL"} |')
        for c in r.checks:
            checks.append(Check(f'leg {r.leg.number} ({r.leg.kind} {r.leg.stream}): {c.name}',
                                c.ok, c.detail))
        s = per_stream.setdefault(r.leg.stream, collections_counter())
        for name in ('sent', 'published', 'received', 'missing', 'duplicated', 'corrupted',
                     'events'):
            s[name] += f.get(name) or 0
        s['legs'] += 1
        s['seconds'] += r.seconds
        s['cpu'] += r.cpu_percent * r.seconds
        s['worst'] = max(s['worst'], worst)
        recovery_kinds = s.setdefault('by_kind', {})
        for kind, gap, _ in r.recoveries:
            if gap is not None:
                recovery_kinds[kind] = max(recovery_kinds.get(kind, 0.0), gap)
    lines += ['', '| stream | legs | sent | published | received | missing | duplicated | '
              'corrupted | faults | longest recovery (s) | node CPU (%) |', '|' + '---|' * 11]
    total = collections_counter()
    for stream in STREAMS:
        s = per_stream.get(stream.name)
        if s is None:
            continue
        cpu = s['cpu'] / s['seconds'] if s['seconds'] else 0.0
        lines.append(f'| {stream.name} | {s["legs"]} | {s["sent"]} | {s["published"]} | '
                     f'{s["received"]} | {s["missing"]} | {s["duplicated"]} | '
                     f'{s["corrupted"]} | {s["events"]} | {s["worst"]:.3f} | {cpu:.1f} |')
        for name in ('legs', 'sent', 'published', 'received', 'missing', 'duplicated',
                     'corrupted', 'events'):
            total[name] += s[name]
        total['worst'] = max(total['worst'], s['worst'])
    lines.append(f'| **all** | {total["legs"]} | {total["sent"]} | {total["published"]} | '
                 f'{total["received"]} | {total["missing"]} | {total["duplicated"]} | '
                 f'{total["corrupted"]} | {total["events"]} | {total["worst"]:.3f} | |')
    kinds: dict[str, float] = {}
    for s in per_stream.values():
        for kind, gap in s.get('by_kind', {}).items():
            kinds[kind] = max(kinds.get(kind, 0.0), gap)
    lines.append('')
    lines.append('longest wait for data after the end of each kind of fault: '
                 + ', '.join(f'{k} {v:.3f} s' for k, v in sorted(kinds.items())))
    expected = eeprom_changes(run.results)
    lines.append(f'EEPROM writes the simulated sensor received: {run.eeprom_writes} (one per '
                 f'change of the divider between legs: {expected})')
    if run.eeprom_writes is not None:
        checks.append(Check('EEPROM written once per change of setting, never otherwise',
                            run.eeprom_writes == expected,
                            f'{run.eeprom_writes} writes of 0xFCA2 received, {expected} changes '
                            f'of data_rate from leg to leg (factory divider {FACTORY_DIVIDER})'))
    lines += ['', *slope_lines, *run.end_lines]
    checks += slope_checks + run.end_checks
    legs_planned = len(run.legs)
    checks.append(Check('every leg ran', len(run.results) == legs_planned,
                        f'{len(run.results)} of {legs_planned} legs'))
    failed = [c for c in checks if not c.ok]
    lines.append('')
    lines.append('Checks failed:' if failed else f'All {len(checks)} checks passed.')
    for c in failed:
        lines.append(f'  FAIL {c.name}: {c.detail}')
    lines.append('')
    lines.append('RESULT: ' + ('PASS' if not failed else f'FAIL ({len(failed)} checks)'))
    return LongSoakResult(checks, '\n'.join(lines))


def eeprom_changes(results: list[LegResult]) -> int:
    """Return how many legs asked for another divider than the sensor had."""
    changes, divider = 0, FACTORY_DIVIDER
    for r in results:
        wanted = divider_for_rate(r.leg.rate_hz)
        changes += wanted != divider
        divider = wanted
    return changes


def collections_counter() -> dict:
    """Return a per-stream accumulator."""
    return collections.defaultdict(int)


def run_long_soak(cfg: LongSoakConfig) -> LongSoakResult:
    """Run the long soak; return its checks and report."""
    soak = LongSoak(cfg)
    return soak.run()
