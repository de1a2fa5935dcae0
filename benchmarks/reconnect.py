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
Data back after a reconnect: the port (or the radio) answering again -> a message published.

The real driver process (its defaults: ``read_timeout`` and
``reconnect_interval`` 1 s; its hot-path timings on, device/hot_path.py, for
the time of every message, and each port open noted by the rig's observer,
harness/instrumented_node.py) streams from the simulated sensor
at 100 Hz, which runs in this process; the scenarios, repeated every round:

- unplug: the base station is unplugged for 1.5 to 2.5 s (at random, so that
  a retry every ``reconnect_interval`` meets the port at any phase; the
  wireless sensor keeps streaming), then plugged back in;
- unplug + power cycle: the same, and the sensor restarts meanwhile (it
  comes back not streaming);
- long stall: 6.5 to 7.5 s of radio silence, longer than the stall recovery
  (1 s, then five requests for continuous mode), so the driver reopens the
  port;
- short stall: 1.5 to 2.5 s of radio silence, recovered without reopening.

Figures: from the port back (``replug()`` returned) or the radio back (end of
the stall) to the first Imu message ``publish()`` returned after it; from the
port opened again to that message; and the commands the driver sent in the
3 s after the port came back (from the simulator's host command log), for
the driver as shipped (a known sensor is confirmed with one serial-number
read; a port is reopened the moment it is back). The figures with those two
measures switched off (docs/device-dialogue.md) came from an earlier version
of this benchmark that replaced the driver's settings from outside, which no
benchmark does any more.

    python benchmarks/reconnect.py --rounds 3
"""

import argparse
import random
import statistics
import sys
import time
from typing import NamedTuple

from bench_common import emit, machine_table, RunNote, TimedNodeProcess
from harness.processes import isolate_ros_domain

from i3dmgx2_driver.device.hot_path import ROW_FIELDS
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig

_PUBLISHED = ROW_FIELDS.index('published')
#: How long the base station stays unplugged (s): uniform in this range.
UNPLUG_S = (1.5, 2.5)
#: Stall lengths (s), uniform in these ranges (so that stalls end at any phase of the
#: sensor's sample clock).
LONG_STALL_S = (6.5, 7.5)
SHORT_STALL_S = (1.5, 2.5)
#: Time given to the driver to stream again after each scenario (s).
SETTLE_S = 4.0
SCENARIOS = ('unplug', 'unplug + power cycle', 'long stall', 'short stall')


class Trial(NamedTuple):
    """One scenario once: when the port or radio was back, and the commands sent after."""

    scenario: str
    back: float
    commands: tuple[str, ...]


def _commands_since(sim: PtySimulator, since: float, until: float) -> tuple[str, ...]:
    out = []
    for entry in sim.host_log:
        if since <= entry.time <= until and entry.command is not None:
            code = entry.command.code
            name = f'{code:02X}'
            if code == 0xEA:
                name += f'({entry.command.args[0]})'
            out.append(name)
    return tuple(out)


def run_scenarios(sim: PtySimulator, rng: random.Random) -> list[Trial]:
    """Run every scenario once on a streaming driver; return when each came back."""
    trials = []
    # The base station unplugged while the sensor streams on; then unplugged while the
    # sensor restarts meanwhile (it comes back in polled mode).
    for name in ('unplug', 'unplug + power cycle'):
        sim.unplug()
        if name != 'unplug':
            sim.power_cycle()
        time.sleep(rng.uniform(*UNPLUG_S))
        sim.replug()
        back = time.time()
        time.sleep(SETTLE_S)
        trials.append(Trial(name, back, _commands_since(sim, back, back + 3.0)))
    for name, lengths in (('long stall', LONG_STALL_S), ('short stall', SHORT_STALL_S)):
        seconds = rng.uniform(*lengths)
        start = time.time()
        sim.stall(seconds)
        back = start + seconds
        time.sleep(seconds + SETTLE_S)
        trials.append(Trial(name, back, _commands_since(sim, back, back + 3.0)))
    return trials


class Figures(NamedTuple):
    """Per scenario: seconds to the first message, from the port back and opened; commands."""

    to_publish: dict[str, list[float]]
    open_to_publish: dict[str, list[float]]
    commands: dict[str, tuple[str, ...]]


def measure(rounds: int, seed: int) -> Figures:
    """Run the rounds; return the figures."""
    figures = Figures({}, {}, {})
    rng = random.Random(seed)
    for round_ in range(rounds):
        print(f'-- round {round_ + 1}/{rounds}', file=sys.stderr, flush=True)
        with PtySimulator(SimulatorConfig(seed=seed + round_)) as sim:
            node = TimedNodeProcess(sim.port, observed=True)
            try:
                time.sleep(3.0)
                trials = run_scenarios(sim, rng)
            finally:
                node.stop()
        published = sorted(row[_PUBLISHED] for row in node.rows)
        for trial in trials:
            key = trial.scenario
            first = next((t for t in published if t > trial.back), None)
            if first is None:
                continue
            figures.to_publish.setdefault(key, []).append(first - trial.back)
            print(f'   {trial.scenario}: first message {(first - trial.back) * 1e3:.1f} ms '
                  f'after the port or radio was back', file=sys.stderr, flush=True)
            opened = [t for t in node.opens if trial.back <= t <= first]
            if opened:
                figures.open_to_publish.setdefault(key, []).append(first - opened[0])
            figures.commands[key] = trial.commands
    return figures


def _ms(values: list[float] | None) -> str:
    if not values:
        return '-'
    return (f'{statistics.median(values) * 1e3:.0f} / {max(values) * 1e3:.0f} ms '
            f'(n={len(values)})')


def _commands(names: tuple[str, ...]) -> str:
    return ' '.join(names) if names else 'none'


def main(argv: list[str] | None = None) -> int:
    """Run from the command line; print and save the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--rounds', type=int, default=3)
    args = parser.parse_args(argv)
    isolate_ros_domain()
    note = RunNote('reconnect.py', argv)
    figures = measure(args.rounds, seed=1)
    lines = ['## Data back after a reconnect (100 Hz)', '', machine_table(), '',
             '| scenario | from | as shipped: median / max |', '|---|---|---|']
    for scenario in SCENARIOS:
        origin = 'radio back' if 'stall' in scenario else 'port back'
        lines.append(f'| {scenario} | {origin} -> first message published | '
                     f'{_ms(figures.to_publish.get(scenario))} |')
        if 'unplug' in scenario:
            lines.append(f'| {scenario} | port opened -> first message published | '
                         f'{_ms(figures.open_to_publish.get(scenario))} |')
    lines += ['', '| commands sent in the 3 s after the port or radio was back | as shipped |',
              '|---|---|']
    for scenario in SCENARIOS:
        lines.append(f'| {scenario} | {_commands(figures.commands.get(scenario, ()))} |')
    lines += ['', note.text()]
    emit('\n'.join(lines) + '\n', 'reconnect.md')
    return 0


if __name__ == '__main__':
    sys.exit(main())
