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
simulated base station (the campaign's faults, ``fault_driver.py``, its line
rate honoured) serves, in turn, *legs* of a few minutes: each leg is one
stream at the highest rate its line budget allows (``data_rate``: the node
writes the divider), the faults of the campaign at seeded random times, a
quiet phase in which the stream must come back, and the checks of the
campaign on what was published (``campaign_verdict.analyse``: matched to the
simulator's truth by exact values).

The legs go round the streams several times. Most legs run a managed node:
one process per stream, started at the beginning and kept to the end, taken
through configure / activate (the leg) / deactivate / cleanup each time its
stream's turn comes, so that every managed process lives the whole run and
its RSS, descriptors and threads can be fitted against time (a leak is a
slope, not a final value: ``process_sampler.py``). Every ``plain_every``-th
leg runs the plain node instead, a fresh process stopped with SIGINT at the
leg's end (shifted by one each round, so that every stream runs on both
kinds). At the end every managed process is taken to a random state and shut
down with SIGINT.

What it counts per leg and stream, and its targets (their limits in
:class:`LongSoakConfig`): ``docs/soak.md``. ``benchmarks/soak.py
--every-stream`` runs it, ``test/test_soak_every_stream.py`` for a minute in CI.

The campaign (:func:`run_campaign`: ``benchmarks/soak.py`` without
``--every-stream``, ``test/test_soak_short.py``) is this run with one plain
leg, its simulator at the campaign's own rate and its checks with the
campaign's settings: the same rig, the same leg, the same verdict.
"""

import bisect
import dataclasses
import itertools
import os
import random
import shutil
import sys
import tempfile
import time
import traceback
from typing import NamedTuple

from harness.campaign import read_counters, Subscriber, TruthCollector
from harness.campaign_verdict import (
    analyse, CampaignConfig, CampaignResult, Check, check_lines, FaultedNodeConfig, rate_text,
    RunData,
)
from harness.fault_driver import FaultDriver, FaultEvent
from harness.instrumented_node import STATS_ENV
from harness.process_sampler import Sampler, slope_per_hour
from harness.processes import (
    isolate_ros_domain, LifecycleClient, NodeProcess, process_cpu_seconds, ros_env,
)
from i3dmgx2_driver.codec import line_budget
from i3dmgx2_driver.codec.data_rate import divider_for_rate, RATE_DIVIDER_ADDRESS
from i3dmgx2_driver.codec.streams import STREAMS
from i3dmgx2_driver.device.timeouts import REQUEST_TIMEOUT
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.eeprom import FACTORY_DIVIDER

BAUD = 115200
#: Seconds a leg takes besides its faults and quiet phase (transitions, draining), roughly.
LEG_OVERHEAD = 15.0
#: What one more try costs the dialogue when a command or its answer is lost: the
#: request's timeout, then the shortest wait for the first record
#: (``SensorDialogue.start_continuous``).
TRY_COST = REQUEST_TIMEOUT + 0.3


# -- the plan ----------------------------------------------------------------------------------

@dataclasses.dataclass
class LongSoakConfig(FaultedNodeConfig):
    """
    How long, how rough, and what counts as a pass.

    The seed, address, node timeouts, fault pacing (the quiet phase: at the
    end of each leg) and log: ``FaultedNodeConfig``.
    """

    #: Length of the whole run (min): legs follow one another until it is over.
    minutes: float = 60.0
    #: Length of each leg's fault phase (min); a quiet phase follows.
    leg_minutes: float = 2.5
    #: How many legs (None: as many as fit in ``minutes``).
    legs: int | None = None
    #: Every this many legs, the plain node runs the leg instead of a managed one (0: never);
    #: shifted by one leg each round of the streams.
    plain_every: int = 3
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


class Leg(NamedTuple):
    """One stream, one node kind, one stretch of faults."""

    number: int
    stream: str
    rate_hz: float
    kind: str


def plan_legs(cfg: LongSoakConfig) -> list[Leg]:
    """Return the legs: the streams in turn, each at its line-budget maximum rate."""
    leg_seconds = cfg.leg_minutes * 60.0 + cfg.quiet + LEG_OVERHEAD
    count = cfg.legs or max(1, round(cfg.minutes * 60.0 / leg_seconds))
    legs = []
    for number in range(count):
        stream = STREAMS[number % len(STREAMS)]
        rate = line_budget.max_rate(stream.code, BAUD, wireless=True)
        # Shifted by one each round of the streams, so that every stream meets both kinds.
        turn = number + number // len(STREAMS)
        plain = cfg.plain_every and (turn + 1) % cfg.plain_every == 0
        # Rounded down to 0.1 Hz: the parameter's text must map to the same divider.
        legs.append(Leg(number, stream.name, int(rate * 10) / 10.0,
                        'plain' if plain else 'managed'))
    return legs


def shared_fields(cfg: FaultedNodeConfig) -> dict:
    """Return what every faulted run shares: ``FaultedNodeConfig``'s fields."""
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(FaultedNodeConfig)}


