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
The node processes of the long soak: started, parameterised, shut down.

The managed nodes live the whole run (one per stream), a plain node lives
one leg; each writes its counters to a file of its own in the run's working
folder (``instrumented_node.py``). Kept apart from the legs so that how a
node is started and stopped has one home.
"""

import os
import random
import shutil
import sys
import tempfile
import time

from harness.campaign import read_json
from harness.campaign_result import Check
from harness.instrumented_node import STATS_ENV
from harness.process_sampler import Sampler
from harness.processes import LifecycleClient, Listener, NodeProcess, ros_env
from harness.soak_plan import Leg, LongSoakConfig
from i3dmgx2_driver.codec.streams import STREAMS

NODE_MODULE = (sys.executable, '-m', 'harness.instrumented_node')


def topic(namespace: str) -> str:
    """Return the Imu topic of the node in ``namespace``."""
    return f'/{namespace}/imu/raw_data'


def managed_name(stream: str) -> str:
    """Return the namespace of the managed node of ``stream``."""
    return f'soak_{stream}'


def leg_node_name(leg: Leg) -> str:
    """Return the namespace of the node that runs ``leg``."""
    return managed_name(leg.stream) if leg.kind == 'managed' else f'soak_plain_{leg.number}'


def final_stats(path: str, after: float, published: int | None = None,
                timeout: float = 10.0) -> dict:
    """Return the node's counters written after ``after`` (with ``published``, if given)."""
    deadline = time.monotonic() + timeout
    got: dict = {}
    while time.monotonic() < deadline:
        got = read_json(path) or {}
        if got.get('time', 0.0) > after and (
                published is None or got.get('stats', {}).get('published') == published):
            break
        time.sleep(0.1)
    return got


class SoakNodes:
    """The node processes: the managed ones by stream, with their lifecycle clients."""

    def __init__(self, cfg: LongSoakConfig, sampler: Sampler) -> None:
        self.cfg = cfg
        self.sampler = sampler
        self.workdir = tempfile.mkdtemp(prefix='i3dmgx2-long-soak-')
        #: The simulator's port, once it runs.
        self.port: str | None = None
        self.managed: dict[str, NodeProcess] = {}
        self.clients: dict[str, LifecycleClient] = {}

    def _params(self, name: str, leg_stream: str, rate: float) -> dict:
        cfg = self.cfg
        qos = f'qos_overrides.{topic(name)}.publisher'
        return {'port': self.port, 'address': cfg.address,
                'read_timeout': cfg.read_timeout, 'reconnect_interval': cfg.reconnect_interval,
                f'{qos}.depth': 1000, f'{qos}.reliability': 'reliable',
                'temperature_period': cfg.temperature_period, 'stream': leg_stream,
                'data_rate': rate}

    def stats_path(self, name: str) -> str:
        """Return where the node ``name`` writes its counters."""
        return os.path.join(self.workdir, f'{name}.json')

    def start_node(self, name: str, stream: str, rate: float, lifecycle: bool) -> NodeProcess:
        """Start a node process in namespace ``name``; sample it from now on."""
        command = NODE_MODULE + (('--lifecycle',) if lifecycle else ())
        node = NodeProcess(self._params(name, stream, rate), extra_args=['-r', f'__ns:=/{name}'],
                           command=command,
                           env=ros_env({STATS_ENV: self.stats_path(name)}))
        self.sampler.watch(name, node.proc.pid, self.stats_path(name))
        return node

    def start_managed(self, legs: list[Leg], listener: Listener) -> None:
        """Start a managed node for each stream a managed leg runs; wait for its services."""
        kinds = {leg.stream for leg in legs if leg.kind == 'managed'}
        for stream in STREAMS:
            if stream.name not in kinds:
                continue
            rate = next(leg.rate_hz for leg in legs if leg.stream == stream.name)
            name = managed_name(stream.name)
            self.managed[stream.name] = self.start_node(name, stream.name, rate, True)
            self.clients[stream.name] = LifecycleClient(listener, f'/{name}/i3dmgx2_driver')
        for stream, client in self.clients.items():
            if not client.wait_ready(60.0):
                raise RuntimeError(f'managed node {stream}: lifecycle services not ready:\n'
                                   f'{self.managed[stream].output()[-3000:]}')

    def shut_down(self, rng: random.Random) -> tuple[list[Check], list[str]]:
        """Take the managed nodes to random states, then SIGINT them; check their exits."""
        checks: list[Check] = []
        lines: list[str] = []
        if not self.managed:
            return checks, lines
        names = sorted(self.managed)
        chosen = rng.choice(names)
        target = rng.choice(('unconfigured', 'inactive', 'active'))
        steps = {'unconfigured': (), 'inactive': ('configure',),
                 'active': ('configure', 'activate')}[target]
        reached = all(self.clients[chosen].change(step) for step in steps)
        states = {name: (target if name == chosen else 'unconfigured') for name in names}
        lines.append(f'shutdown: {chosen} taken to {target} '
                     f'({"reached" if reached else "NOT reached"}), the others '
                     f'unconfigured; then SIGINT to every managed process')
        for name in names:
            node = self.managed[name]
            alive = node.proc.poll() is None
            code, seconds = node.stop(timeout=15.0)
            self.sampler.forget(managed_name(name))
            ok = alive and code == 0 and seconds < 5.0
            checks.append(Check(
                f'managed {name}: clean exit on SIGINT from {states[name]}', ok,
                f'alive until the end: {alive}; exit code {code} after {seconds:.2f} s'
                + ('' if ok else f'\n{node.output()[-3000:]}')))
        return checks, lines

    def slope_processes(self) -> list[tuple[str, str]]:
        """Return (stream, sampler name) of each managed process: the ones fitted for leaks."""
        return [(name, managed_name(name)) for name in sorted(self.managed)]

    def closers(self) -> list:
        """Return the steps that end every managed process still running."""
        return [node.close for node in self.managed.values()]

    def remove_workdir(self) -> None:
        """Remove the counters' folder."""
        shutil.rmtree(self.workdir, ignore_errors=True)
