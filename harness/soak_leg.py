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
One leg of the long soak: bring the leg's node up, fault it, bring it down, judge it.

A managed leg takes its stream's long-lived node through configure /
activate / deactivate / cleanup; a plain leg starts a fresh node and stops
it with SIGINT. What was published is then judged by the campaign's checks
(``campaign_analysis.analyse``) and by the recoveries (``soak_recovery.py``).
"""

from collections.abc import Callable
import random
import time
from typing import NamedTuple

from harness.campaign_analysis import analyse
from harness.campaign_config import CampaignConfig
from harness.campaign_data import RunData
from harness.campaign_listener import Subscriber
from harness.campaign_result import Check
from harness.campaign_truth import TruthCollector
from harness.fault_driver import FaultDriver
from harness.process_sampler import Sampler
from harness.processes import LifecycleClient, NodeProcess, process_cpu_seconds
from harness.soak_nodes import final_stats, leg_node_name, SoakNodes, topic
from harness.soak_plan import Leg, LongSoakConfig
from harness.soak_recovery import recoveries, TRY_COST
from i3dmgx2_driver.codec.data_rate import RATE_DIVIDER_ADDRESS
from i3dmgx2_driver.simulator import PtySimulator


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


class SoakRig(NamedTuple):
    """What every leg runs on: the simulator and its truth, the listener, the processes."""

    sim: PtySimulator
    collector: TruthCollector
    subscriber: Subscriber
    sampler: Sampler
    nodes: SoakNodes


class LegRunner:
    """Run the legs one at a time on one rig."""

    def __init__(self, cfg: LongSoakConfig, rig: SoakRig, log: Callable[[str], None]) -> None:
        self.cfg = cfg
        self.rig = rig
        self.log = log

    # -- what the listener and the simulator gathered ----------------------------------------

    def _wait_publisher(self, name: str, node: NodeProcess, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while self.rig.subscriber.node.count_publishers(topic(name)) < 1:
            if node.proc.poll() is not None:
                raise RuntimeError(f'the node exited:\n{node.output()[-3000:]}')
            if time.monotonic() > deadline:
                raise RuntimeError(f'no publisher of {topic(name)} within {timeout:g} s')
            time.sleep(0.1)

    def _wait_messages(self, count: int, timeout: float) -> bool:
        subscriber = self.rig.subscriber
        deadline = time.monotonic() + timeout
        while subscriber.count < count and time.monotonic() < deadline:
            time.sleep(0.05)
        return subscriber.count >= count

    def _take_rows(self) -> list:
        subscriber = self.rig.subscriber
        rows, subscriber.rows = subscriber.rows, []
        return rows

    def _take_truth(self) -> tuple[list, int]:
        collector = self.rig.collector
        collector.collect()
        with collector._lock:
            entries, collector.entries = collector.entries, []
            missed, collector.missed = collector.missed, 0
        return entries, missed

    # -- the node up and down ----------------------------------------------------------------

    def _bring_up(self, leg: Leg, name: str) -> tuple[NodeProcess, LifecycleClient | None]:
        """Configure and activate the stream's managed node, or start a plain one."""
        rig = self.rig
        if leg.kind == 'managed':
            node = rig.nodes.managed[leg.stream]
            client = rig.nodes.clients[leg.stream]
            rig.sampler.busy.add(name)
            if not client.change('configure'):
                raise RuntimeError(f'leg {leg.number}: configure failed:\n'
                                   f'{node.output()[-3000:]}')
            self._wait_publisher(name, node)
            time.sleep(0.5)
            if not client.change('activate'):
                raise RuntimeError(f'leg {leg.number}: activate failed:\n'
                                   f'{node.output()[-3000:]}')
            return node, client
        rig.sim.unplug(None)
        node = rig.nodes.start_node(name, leg.stream, leg.rate_hz, lifecycle=False)
        try:
            self._wait_publisher(name, node)
        except BaseException:
            node.close()
            raise
        time.sleep(1.0)
        rig.sim.replug()
        return node, None

    def _bring_down(self, name: str, node: NodeProcess, client: LifecycleClient | None,
                    stopped: float) -> tuple[int, float, dict]:
        """Deactivate and clean up a managed node, or SIGINT a plain one; its last counters."""
        rig = self.rig
        path = rig.nodes.stats_path(name)
        exit_code, exit_seconds = 0, 0.0
        if client is not None:
            client.change('deactivate')
            done = time.time()
            stats = final_stats(path, done)
            published = stats.get('stats', {}).get('published')
            if published is not None:
                self._wait_messages(published, 15.0)
            stats = final_stats(path, done, published)
            client.change('cleanup')
            time.sleep(0.5)  # the port closed, the threads joined
            rig.sampler.first_release.setdefault(name, time.time())
            rig.sampler.busy.discard(name)
        else:
            exit_code, exit_seconds = node.stop(timeout=15.0)
            rig.sampler.forget(name)
            stats = final_stats(path, stopped)
            if not stats.get('final'):
                stats = final_stats(path, stopped, timeout=5.0)
            published = stats.get('stats', {}).get('published')
            if published is not None:
                self._wait_messages(published, 15.0)
        return exit_code, exit_seconds, stats

    def _faults(self, leg: Leg, started: float) -> FaultDriver:
        """Run the fault phase of a leg; return the driver (its events)."""
        cfg = self.cfg
        campaign = CampaignConfig(event_gap=cfg.event_gap, long_stalls=True, log=None)
        driver = FaultDriver(self.rig.sim, campaign, random.Random(cfg.seed * 7919 + leg.number))
        driver.start()
        end = started + cfg.leg_minutes * 60.0
        while time.time() < end:
            time.sleep(0.5)
        driver.stop()
        return driver

    # -- the leg -----------------------------------------------------------------------------

    def run(self, leg: Leg) -> LegResult:
        """Bring the leg's node up, fault it, bring it down; analyse what it published."""
        name = leg_node_name(leg)
        self._take_rows()
        self._take_truth()
        begin = time.time()
        node, client = self._bring_up(leg, name)
        try:
            return self._run_node(leg, name, node, client, begin)
        finally:
            if client is None:  # a plain node lives one leg: its process and its log go
                node.close()

    def _run_node(self, leg: Leg, name: str, node: NodeProcess, client: LifecycleClient | None,
                  begin: float) -> LegResult:
        """Fault the node brought up at ``begin``, bring it down; analyse what it published."""
        cfg, sim, subscriber = self.cfg, self.rig.sim, self.rig.subscriber
        if not self._wait_messages(1, 60.0):
            raise RuntimeError(f'leg {leg.number}: no message within 60 s:\n'
                               f'{node.output()[-3000:]}')
        started = time.time()
        cpu_start = process_cpu_seconds(node.proc.pid)
        self.log(f'leg {leg.number}: {leg.kind} node, stream {leg.stream} at {leg.rate_hz:g} '
                 f'Hz, {cfg.leg_minutes:g} min of faults')
        driver = self._faults(leg, started)
        fault_end = time.time()
        before = subscriber.count
        time.sleep(cfg.quiet)
        recovered = subscriber.count - before
        alive = node.proc.poll() is None
        cpu = process_cpu_seconds(node.proc.pid) - cpu_start if alive else 0.0
        stopped = time.time()
        exit_code, exit_seconds, stats = self._bring_down(name, node, client, stopped)
        time.sleep(0.3)
        rows = self._take_rows()
        truth, missed = self._take_truth()
        events = [e for e in stats.get('port_events', []) if e[1] >= begin
                  and (leg.kind == 'plain' or e[1] < stopped)]
        stats = dict(stats, port_events=events)
        with sim.lock:
            divider = sim.sensor.eeprom.get(RATE_DIVIDER_ADDRESS, 512)
        rss = [(t, kib) for t, kib, _, _ in self.rig.sampler.all_samples.get(name, [])
               if t >= started]
        data = RunData(
            cfg=CampaignConfig(minutes=cfg.leg_minutes, rate_hz=None, stream=leg.stream,
                               data_rate=leg.rate_hz, seed=cfg.seed, address=cfg.address,
                               read_timeout=cfg.read_timeout,
                               reconnect_interval=cfg.reconnect_interval,
                               quiet=cfg.quiet, temperature_period=cfg.temperature_period,
                               warmup_min=10.0, log=None),
            truth=truth, truth_missed=missed, messages=rows, events=list(driver.events),
            node_stats=stats, sim_stats=sim.stats.as_dict(), host_log=sim.host_log,
            rss=rss, warmup_end=started + 10.0, fault_end=fault_end, alive_at_end=alive,
            exit_code=exit_code, exit_seconds=exit_seconds, recovered=recovered,
            unsafe_garbage_bytes=driver.unsafe_garbage_bytes,
            unsafe_garbage_bursts=driver.unsafe_garbage_bursts, divider=divider,
            power_ups=list(driver.power_ups), node_output=node.output()[-5000:],
            started=started, end=stopped if leg.kind == 'managed' else None)
        return self._verdict(leg, data, driver, cpu, stopped - started)

    def _verdict(self, leg: Leg, data: RunData, driver: FaultDriver, cpu: float,
                 seconds: float) -> LegResult:
        """Judge the leg: the campaign's checks, and the data back after every fault."""
        cfg = self.cfg
        # A managed node does not exit at a leg's end (its exit is checked at the run's),
        # and counts as unpublished what it reads while inactive, by design.
        result = analyse(data, exempt=('clean exit on SIGINT', 'nothing left unpublished')
                         if leg.kind == 'managed' else ())
        checks = list(result.checks)
        found = recoveries(driver.events, data.messages, data.truth, self.rig.sim.host_log,
                           cfg.recovery_limit, self.log)
        slow = [(k, g, lim) for k, g, lim in found if g is None or g > lim]
        worst = max((g for _, g, _ in found if g is not None), default=0.0)
        retried = sum(1 for _, _, lim in found if lim > cfg.recovery_limit)
        checks.append(Check(
            'data back after every fault that ends', not slow,
            f'{len(found)} faults ended; longest wait for the next message '
            f'{worst:.3f} s (limit {cfg.recovery_limit:g} s, plus {TRY_COST:g} s for '
            f'each command or reply lost or ignored meanwhile: {retried} such)'
            + ('; over: ' + ', '.join(f'{k} {g if g is None else round(g, 3)} (limit '
                                      f'{lim:g})' for k, g, lim in slow[:8])
               if slow else '')))
        legresult = LegResult(leg, checks, result.figures, found,
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
