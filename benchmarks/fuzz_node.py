#!/usr/bin/env python3
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
Fuzz the running node through its port: a hostile base station, end to end.

The node process opens the port of a :class:`~harness.hostile.HostileStation`
in front of a simulated base station. Round after round an attack is armed
for one phase of the dialogue (quiet, identity, data rate, continuous mode,
streaming, shutdown); to meet the start-up phases again the node is
restarted (a full dialogue) or its port pulled out (a reconnect). All the
time, checked: the node process lives and answers a parameter request
within its period, ``/diagnostics`` keeps coming, nothing is published that
the bytes it was given did not hold as a valid packet from its address,
every real record of its stream forwarded whole while the station behaved
is published, the stream comes back once the station behaves, and a SIGINT
during an attack ends the process cleanly. Each finding keeps the bytes
the node was given just before it, for a regression test. Prints the
duration, packets, inputs per second and findings; exits 1 on any finding.
For 30 minutes and at least a million packets:

    python benchmarks/fuzz_node.py --minutes 30 --packets 1000000 --seed 1
"""

import argparse
from collections import Counter
import dataclasses
import os
from pathlib import Path
import random
import signal
import sys
import threading
import time
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402, RUF100 - after the path
from harness.campaign import message_key, VALUES  # noqa: E402, RUF100
from harness.campaign_verdict import RunConfig  # noqa: E402, RUF100
from harness.hostile import Attack, HostileStation, MODES, PHASES  # noqa: E402, RUF100
from harness.processes import (  # noqa: E402, RUF100
    BENCHMARK_DOMAINS, isolate_ros_domain, Listener, NodeProcess, reserve_ros_domain, wait_done,
)
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig  # noqa: E402, RUF100
from rcl_interfaces.srv import GetParameters  # noqa: E402, RUF100
from sensor_msgs.msg import Imu  # noqa: E402, RUF100


@dataclasses.dataclass
class FuzzConfig(RunConfig):
    """How long, how fast, how rough (the seed, address and log: ``RunConfig``)."""

    minutes: float = 30.0
    #: Stop once this many packets went through the station (0: only the minutes count).
    packets: int = 0
    #: The simulator's rate (its override, the line not limited: packets per second).
    rate_hz: float = 600.0
    #: Longest attack (s); each lasts between a tenth of it and it.
    attack_max: float = 3.0
    #: The stream must be back within this long after the station behaves again (s).
    back_within: float = 10.0
    #: A parameter request must be answered within this long (s).
    answer_within: float = 2.0
    #: /diagnostics must not pause longer than this (s) (its period is 1 s).
    diagnostics_gap: float = 3.0
    #: Share of rounds that restart the node (a full start-up dialogue).
    restart_share: float = 0.3


@dataclasses.dataclass
class Finding:
    """Something the node must not do, with when and the bytes before it."""

    kind: str
    time: float
    detail: str
    evidence: bytes = b''


class Watch(Listener):
    """The published Imu values and /diagnostics times; a parameter client."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, bytes]] = []
        self.diagnostics: list[float] = []
        super().__init__({'imu/raw_data': Imu, '/diagnostics': DiagnosticArray}, depth=5000)
        self.params = self.node.create_client(GetParameters, '/i3dmgx2_driver/get_parameters')

    def _store(self, topic: str, msg: Any) -> None:
        if topic == '/diagnostics':
            self.diagnostics.append(time.time())
            return
        self.rows.append((time.time(), message_key(msg)))

    def ask(self, timeout: float) -> bool:
        """Ask the node for a parameter; return whether it answered within ``timeout``."""
        if not self.params.service_is_ready():
            return False
        future = self.params.call_async(GetParameters.Request(names=['address']))
        if not wait_done(future, timeout):
            self.params.remove_pending_request(future)
            return False
        return True


