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

This module runs the whole; the rooms it runs on: ``soak_plan.py`` (the
settings and the legs), ``soak_nodes.py`` (the node processes),
``soak_leg.py`` (one leg), ``soak_recovery.py`` (the data back after a
fault), ``process_sampler.py`` (RSS, descriptors, threads and their slopes),
``soak_report.py`` (the tables and the checks).
"""

import os
import random
import sys
import time
import traceback

from harness.campaign_listener import Subscriber
from harness.campaign_result import Check
from harness.campaign_truth import TruthCollector
from harness.process_sampler import fit_slopes, Sampler
from harness.processes import isolate_ros_domain
from harness.soak_leg import LegRunner, SoakRig
from harness.soak_nodes import leg_node_name, managed_name, SoakNodes, topic
from harness.soak_plan import LongSoakConfig, plan_legs
from harness.soak_report import LongSoakResult, report, SoakRecord
from i3dmgx2_driver.codec.streams import STREAMS
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig


class LongSoak:
    """The run: start the simulator and the processes, run the legs, end, report."""

    def __init__(self, cfg: LongSoakConfig) -> None:
        self.cfg = cfg
        self.log = cfg.log or (lambda text: None)
        self.legs = plan_legs(cfg)
        self.sampler = Sampler(cfg.sample_period)
        self.nodes = SoakNodes(cfg, self.sampler)
        self.sim: PtySimulator | None = None
        self.collector: TruthCollector | None = None
        self.subscriber: Subscriber | None = None
        self.record = SoakRecord(planned=len(self.legs))
        self.rng = random.Random(cfg.seed * 104729 + 3)

    def start(self) -> LegRunner:
        """Start the simulator, the subscriber and the managed node processes."""
        cfg = self.cfg
        isolate_ros_domain()
        self.sim = PtySimulator(SimulatorConfig(
            address=cfg.address, seed=cfg.seed, rate_hz=None, limit_to_line_rate=True,
            truth_limit=400 * 120 + 20000))
        self.sim.start()
        self.nodes.port = self.sim.port
        self.collector = TruthCollector(self.sim)
        self.collector.start()
        kinds = {leg.stream for leg in self.legs if leg.kind == 'managed'}
        topics = [topic(managed_name(s.name)) for s in STREAMS if s.name in kinds]
        topics += [topic(leg_node_name(leg)) for leg in self.legs if leg.kind == 'plain']
        self.subscriber = Subscriber(topics=tuple(topics))
        self.sampler.start()
        self.nodes.start_managed(self.legs, self.subscriber)
        return LegRunner(cfg, SoakRig(self.sim, self.collector, self.subscriber, self.sampler,
                                      self.nodes), self.log)

    def close(self) -> None:
        """Stop everything that still runs."""
        steps = [self.sampler.stop]
        steps += self.nodes.closers()
        if self.subscriber is not None:
            steps.append(self.subscriber.close)
        if self.collector is not None:
            steps.append(lambda: self.collector.is_alive() and self.collector.stop())
        if self.sim is not None:
            steps.append(self.sim.stop)
        steps.append(self.nodes.remove_workdir)
        for step in steps:
            try:
                step()
            except Exception as exc:  # keep cleaning up; say what went wrong
                print(f'long soak cleanup: {type(exc).__name__}: {exc}', file=sys.stderr)

    def run(self) -> LongSoakResult:
        """Run every leg, then the end; return the verdict and the report."""
        cfg, record = self.cfg, self.record
        began = time.time()
        try:
            runner = self.start()
            self.log(f'long soak: {len(self.legs)} legs over {cfg.minutes:g} min, domain '
                     f'{os.environ.get("ROS_DOMAIN_ID")}, seed {cfg.seed}')
            for leg in self.legs:
                record.results.append(runner.run(leg))
            record.eeprom_writes = len(self.sim.eeprom_writes())
            checks, lines = self.nodes.shut_down(self.rng)
            record.end_checks += checks
            record.end_lines += lines
        except Exception:  # the run could not go on: a failed check with the reason
            record.end_checks.append(Check('run completed', False, traceback.format_exc()))
        finally:
            minutes = (time.time() - began) / 60.0
            slope_checks, slope_lines = fit_slopes(cfg, self.sampler,
                                                   self.nodes.slope_processes(), minutes)
            self.close()
        return report(cfg, record, minutes, slope_checks, slope_lines)


def run_long_soak(cfg: LongSoakConfig) -> LongSoakResult:
    """Run the long soak; return its checks and report."""
    soak = LongSoak(cfg)
    return soak.run()