# -- the node processes ------------------------------------------------------------------------

def topic(namespace: str) -> str:
    """Return the Imu topic of the node in ``namespace``."""
    return f'/{namespace}/imu/raw_data'


def managed_name(stream: str) -> str:
    """Return the namespace of the managed node of ``stream``."""
    return f'soak_{stream}'


def leg_node_name(leg: Leg) -> str:
    """Return the namespace of the node that runs ``leg``."""
    return managed_name(leg.stream) if leg.kind == 'managed' else f'soak_plain_{leg.number}'


def final_stats(path: str, after: float, published: int | None = None) -> dict:
    """Return the node's counters written after ``after`` (with ``published``, if given)."""
    return read_counters(path, lambda got: got.get('time', 0.0) > after and (
        published is None or got.get('stats', {}).get('published') == published), 10.0)


# -- the data back after each fault ------------------------------------------------------------

def recoveries(events: list[FaultEvent], rows: list, truth: list, host_log: list,
               recovery_limit: float) -> list[tuple[str, float | None, float]]:
    """
    For each fault that ends: (kind, seconds to the next message received, the limit).

    The limit is not one number: ``recovery_limit``, plus :data:`TRY_COST`
    for every command the radio lost, stalled or the sensor ignored, and
    every reply the radio dropped, from one try before the fault ended to
    the message: each costs the dialogue one more try, by design. A fault
    followed by the next one before the data came back is left out (the
    recovery was cut short, not slow).
    """
    times = sorted(row[3] for row in rows)
    misses = sorted([h.time for h in host_log
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
        limit = recovery_limit + retries * TRY_COST
        gap = back - event.end if back is not None else None
        out.append((event.kind, gap, limit))
    return out


# -- one leg -----------------------------------------------------------------------------------

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


# -- the report: the tables and every check in one list ----------------------------------------

#: The figures of a leg the tables sum, in their columns' order.
COLUMNS = ('sent', 'published', 'received', 'missing', 'duplicated', 'corrupted', 'events')


def report(soak: 'LongSoak', minutes: float, slope_checks: list[Check],
           slope_lines: list[str]) -> CampaignResult:
    """Build the per-stream and overall table and the list of checks."""
    cfg, results = soak.cfg, soak.results
    lines = ['== i3dmgx2 long soak: every stream, every fault, both node kinds ==',
             f'{minutes:.1f} min, {len(results)} legs of {cfg.leg_minutes:g} min of faults '
             f'+ {cfg.quiet:g} s quiet, seed {cfg.seed}, 115200 baud, wireless; the simulator '
             f'honours the line rate', '',
             '| stream | legs | sent | published | received | missing | duplicated | '
             'corrupted | faults | longest recovery (s) | node CPU (%) |', '|' + '---|' * 11]
    checks = [Check(f'leg {r.leg.number} ({r.leg.kind} {r.leg.stream}): {c.name}', c.ok,
                    c.detail) for r in results for c in r.checks]
    # The longest wait for data after each kind of fault, over every leg.
    kinds: dict[str, float] = {}
    for r in results:
        for kind, gap, _ in r.recoveries:
            if gap is not None:
                kinds[kind] = max(kinds.get(kind, 0.0), gap)
    groups = [(stream.name, [r for r in results if r.leg.stream == stream.name])
              for stream in STREAMS]
    for name, legs in [*groups, ('**all**', results)]:
        if not legs:
            continue
        sums = [sum(r.figures.get(column) or 0 for r in legs) for column in COLUMNS]
        worst = max((g for r in legs for _, g, _ in r.recoveries if g is not None),
                    default=0.0)
        seconds = sum(r.seconds for r in legs)
        cpu = (f'{sum(r.cpu_percent * r.seconds for r in legs) / seconds:.1f}'
               if seconds and legs is not results else '')
        lines.append(f'| {name} | {len(legs)} | ' + ' | '.join(map(str, sums))
                     + f' | {worst:.3f} | {cpu} |')
    lines.append('')
    lines.append('longest wait for data after the end of each kind of fault: '
                 + ', '.join(f'{k} {v:.3f} s' for k, v in sorted(kinds.items())))
    # How many legs asked for another divider than the sensor had.
    dividers = [FACTORY_DIVIDER, *(divider_for_rate(r.leg.rate_hz) for r in results)]
    expected = sum(a != b for a, b in itertools.pairwise(dividers))
    lines.append(f'EEPROM writes the simulated sensor received: {soak.eeprom_writes} (one per '
                 f'change of the divider between legs: {expected})')
    if soak.eeprom_writes is not None:
        checks.append(Check('EEPROM written once per change of setting, never otherwise',
                            soak.eeprom_writes == expected,
                            f'{soak.eeprom_writes} writes of 0xFCA2 received, {expected} changes '
                            f'of data_rate from leg to leg (factory divider {FACTORY_DIVIDER})'))
    checks += slope_checks + soak.end_checks
    checks.append(Check('every leg ran', len(results) == len(soak.legs),
                        f'{len(results)} of {len(soak.legs)} legs'))
    lines += ['', *slope_lines, *soak.end_lines, '', *check_lines(checks, failed_only=True)]
    return CampaignResult(checks, '\n'.join(lines))


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
        lines.append(f'  {name:22s} RSS {_per_hour(rss, "MiB")}, descriptors '
                     f'{_per_hour(fds, "")}, threads {_per_hour(threads, "")}; '
                     f'{len(samples)} samples; first {first}, last {last} '
                     f'(RSS KiB, fds, threads)')
        kinds = [k for k in sampler.kinds.get(key, []) if k[0] >= since]
        if kinds:
            # Not asserted: which memory the slope is (a leak is anonymous).
            per_kind = [slope_per_hour([(k[0], k[i] / 1024.0) for k in kinds])
                        for i in (1, 2, 3)]
            lines.append(f'  {"":22s} RSS by kind: anonymous {_per_hour(per_kind[0], "MiB")}, '
                         f'file-backed {_per_hour(per_kind[1], "MiB")}, shared memory '
                         f'{_per_hour(per_kind[2], "MiB")}; first {kinds[0][1:]}, last '
                         f'{kinds[-1][1:]} (KiB)')
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


# -- the run -----------------------------------------------------------------------------------

class LongSoak:
    """
    The run: start the simulator and the processes, run the legs, end, report.

    The legs run one at a time: a managed leg takes its stream's long-lived
    node through configure / activate / deactivate / cleanup; a plain leg
    starts a fresh node and stops it with SIGINT.
    """

    def __init__(self, cfg: LongSoakConfig, campaign: CampaignConfig | None = None) -> None:
        self.cfg = cfg
        self.campaign = campaign
        self.log = cfg.log or (lambda text: None)
        # The campaign: one plain leg, its stream at its data rate (numbered 1: its faults'
        # seed is the one the campaign always drew).
        self.legs = ([Leg(1, campaign.stream, campaign.data_rate, 'plain')] if campaign
                     else plan_legs(cfg))
        self.sampler = Sampler(cfg.sample_period)
        #: The node processes: the managed ones by stream (each lives the whole run, a plain
        #: node one leg), with their lifecycle clients; each writes its counters to a file of
        #: its own in ``workdir``.
        self.workdir = tempfile.mkdtemp(prefix='i3dmgx2-long-soak-')
        self.managed: dict[str, NodeProcess] = {}
        self.clients: dict[str, LifecycleClient] = {}
        self.sim: PtySimulator | None = None
        self.collector: TruthCollector | None = None
        self.subscriber: Subscriber | None = None
        self.results: list[LegResult] = []
        #: Writes of the rate divider the simulated sensor received (None: the run broke off).
        self.eeprom_writes: int | None = None
        #: The checks and lines of the end: the managed nodes' shutdown, the run broken off.
        self.end_checks: list[Check] = []
        self.end_lines: list[str] = []
        self.rng = random.Random(cfg.seed * 104729 + 3)

    def start(self) -> None:
        """Start the simulator, the subscriber and the managed node processes."""
        cfg = self.cfg
        isolate_ros_domain()
        rate = self.campaign.rate_hz if self.campaign is not None else None
        self.sim = PtySimulator(SimulatorConfig(
            address=cfg.address, seed=cfg.seed, rate_hz=rate, limit_to_line_rate=rate is None,
            truth_limit=int((rate or 400) * 120) + 20000))
        self.sim.start()
        self.collector = TruthCollector(self.sim)
        self.collector.start()
        # A managed node for each stream a managed leg runs (at the rate of its stream).
        managed = {leg.stream: leg.rate_hz for leg in self.legs if leg.kind == 'managed'}
        topics = [topic(managed_name(stream)) for stream in managed]
        topics += [topic(leg_node_name(leg)) for leg in self.legs if leg.kind == 'plain']
        self.subscriber = Subscriber(topics=tuple(topics))
        self.sampler.start()
        for stream, rate in managed.items():
            name = managed_name(stream)
            self.managed[stream] = self.start_node(name, stream, rate, True)
            self.clients[stream] = LifecycleClient(self.subscriber, f'/{name}/i3dmgx2_driver')
        for stream, client in self.clients.items():
            if not client.wait_ready(60.0):
                raise RuntimeError(f'managed node {stream}: lifecycle services not ready:\n'
                                   f'{self.managed[stream].output()[-3000:]}')

    def stats_path(self, name: str) -> str:
        """Return where the node ``name`` writes its counters."""
        return os.path.join(self.workdir, f'{name}.json')

    def start_node(self, name: str, stream: str, rate: float, lifecycle: bool) -> NodeProcess:
        """
        Start the instrumented node (managed with ``lifecycle``) in namespace ``name``.

        Its counters go to a file; it is sampled from now on. Its Imu topic
        is reliable, with a deep history: a message lost on the way to the
        subscriber would read as one the node never published.
        """
        cfg, qos = self.cfg, f'qos_overrides.{topic(name)}.publisher'
        params = {'port': self.sim.port, 'address': cfg.address,
                  'read_timeout': cfg.read_timeout, 'reconnect_interval': cfg.reconnect_interval,
                  f'{qos}.depth': 1000, f'{qos}.reliability': 'reliable',
                  'temperature_period': cfg.temperature_period, 'stream': stream,
                  'data_rate': float(rate)}
        command = (sys.executable, '-m', 'harness.instrumented_node') + (
            ('--lifecycle',) if lifecycle else ())
        node = NodeProcess(params, ('-r', f'__ns:=/{name}'), command=command,
                           env=ros_env({STATS_ENV: self.stats_path(name)}))
        self.sampler.watch(name, node.proc.pid)
        return node

    def shut_down(self) -> None:
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
            self.sampler.forget(managed_name(name))
            ok = alive and code == 0 and seconds < 5.0
            self.end_checks.append(Check(
                f'managed {name}: clean exit on SIGINT from {states[name]}', ok,
                f'alive until the end: {alive}; exit code {code} after {seconds:.2f} s'
                + ('' if ok else f'\n{node.output()[-3000:]}')))

    def close(self) -> None:
        """Stop everything that still runs."""
        steps = [self.sampler.stop, *(node.close for node in self.managed.values())]
        if self.subscriber is not None:
            steps.append(self.subscriber.close)
        if self.collector is not None:
            steps.append(lambda: self.collector.is_alive() and self.collector.stop())
        if self.sim is not None:
            steps.append(self.sim.stop)
        # Each step on its own: a failure in one must not leave a process behind.
        for step in [*steps, lambda: shutil.rmtree(self.workdir, ignore_errors=True)]:
            try:
                step()
            except Exception as exc:  # keep cleaning up; say what went wrong
                print(f'long soak cleanup: {type(exc).__name__}: {exc}', file=sys.stderr)

    def leg_config(self, leg: Leg) -> CampaignConfig:
        """Return the settings the leg is judged by: the campaign's own, or the leg's."""
        if self.campaign is not None:
            return self.campaign
        return CampaignConfig(**dict(shared_fields(self.cfg), log=None),
                              minutes=self.cfg.leg_minutes, rate_hz=None, stream=leg.stream,
                              data_rate=leg.rate_hz, warmup_fraction=0.0)

    def _bring_up(self, leg: Leg, name: str) -> tuple[NodeProcess, LifecycleClient | None]:
        """Configure and activate the stream's managed node, or start a plain one."""
        if leg.kind == 'managed':
            node = self.managed[leg.stream]
            client = self.clients[leg.stream]
            self.sampler.busy.add(name)
            if not client.change('configure'):
                raise RuntimeError(f'leg {leg.number}: configure failed:\n'
                                   f'{node.output()[-3000:]}')
            self.subscriber.wait_publisher(node, topic(name))
            time.sleep(0.5)
            if not client.change('activate'):
                raise RuntimeError(f'leg {leg.number}: activate failed:\n'
                                   f'{node.output()[-3000:]}')
            return node, client
        self.sim.unplug(None)
        node = self.start_node(name, leg.stream, leg.rate_hz, lifecycle=False)
        try:
            self.subscriber.wait_publisher(node, topic(name))
        except BaseException:
            node.close()
            raise
        time.sleep(1.0)
        self.sim.replug()
        return node, None

    def _bring_down(self, name: str, node: NodeProcess, client: LifecycleClient | None,
                    stopped: float) -> tuple[int, float, dict]:
        """Deactivate and clean up a managed node, or SIGINT a plain one; its last counters."""
        path = self.stats_path(name)
        exit_code, exit_seconds = 0, 0.0
        if client is not None:
            client.change('deactivate')
            done = time.time()
            stats = final_stats(path, done)
            published = stats.get('stats', {}).get('published')
            if published is not None:
                self.subscriber.wait_count(published, 15.0)
            stats = final_stats(path, done, published)
            client.change('cleanup')
            time.sleep(0.5)  # the port closed, the threads joined
            self.sampler.first_release.setdefault(name, time.time())
            self.sampler.busy.discard(name)
        else:
            exit_code, exit_seconds = node.stop(timeout=15.0)
            self.sampler.forget(name)
            stats = read_counters(path, lambda got: got.get('final') and got['time'] > stopped,
                                  15.0)
            published = stats.get('stats', {}).get('published')
            if published is not None:
                self.subscriber.wait_count(published, 15.0)
        return exit_code, exit_seconds, stats

    def run_leg(self, leg: Leg) -> LegResult:
        """Bring the leg's node up, fault it, bring it down; analyse what it published."""
        name = leg_node_name(leg)
        self.subscriber.take()
        self.collector.take()
        begin = time.time()
        node, client = self._bring_up(leg, name)
        try:
            return self._run_node(leg, name, node, client, begin)
        finally:
            if client is None:  # a plain node lives one leg: its process and its log go
                node.close()

    def _run_node(self, leg: Leg, name: str, node: NodeProcess, client: LifecycleClient | None,
                  begin: float) -> LegResult:
        """Fault the node brought up at ``begin``, bring it down; judge what it published."""
        cfg, subscriber, judged = self.cfg, self.subscriber, self.leg_config(leg)
        if not subscriber.wait_count(1, 60.0):
            raise RuntimeError(f'leg {leg.number}: no message within 60 s:\n'
                               f'{node.output()[-3000:]}')
        started = time.time()
        cpu_start = process_cpu_seconds(node.proc.pid)
        self.log(f'leg {leg.number}: {leg.kind} node, {rate_text(judged)}, '
                 f'{judged.minutes:g} min of faults')
        driver = FaultDriver(self.sim, random.Random(cfg.seed * 7919 + leg.number),
                             cfg.event_gap)
        driver.start()
        while time.time() < started + judged.minutes * 60.0:
            time.sleep(0.5)
        driver.stop()
        fault_end = time.time()
        before = len(subscriber.rows)
        time.sleep(cfg.quiet)
        recovered = len(subscriber.rows) - before
        alive = node.proc.poll() is None
        cpu = process_cpu_seconds(node.proc.pid) - cpu_start if alive else 0.0
        stopped = time.time()
        exit_code, exit_seconds, stats = self._bring_down(name, node, client, stopped)
        time.sleep(0.3)
        rows = subscriber.take()
        truth, missed = self.collector.take()
        events = [e for e in stats.get('port_events', []) if e[1] >= begin
                  and (leg.kind == 'plain' or e[1] < stopped)]
        stats = dict(stats, port_events=events)
        rss = [(t, kib) for t, kib, _, _ in self.sampler.all_samples.get(name, [])
               if t >= started]
        warmup = max(judged.warmup_min, judged.warmup_fraction * judged.minutes * 60.0)
        with self.sim.lock:
            divider = self.sim.sensor.eeprom.get(RATE_DIVIDER_ADDRESS, 512)
        data = RunData(
            cfg=judged, truth=truth, truth_missed=missed, messages=rows,
            events=list(driver.events), node_stats=stats, sim_stats=self.sim.stats.as_dict(),
            host_log=self.sim.host_log, rss=rss, warmup_end=started + warmup,
            fault_end=fault_end, alive_at_end=alive, exit_code=exit_code,
            exit_seconds=exit_seconds, recovered=recovered,
            unsafe_garbage_bytes=driver.unsafe_garbage_bytes,
            unsafe_garbage_bursts=driver.unsafe_garbage_bursts, divider=divider,
            power_ups=list(driver.power_ups), node_output=node.output()[-5000:],
            started=started, end=stopped if leg.kind == 'managed' else None)
        # Judged: the campaign's checks, and the data back after every fault.
        seconds = stopped - started
        found = recoveries(driver.events, rows, truth, self.sim.host_log, cfg.recovery_limit)
        slow = [(k, g, lim) for k, g, lim in found if g is None or g > lim]
        worst = max((g for _, g, _ in found if g is not None), default=0.0)
        retried = sum(1 for _, _, lim in found if lim > cfg.recovery_limit)
        recovery = Check(
            'data back after every fault that ends', not slow,
            f'{len(found)} faults ended; longest wait for the next message '
            f'{worst:.3f} s (limit {cfg.recovery_limit:g} s, plus {TRY_COST:g} s for '
            f'each command or reply lost or ignored meanwhile: {retried} such)'
            + ('; over: ' + ', '.join(f'{k} {g if g is None else round(g, 3)} (limit '
                                      f'{lim:g})' for k, g, lim in slow[:8])
               if slow else ''))
        # A managed node does not exit at a leg's end (its exit is checked at the run's),
        # and counts as unpublished what it reads while inactive, by design.
        result = analyse(data, exempt=('clean exit on SIGINT', 'nothing left unpublished')
                         if leg.kind == 'managed' else (), more=(recovery,))
        legresult = LegResult(leg, result.checks, result.figures, found,
                              100.0 * cpu / seconds if seconds > 0 else 0.0, seconds,
                              result.report)
        failed = [c.name for c in result.failures()]
        self.log(f'leg {leg.number}: {result.figures.get("published")} published, '
                 f'{result.figures.get("missing")} missing, {len(driver.events)} faults, '
                 f'worst recovery {worst:.3f} s, CPU {legresult.cpu_percent:.1f} %: '
                 + ('PASS' if not failed else 'FAIL ' + ', '.join(failed)))
        if failed:
            self.log(result.report)
        return legresult

    def run(self) -> CampaignResult:
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
            self.shut_down()
        except Exception:  # the run could not go on: a failed check with the reason
            self.end_checks.append(Check('run completed', False, traceback.format_exc()))
        finally:
            minutes = (time.time() - began) / 60.0
            # The managed processes, the ones fitted for leaks: (stream, sampler name).
            managed = [(name, managed_name(name)) for name in sorted(self.managed)]
            slope_checks, slope_lines = fit_slopes(cfg, self.sampler, managed, minutes)
            self.close()
        return report(self, minutes, slope_checks, slope_lines)


def run_campaign(cfg: CampaignConfig) -> CampaignResult:
    """
    Run the campaign: one plain node through ``cfg.minutes`` of faults and a quiet phase.

    The long soak with one plain leg: the simulator streams at the
    campaign's rate (its override, beyond the device; None: the rate the
    node sets, the line's limit honoured), the node's RSS is sampled every
    second, and the leg is judged with the campaign's settings (its warm-up,
    its RSS limit). Returns its checks and printable report.
    """
    soak = LongSoak(LongSoakConfig(**shared_fields(cfg), sample_period=1.0), campaign=cfg)
    try:
        soak.start()
        leg = soak.run_leg(soak.legs[0])
    finally:
        soak.close()
    return CampaignResult(leg.checks, leg.report, leg.figures)
