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
The soak and fault campaign: the real node against a simulator that misbehaves.

The node runs as its own process (``harness/instrumented_node.py``: the
real node, with its counters written to a file) on a simulated base station
whose faults change at random all through the run: line noise (garbage, with
and without 0xAA bytes), corrupted checksums and lengths, packets from a
foreign sensor, radio drops and lost commands, jitter, stalls short and long,
unplug and replug, sensor power cycles (streaming again at once, or not), the
sensor ignoring its first request to stream or wanting a polled request
first. A real rclpy subscriber (reliable, deep history) records what the
node publishes. Afterwards every published message is matched, by its exact
values, to the simulator's ground truth, and the node's counters are
reconciled with what the simulator wrote.

Used by ``benchmarks/soak.py`` (ten minutes) and ``test/test_soak_short.py``
(about half a minute in CI). :func:`run_campaign` does everything and returns
the checks and a printable report; the rules are stated in the report.

Its pieces, one room each: the settings (``campaign_config.py``), the faults
(``fault_driver.py``), the truth (``campaign_truth.py``), the subscriber
(``campaign_listener.py``), what a run produced (``campaign_data.py``) and
the analysis (``campaign_analysis.py``). Here: the run itself, set up, run
through its fault and quiet phases, and collected.
"""

from collections.abc import Callable
import json
import os
import random
import shutil
import sys
import tempfile
import time
from typing import NamedTuple

from harness.campaign_analysis import analyse
from harness.campaign_config import CampaignConfig, rate_text
from harness.campaign_data import RunData
from harness.campaign_listener import Subscriber
from harness.campaign_result import CampaignResult
from harness.campaign_truth import TruthCollector
from harness.fault_driver import FaultDriver
from harness.instrumented_node import STATS_ENV
from harness.processes import isolate_ros_domain, NodeProcess, ros_env
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig

NODE_COMMAND = (sys.executable, '-m', 'harness.instrumented_node')


def read_rss_kib(pid: int) -> int | None:
    """Return the VmRSS of a process (KiB), None if it is gone."""
    try:
        with open(f'/proc/{pid}/status') as handle:
            for line in handle:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def read_json(path: str) -> dict | None:
    """Return a node's counters file, None while it is missing or half written."""
    try:
        with open(path) as handle:
            return json.load(handle)
    except (OSError, ValueError):
        return None


class Rig(NamedTuple):
    """What a campaign runs on: the simulator and its truth, the listener, the node, the faults."""

    sim: PtySimulator
    collector: TruthCollector
    subscriber: Subscriber
    node: NodeProcess
    driver: FaultDriver
    workdir: str
    stats_path: str


class Timeline(NamedTuple):
    """When the stream began, the warm-up ended and the faults were to end (wall clock)."""

    started: float
    warmup_end: float
    fault_end: float


def run_campaign(cfg: CampaignConfig) -> CampaignResult:
    """Run the whole campaign; return its checks and report."""
    log = cfg.log or (lambda text: None)
    rig = set_up(cfg)
    rss: list[tuple[float, int]] = []
    try:
        wait_for_stream(rig)
        timeline = fault_phase(rig, cfg, log, rss)
        recovered = quiet_phase(rig, cfg, rss)
        data = collect(rig, cfg, timeline, rss, recovered)
    finally:
        clean_up(rig)
    return analyse(data)


def set_up(cfg: CampaignConfig) -> Rig:
    """Start the simulator (unplugged), the truth collector, the subscriber and the node."""
    isolate_ros_domain()
    workdir = tempfile.mkdtemp(prefix='i3dmgx2-soak-')
    stats_path = os.path.join(workdir, 'node_stats.json')
    sim = PtySimulator(SimulatorConfig(
        address=cfg.address, seed=cfg.seed, rate_hz=cfg.rate_hz,
        limit_to_line_rate=cfg.rate_hz is None,
        truth_limit=int((cfg.rate_hz or 400.0) * 60) + 20000))
    sim.start()
    # The port is missing until the subscriber has matched the node's publisher:
    # nothing published can then be lost in discovery, and the node starts by
    # retrying to open a port that is not there.
    sim.unplug(None)
    collector = TruthCollector(sim)
    collector.start()
    subscriber = Subscriber()
    params = {'port': sim.port, 'address': cfg.address, 'read_timeout': cfg.read_timeout,
              'reconnect_interval': cfg.reconnect_interval,
              'qos_overrides./imu/raw_data.publisher.depth': 1000,
              'qos_overrides./imu/raw_data.publisher.reliability': 'reliable',
              'temperature_period': cfg.temperature_period,
              'stream': cfg.stream, 'data_rate': float(cfg.data_rate)}
    node = NodeProcess(params, command=NODE_COMMAND, env=ros_env({STATS_ENV: stats_path}))
    driver = FaultDriver(sim, cfg, random.Random(cfg.seed * 7919 + 1))
    return Rig(sim, collector, subscriber, node, driver, workdir, stats_path)