class NodeFuzz:
    """One run: the simulator, the station, the node, the rounds and the watchers."""

    def __init__(self, cfg: FuzzConfig) -> None:
        self.cfg = cfg
        self.rng = random.Random(cfg.seed)
        self.findings: list[Finding] = []
        self.node: NodeProcess | None = None
        self.restarts = 0
        self._halt = threading.Event()

    def _find(self, kind: str, detail: str, t: float | None = None) -> None:
        t = time.time() if t is None else t
        self.findings.append(Finding(kind, t, detail, self.station.evidence(t)))

    def _start_node(self) -> None:
        self.node = NodeProcess({'port': self.station.path, 'address': self.cfg.address,
                                 'read_timeout': 0.3, 'reconnect_interval': 0.2,
                                 'qos_overrides./imu/raw_data.publisher.depth': 1000,
                                 'data_rate': 100.0})
        self.restarts += 1

    def _stop_node(self, during: str) -> None:
        node = self.node
        alive = node.proc.poll() is None
        code, seconds = node.stop(signal.SIGINT, timeout=10.0)
        if not alive:
            self._find('died', f'the node process had exited ({code}) before the SIGINT '
                               f'{during}: {node.output()[-2000:]}')
        elif code != 0 or seconds > 5.0:
            self._find('unclean exit', f'SIGINT {during}: exit code {code} after '
                                       f'{seconds:.2f} s: {node.output()[-2000:]}')
        node.close()
        self.node = None

    def _restart_node(self, during: str) -> None:
        """Stop the node with a SIGINT and start it again, liveness unchecked meanwhile."""
        self._quiet_until = time.time() + 30.0
        self._stop_node(during)
        self._start_node()
        self._quiet_until = time.time() + 8.0

    def _liveness(self) -> None:
        """Ask for a parameter every second; watch /diagnostics; note a dead process."""
        while not self._halt.wait(1.0):
            node = self.node
            if node is None or time.time() < self._quiet_until:
                continue
            if node.proc.poll() is not None:
                self._find('died', f'exit code {node.proc.returncode}: '
                                   f'{node.output()[-2000:]}')
                self.node = None
                continue
            if not self.watch.ask(self.cfg.answer_within):
                self._find('hang', f'no answer to a parameter request within '
                                   f'{self.cfg.answer_within:g} s')
            last = self.watch.diagnostics[-1] if self.watch.diagnostics else 0.0
            if last and time.time() - last > self.cfg.diagnostics_gap:
                self._find('hang', f'no /diagnostics for {time.time() - last:.1f} s')

    def _wait_stream(self, after: float, within: float) -> bool:
        deadline = time.time() + within
        while time.time() < deadline:
            rows = self.watch.rows
            if rows and rows[-1][0] > after:
                return True
            time.sleep(0.02)
        return False

    def _round(self) -> None:
        cfg, rng, station = self.cfg, self.rng, self.station
        phase = rng.choice(PHASES)
        attack = Attack(phase, rng.choice(MODES),
                        rng.uniform(cfg.attack_max / 10, cfg.attack_max))
        restart = phase in ('quiet', 'data_rate', 'continuous') \
            or rng.random() < cfg.restart_share
        station.arm(attack)
        if phase == 'shutdown':
            time.sleep(rng.uniform(0.0, attack.seconds))
            self._restart_node('during an attack')
        elif restart and phase != 'streaming':
            self._restart_node('while behaving')
        elif phase != 'streaming':
            self._quiet_until = time.time() + 2.0
            station.unplug(rng.uniform(0.05, 0.5))
        # Let the attack happen (or not, if that phase never came), then behave.
        deadline = time.time() + 15.0
        while (station.armed is not None or station.hostile) and time.time() < deadline:
            time.sleep(0.02)
        station.armed = None
        calm = time.time()
        if not self._wait_stream(calm, cfg.back_within):
            self._find('no stream', f'not streaming again {cfg.back_within:g} s after the '
                                    f'station behaved (attack {attack})', calm)
            if self.node is not None:
                self._restart_node('after a failed recovery')
            return
        # A stretch of good behaviour: every intact packet of it must be published.
        start = time.time()
        time.sleep(rng.uniform(0.5, 2.0))
        end = time.time() - 0.3
        time.sleep(0.5)
        published = {key for _, key in self.watch.rows[-20000:]}
        missing = [t for t, key in station.oracle.intact[-20000:]
                   if start + 0.2 <= t <= end and key not in published]
        if missing:
            self._find('valid not published',
                       f'{len(missing)} intact packets of a calm stretch not published after '
                       f'{attack}', missing[0])

    def _check_published(self) -> None:
        """Check the messages not checked yet against what the bytes allowed."""
        rows = self.watch.rows
        upto = len(rows)
        station = self.station
        for t, key in rows[self._checked:upto]:
            if key not in station.oracle.allowed and key not in station.oracle.intact_keys:
                mode = station.oracle.attacked_keys.get(key)
                self._find('false publication',
                           'a message no valid packet from our address held: '
                           + (f'the values of a real packet attacked by {mode!r}' if mode
                              else 'values the sensor never sent')
                           + f' ({VALUES.unpack(key)})', t)
        self._checked = upto

    def run(self) -> str:
        """Run rounds until the minutes (and packets, if asked) are done; return the report."""
        cfg = self.cfg
        isolate_ros_domain()
        sim = PtySimulator(SimulatorConfig(address=cfg.address, seed=cfg.seed,
                                           rate_hz=cfg.rate_hz, wire_baud=None))
        sim.start()
        self.station = HostileStation(sim.port, cfg.address, cfg.seed * 31 + 7)
        self.station.start()
        self.watch = Watch()
        self._checked = 0
        self._quiet_until = time.time() + 15.0
        began = time.time()
        rounds = 0
        liveness = threading.Thread(target=self._liveness, daemon=True)
        try:
            self._start_node()
            if not self._wait_stream(began, 60.0):
                raise RuntimeError(f'no stream at start: {self.node.output()[-3000:]}')
            liveness.start()
            end = began + cfg.minutes * 60.0
            while time.time() < end or (cfg.packets and self.station.packets_in < cfg.packets):
                self._round()
                rounds += 1
                self._check_published()
        finally:
            self._halt.set()
            if self.node is not None:
                self._quiet_until = time.time() + 60.0
                self._stop_node('at the end')
            self.watch.close()
            self.station.stop()
            sim.stop()
        self._check_published()
        return self.report(time.time() - began, rounds)

    def report(self, seconds: float, rounds: int) -> str:
        """Say what was run and found."""
        station = self.station
        attacks = Counter(f'{attack.phase}/{attack.mode}' for attack in station.attacks)
        lines = ['== i3dmgx2 node fuzz: a hostile base station, end to end ==',
                 f'{seconds / 60:.1f} min, {rounds} rounds ({self.restarts} node '
                 f'restarts), {station.packets_in} packets through the station '
                 f'({station.packets_in / max(seconds, 1e-9):.0f}/s), '
                 f'{station.packets_mutated} of them attacked, {station.bytes_out} bytes to '
                 f'the node, {len(self.watch.rows)} messages published',
                 'attacks (phase/mode: count): ' + ', '.join(
                     f'{k} {v}' for k, v in sorted(attacks.items()))]
        lines.append(f'findings: {len(self.findings)}')
        for f in self.findings[:50]:
            lines.append(f'  {f.kind} at {f.time:.3f}: {f.detail}')
            if f.evidence:
                lines.append(f'    bytes before it ({len(f.evidence)}): '
                             f'{f.evidence[-256:].hex()}')
        lines.append('RESULT: ' + ('FAIL' if self.findings else 'PASS'))
        return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the fuzz; print the report; return 0 if nothing was found."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--minutes', type=float, default=30.0, help='at least this long')
    parser.add_argument('--packets', type=int, default=0,
                        help='and at least this many packets through the station')
    parser.add_argument('--rate', type=float, default=600.0,
                        help='simulated packets per second (default 600)')
    parser.add_argument('--seed', type=int, default=1, help='seed of the attacks and the data')
    args = parser.parse_args(argv)
    if args.minutes <= 0 or args.rate <= 0 or args.packets < 0:
        parser.error('--minutes and --rate must be positive, --packets not negative')
    reserve_ros_domain(BENCHMARK_DOMAINS)
    os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '1')
    fuzz = NodeFuzz(FuzzConfig(minutes=args.minutes, packets=args.packets,
                               rate_hz=args.rate, seed=args.seed))
    print(fuzz.run(), flush=True)
    return 1 if fuzz.findings else 0


if __name__ == '__main__':
    sys.exit(main())
