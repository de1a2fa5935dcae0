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
Shutdown at a random moment of every phase, thousands of times: whether the node always ends.

One trial starts a node (plain or managed, through the fork server of
``node_forks.py``) against a simulated sensor in this process, brings it to
a phase, sends SIGINT or SIGTERM at a random moment of it, and times the end:

- ``no port``: the port does not exist yet (the node retries);
- ``dialogue``: from the node's start, while it opens the port and talks
  its way to the stream (some land after the first record: the log says);
- ``first record``: within 30 ms of the first record;
- ``reconnect``: after an unplug, while the node reopens the port (the
  station plugged back in at a random moment too);
- ``gyro bias``: during the gyro bias capture that follows the first
  record (``capture_gyro_bias_on_start``);
- ``several sensors``: two sensors on one base station, from the start;
- ``lifecycle idle``: the managed node, unconfigured;
- ``configure``, ``activate``, ``deactivate``, ``cleanup``, ``shutdown``:
  the managed node during that transition, asked for by a lifecycle client.

A node that has not ended 10 s after the signal is hung: SIGABRT makes it
write every thread's stack to its log (kept in the outcome), SIGKILL follows
if even that does not end it (a forced kill). The shutdown deadline of the
node itself (3 s, ``i3dmgx2_driver/lifetime.py``) shows as exit code 1 with
its stacks in the log. Several slots run side by side, each in a ROS domain
of its own. ``benchmarks/shutdown.py`` runs thousands;
``test/test_shutdown_stress.py`` 300.
"""

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
import os
import random
import signal
import tempfile
import threading
import time

from harness.node_forks import ForkedNode, ForkServer
from harness.processes import ADDRESS, LifecycleClient, Listener, param_args

from i3dmgx2_driver.lifetime import SHUTDOWN_DEADLINE
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig

PHASES = ('no port', 'dialogue', 'first record', 'reconnect', 'gyro bias', 'several sensors',
          'lifecycle idle', 'configure', 'activate', 'deactivate', 'cleanup', 'shutdown')
#: The phases of the managed node, which need a lifecycle client.
LIFECYCLE_PHASES = PHASES[6:]
#: A node still running this long after the signal is hung (s).
HANG_AFTER = 10.0
SECOND_SENSOR = 17
FIRST_RECORD = '(first record received)'
SIGNALS = (signal.SIGINT, signal.SIGTERM)


@dataclass
class Outcome:
    """One trial: the phase, the signal, how it ended and how long the end took."""

    phase: str
    signal: str
    code: int | None
    seconds: float
    hung: bool = False
    killed: bool = False
    #: Why the trial could not reach its phase ('' if it did).
    setup_error: str = ''
    #: The node's log, kept when it did not end cleanly.
    log: str = ''

    @property
    def before_handlers(self) -> bool:
        """Whether the signal itself ended it, before the node's handlers were installed."""
        return self.code == -signal.Signals[self.signal].value

    @property
    def clean(self) -> bool:
        """
        Whether it ended by itself: code 0, or the signal's own (before the handlers).

        Code 0 also says the node's own deadline did not end it (that is exit 1);
        ``seconds``, measured from outside, adds the machine's scheduling delays.
        """
        return not self.hung and (self.code == 0 or self.before_handlers)


@dataclass
class Tally:
    """What many trials came to."""

    outcomes: list[Outcome] = field(default_factory=list)

    def ran(self) -> list[Outcome]:
        """Return the trials that reached their phase and were signalled."""
        return [o for o in self.outcomes if not o.setup_error]

    def summary(self) -> dict[str, object]:
        """Return runs, hangs, forced kills, exits past the deadline, exit codes, slowest."""
        ran = self.ran()
        codes = Counter(o.code for o in ran if not o.hung)
        return {
            'runs': len(ran),
            'not reached': len(self.outcomes) - len(ran),
            'hangs': sum(o.hung for o in ran),
            'forced kills': sum(o.killed for o in ran),
            'past the deadline': sum(o.seconds > SHUTDOWN_DEADLINE for o in ran if not o.hung),
            'exit codes': dict(sorted(codes.items(), key=lambda kv: (kv[0] is None, kv[0]))),
            'slowest exit': max((o.seconds for o in ran if not o.hung), default=0.0),
        }

    def by_phase(self) -> dict[str, list[Outcome]]:
        """Return the trials that ran, by phase."""
        phases: dict[str, list[Outcome]] = {}
        for outcome in self.ran():
            phases.setdefault(outcome.phase, []).append(outcome)
        return phases