def wait_for_stream(rig: Rig) -> None:
    """Plug the port in once the subscriber sees the node; wait for the first message."""
    subscriber, node = rig.subscriber, rig.node
    deadline = time.monotonic() + 60.0
    while subscriber.publishers() < 1 and time.monotonic() < deadline:
        if node.proc.poll() is not None:
            raise RuntimeError(f'the node exited at start:\n{node.output()}')
        time.sleep(0.1)
    time.sleep(1.0)
    rig.sim.replug()
    deadline = time.monotonic() + 60.0
    while subscriber.count == 0 and time.monotonic() < deadline:
        time.sleep(0.1)
    if subscriber.count == 0:
        raise RuntimeError(f'no message within 60 s:\n{node.output()}')


def sample_rss(pid: int, rss: list[tuple[float, int]]) -> int | None:
    """Add the node's RSS now to ``rss``; return it (None if the process is gone)."""
    sample = read_rss_kib(pid)
    if sample is not None:
        rss.append((time.time(), sample))
    return sample


def fault_phase(rig: Rig, cfg: CampaignConfig, log: Callable[[str], None],
                rss: list[tuple[float, int]]) -> Timeline:
    """Inject faults for the run's minutes, sampling the node's RSS every second."""
    node, driver = rig.node, rig.driver
    duration = cfg.minutes * 60.0
    started = time.time()
    log(f'streaming; domain {os.environ.get("ROS_DOMAIN_ID")}, node pid {node.proc.pid}, '
        f'{cfg.minutes:g} min of faults at {rate_text(cfg)}, seed {cfg.seed}')
    warmup_end = started + max(cfg.warmup_min, cfg.warmup_fraction * duration)
    fault_end = started + duration
    driver.start()
    next_report = started + 60.0
    while time.time() < fault_end and node.proc.poll() is None:
        sample = sample_rss(node.proc.pid, rss)
        if time.time() >= next_report:
            next_report += 60.0
            log(f'  {time.time() - started:5.0f} s: {rig.subscriber.count} messages, '
                f'{len(driver.events)} fault events, RSS {sample} KiB')
        time.sleep(1.0)
    return Timeline(started, warmup_end, fault_end)


def quiet_phase(rig: Rig, cfg: CampaignConfig, rss: list[tuple[float, int]]) -> int:
    """Switch every fault off; return how many messages came in the quiet phase."""
    rig.driver.stop()
    before = rig.subscriber.count
    quiet_end = time.time() + cfg.quiet
    while time.time() < quiet_end and rig.node.proc.poll() is None:
        sample_rss(rig.node.proc.pid, rss)
        time.sleep(0.5)
    return rig.subscriber.count - before


def collect(rig: Rig, cfg: CampaignConfig, timeline: Timeline,
            rss: list[tuple[float, int]], recovered: int) -> RunData:
    """Stop the node; wait for its final counters and its last messages; gather the run."""
    sim, node, driver, subscriber = rig.sim, rig.node, rig.driver, rig.subscriber
    alive = node.proc.poll() is None
    exit_code, exit_seconds = node.stop(timeout=15.0)
    final = final_counters(rig.stats_path)
    published = final.get('stats', {}).get('published')
    deadline = time.monotonic() + 15.0
    while published is not None and subscriber.count < published \
            and time.monotonic() < deadline:
        time.sleep(0.1)
    rig.collector.stop()
    return RunData(
        cfg=cfg, truth=rig.collector.entries, truth_missed=rig.collector.missed,
        messages=list(subscriber.rows), events=list(driver.events), node_stats=final,
        sim_stats=sim.stats.as_dict(), host_log=sim.host_log, rss=rss,
        warmup_end=timeline.warmup_end, fault_end=timeline.fault_end, alive_at_end=alive,
        exit_code=exit_code, exit_seconds=exit_seconds, recovered=recovered,
        unsafe_garbage_bytes=driver.unsafe_garbage_bytes,
        unsafe_garbage_bursts=driver.unsafe_garbage_bursts,
        divider=sim.sensor.eeprom.get(0xFCA2, 512), power_ups=list(driver.power_ups),
        node_output=node.output(),
        started=timeline.started)


def final_counters(stats_path: str) -> dict:
    """Return the node's counters as it wrote them at its exit (waiting up to 5 s for them)."""
    final = None
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        final = read_json(stats_path)
        if final and final.get('final'):
            break
        time.sleep(0.1)
    return final or {}


def clean_up(rig: Rig) -> None:
    """Stop everything, each step on its own: a failure in one must not leave the node behind."""
    driver, collector = rig.driver, rig.collector
    for step in (lambda: driver.is_alive() and driver.stop(), rig.node.close,
                 rig.subscriber.close, lambda: collector.is_alive() and collector.stop(),
                 rig.sim.stop, lambda: shutil.rmtree(rig.workdir, ignore_errors=True)):
        try:
            step()
        except Exception as exc:  # keep cleaning up; say what went wrong
            print(f'soak cleanup: {type(exc).__name__}: {exc}', file=sys.stderr)
