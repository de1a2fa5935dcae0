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
The faults the campaign injects into the simulator, drawn at random all through a run.

Its own room: every leg of the campaign and the long soak (``long_soak.py``)
runs it, and adding a fault is one change here (the checks of
``campaign_verdict.py`` then judge what it did).
"""

import random
import threading
import time
from typing import NamedTuple

from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator


#: The stalls' lengths (s), each drawn uniformly from its range.
STALLS = {'stall_short': (0.05, 0.25), 'stall': (0.4, 3.0), 'stall_long': (4.5, 7.0)}


class FaultEvent(NamedTuple):
    """One fault the campaign injected."""

    kind: str
    start: float
    end: float


class FaultDriver(threading.Thread):
    """
    Inject random faults into the simulator until told to stop.

    ``event_gap``: the seconds between two faults, drawn uniformly from that
    range. ``stall_long`` outlasts the node's stall recovery (it reopens the port).
    """

    WEIGHTS = (('unplug', 2.0), ('stall_short', 1.5), ('stall', 2.0), ('stall_long', 0.4),
               ('noise', 3.0), ('quirks', 1.0), ('power_cycle', 1.0))

    def __init__(self, sim: PtySimulator, rng: random.Random,
                 event_gap: tuple[float, float]) -> None:
        super().__init__(name='soak-faults', daemon=True)
        self.sim = sim
        self.rng = rng
        self.event_gap = event_gap
        self.events: list[FaultEvent] = []
        #: Power-up times of the sensor's power cycles (simulator wall clock).
        self.power_ups: list[float] = []
        self.unsafe_garbage_bytes = 0
        self.unsafe_garbage_bursts = 0
        self._unsafe = False
        self._garbage_mark = (0, 0)
        self._halt = threading.Event()
        self._kinds = [k for k, _ in self.WEIGHTS]
        self._weights = [w for _, w in self.WEIGHTS]

    def run(self) -> None:
        """Draw and inject events until stopped."""
        low, high = self.event_gap
        # Every kind once first, in random order, so that a short run meets them all.
        first = list(self._kinds)
        self.rng.shuffle(first)
        while not self._halt.wait(self.rng.uniform(low, high)):
            kind = first.pop() if first else self.rng.choices(self._kinds, self._weights)[0]
            if kind in STALLS:
                self._stall(kind, *STALLS[kind])
            else:
                getattr(self, '_' + kind)()

    def stop(self) -> None:
        """Stop injecting, then switch every fault off and plug the port back."""
        self._halt.set()
        self.join(15.0)
        self._account_garbage()
        start = time.time()
        self.sim.set_faults(FaultConfig())
        self.sim.stall(0.0)
        if not self.sim.pty.plugged.is_set():
            self.sim.replug()
        self._unsafe = False
        self.events.append(FaultEvent('all_off', start, time.time()))

    def _sleep(self, seconds: float) -> None:
        self._halt.wait(seconds)

    def _account_garbage(self) -> None:
        stats = self.sim.stats
        now = (stats.garbage_bytes, stats.garbage_bursts)
        if self._unsafe:
            self.unsafe_garbage_bytes += now[0] - self._garbage_mark[0]
            self.unsafe_garbage_bursts += now[1] - self._garbage_mark[1]
        self._garbage_mark = now

    def _unplug(self) -> None:
        seconds = self.rng.uniform(0.2, 2.5)
        start = time.time()
        self.sim.unplug(None)
        if self.rng.random() < 0.3:  # the sensor power-cycled meanwhile
            self._power_cycle_now(self.rng.random() < 0.7)
        self._sleep(seconds)
        self.sim.replug()
        self.events.append(FaultEvent('unplug', start, time.time()))

    def _stall(self, kind: str, low: float, high: float) -> None:
        seconds = self.rng.uniform(low, high)
        start = time.time()
        self.sim.stall(seconds)
        self._sleep(seconds)
        self.events.append(FaultEvent(kind, start, start + seconds))

    def _noise(self) -> None:
        rng = self.rng

        def maybe(high: float) -> float:
            return 0.0 if rng.random() < 0.3 else rng.uniform(0.0, high)

        self._account_garbage()
        changes = {
            'garbage_probability': maybe(0.2), 'garbage_safe': rng.random() < 0.5,
            'garbage_max_bytes': rng.randint(1, 16),
            'corrupt_checksum_probability': maybe(0.05),
            'corrupt_length_probability': maybe(0.05), 'foreign_probability': maybe(0.05),
            'drop_probability': maybe(0.05), 'command_loss_probability': maybe(0.3),
            'jitter_ms': maybe(5.0),
        }
        start = time.time()
        self.sim.set_faults(**changes)
        self._unsafe = changes['garbage_safe'] is False and changes['garbage_probability'] > 0
        self.events.append(FaultEvent('noise', start, start))

    def _quirks(self) -> None:
        start = time.time()
        polled_first = self.rng.random() < 0.5
        self.sim.set_faults(ignore_first_continuous=False)
        self.sim.set_faults(ignore_first_continuous=True, needs_polled_first=polled_first)
        self.events.append(FaultEvent('quirks', start, start))

    def _power_cycle_now(self, streaming: bool) -> None:
        """
        Power-cycle the sensor, streaming again at once or waiting to be asked.

        A real timer restarts from zero, which is behind where it was unless
        the sensor had run for more than half the timer's range (about 109 s)
        since it last wrapped: then zero is *ahead* of it modulo 2^32, and only
        the host's clock can tell a restart from a jump forward. The simulated
        timer restarts at the ``timer_start`` given: here 1..100 s behind or
        ahead of the timer now, half the time each, so that short runs meet
        both cases.
        """
        ahead = self.rng.random() < 0.5
        offset = self.rng.uniform(1.0, 100.0) * TICKS_PER_SECOND * (1 if ahead else -1)
        with self.sim.lock:
            start = (self.sim.sensor.clock.timer_at(time.time()) + round(offset)) % TIMER_MODULUS
        self.sim.power_cycle(timer_start=start)
        with self.sim.lock:
            self.power_ups.append(self.sim.sensor.clock.power_up_time)
        if streaming:
            self.sim.set_faults(already_streaming=False)
            self.sim.set_faults(already_streaming=True)

    def _power_cycle(self) -> None:
        start = time.time()
        self._power_cycle_now(self.rng.random() < 0.5)
        self.events.append(FaultEvent('power_cycle', start, start))