class Slot:
    """One lane of trials: its ROS domain, a lifecycle client when needed, one node at a time."""

    def __init__(self, server: ForkServer, domain: int, rng: random.Random) -> None:
        self.server = server
        self.domain = domain
        self.rng = rng
        self._listener: Listener | None = None
        self._client: LifecycleClient | None = None

    def client(self) -> LifecycleClient:
        """Return the lifecycle client in this slot's domain (made once)."""
        if self._client is None:
            self._listener = Listener({}, domain=self.domain)
            self._client = LifecycleClient(self._listener)
        return self._client

    def close(self) -> None:
        """Close the client's node."""
        if self._listener is not None:
            self._listener.close()

    def env(self) -> dict[str, str]:
        """Return the node's environment: this slot's domain, on this machine only."""
        return {'ROS_DOMAIN_ID': str(self.domain), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}

    def trial(self, phase: str, signum: int) -> Outcome:
        """Run one trial of ``phase`` ending with ``signum``."""
        rng = self.rng
        addresses = (ADDRESS, SECOND_SENSOR) if phase == 'several sensors' else (ADDRESS,)
        sim = None
        if phase != 'no port':
            sim = PtySimulator(SimulatorConfig(addresses=addresses if len(addresses) > 1 else (),
                                               address=ADDRESS, seed=rng.randrange(1 << 30)))
            sim.start()
        try:
            port = sim.port if sim is not None else os.path.join(
                tempfile.gettempdir(), f'i3dmgx2-none-{rng.randrange(1 << 30)}')
            params: dict[str, object] = {'port': port, 'reconnect_interval': 0.3}
            if len(addresses) > 1:
                params['addresses'] = '[' + ','.join(map(str, addresses)) + ']'
            else:
                params['address'] = ADDRESS
            if phase == 'gyro bias':
                params.update(capture_gyro_bias_on_start=True, gyro_bias_sampling_ms=1000)
            kind = 'lifecycle_node' if phase in LIFECYCLE_PHASES else 'node'
            node = self.server.start(kind, param_args(params), self.env())
            try:
                return self._signal_in_phase(phase, node, sim, signum)
            finally:
                node.close()
        finally:
            if sim is not None:
                sim.stop()

    def _signal_in_phase(self, phase: str, node: ForkedNode, sim: PtySimulator | None,
                         signum: int) -> Outcome:
        rng = self.rng
        name = signal.Signals(signum).name

        def not_reached(why: str) -> Outcome:
            node.signal(signal.SIGKILL)
            node.wait(5.0)
            return Outcome(phase, name, node.code, 0.0, setup_error=why, log=node.output())

        if phase in ('no port', 'dialogue', 'several sensors', 'lifecycle idle'):
            time.sleep(rng.uniform(0.0, {'no port': 1.0, 'dialogue': 0.8,
                                         'several sensors': 1.5,
                                         'lifecycle idle': 0.5}[phase]))
        elif phase in ('first record', 'reconnect', 'gyro bias'):
            if not node.wait_for_output(FIRST_RECORD, 20.0):
                return not_reached('no first record')
            if phase == 'first record':
                time.sleep(rng.uniform(0.0, 0.03))
            elif phase == 'gyro bias':
                time.sleep(rng.uniform(0.0, 1.2))
            else:
                sim.unplug(rng.uniform(0.2, 1.0))
                time.sleep(rng.uniform(0.0, 1.5))
        else:
            reached = self._transition(phase, node)
            if reached:
                return not_reached(reached)
        if phase == 'dialogue' and FIRST_RECORD in node.output():
            phase = 'dialogue (streaming)'
        sent = time.monotonic()
        node.signal(signum)
        hung, killed = node.end(HANG_AFTER)
        seconds = max((node.ended or time.monotonic()) - sent, 0.0)
        outcome = Outcome(phase, name, node.code, seconds, hung, killed)
        if not outcome.clean:
            outcome.log = node.output()
        return outcome

    def _transition(self, phase: str, node: ForkedNode) -> str:
        """Bring the managed node to ``phase`` and ask for it; '' once asked, else why not."""
        rng = self.rng
        client = self.client()
        if not client.wait_ready(20.0):
            return 'lifecycle services not ready'
        steps = {'configure': [], 'activate': ['configure'],
                 'deactivate': ['configure', 'activate'],
                 'cleanup': ['configure', 'activate', 'deactivate'],
                 'shutdown': ['configure', 'activate']}[phase]
        for step in steps:
            if not client.change(step, timeout=20.0):
                return f'{step} failed'
        client.change_async(phase)
        time.sleep(rng.uniform(0.0, {'configure': 0.6, 'activate': 0.6}.get(phase, 0.3)))
        return ''


def run_trials(count: int, slots: int = 3, seed: int = 1,
               progress: Callable[[int, Outcome], None] | None = None) -> Tally:
    """Run ``count`` trials over ``slots`` lanes side by side, the phases in turn."""
    rng = random.Random(seed)
    base = rng.randrange(110, 200)
    plan = [(PHASES[i % len(PHASES)], rng.choice(SIGNALS)) for i in range(count)]
    rng.shuffle(plan)
    tally = Tally()
    lock = threading.Lock()
    done = [0]
    server = ForkServer()

    def lane(index: int) -> None:
        slot = Slot(server, base + index, random.Random(rng.randrange(1 << 30) + index))
        try:
            while True:
                with lock:
                    if not plan:
                        return
                    phase, signum = plan.pop()
                try:
                    outcome = slot.trial(phase, signum)
                except Exception as exc:  # noqa: B902 - a broken trial is counted, not fatal
                    outcome = Outcome(phase, signal.Signals(signum).name, None, 0.0,
                                      setup_error=f'{type(exc).__name__}: {exc}')
                with lock:
                    tally.outcomes.append(outcome)
                    done[0] += 1
                    if progress is not None:
                        progress(done[0], outcome)
        finally:
            slot.close()

    try:
        lanes = [threading.Thread(target=lane, args=(i,), name=f'shutdown-lane-{i}')
                 for i in range(slots)]
        for thread in lanes:
            thread.start()
        for thread in lanes:
            thread.join()
    finally:
        server.close()
    return tally
