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
CPU use of the node process while it streams, in % of one core.

The node runs exactly as ``ros2 run i3dmgx2_driver node`` runs it, against
the simulated device (its own process), with a subscriber in a third process
so that every message really goes out through DDS. After a warm-up, the
node's user + system CPU time (all its threads, from /proc/<pid>/stat) is
read at the start and the end of a window. Target: <= 3 % at 100 Hz.

``--against DIR`` measures another checkout of the driver (``git worktree
add /tmp/before <commit>``) against this one at 100 Hz, interleaved round by
round in one run, so that both see the same machine: a change's effect on
CPU is a few tenths of a percent, less than a busy machine moves one window.
"""

import argparse
from pathlib import Path
import statistics
import sys
import time

from bench_common import report, Result, standard_args
from harness.processes import (
    ADDRESS, isolate_ros_domain, NodeProcess, SimProcess, SubscriberProcess,
)

TARGET_PERCENT_100HZ = 3.0
WARM_UP_S = 5.0


def measure(rate_hz: float, seconds: float, warm_up: float = WARM_UP_S,
            tree: Path | None = None, params: dict | None = None) -> tuple[float, int]:
    """
    Return the node's CPU (% of one core) and how many messages the subscriber got.

    ``params`` are given to the node besides the port and address (another
    benchmark's switch, measured on and off with the same rig).
    """
    sim = SimProcess(rate_hz=rate_hz)
    subscriber = SubscriberProcess()
    # qos_depth (deprecated, warned about) rather than qos_overrides: the A/B run's other
    # tree may predate the standard parameters, and both trees take this name.
    node = NodeProcess({'port': sim.port, 'address': ADDRESS, 'qos_depth': 1000,
                        **(params or {})}, tree=tree)
    try:
        if not node.wait_for_output('streaming 0xCC', timeout=30.0):
            raise RuntimeError(f'the node did not start streaming:\n{node.output()}')
        time.sleep(warm_up)
        cpu0, wall0 = node.cpu_seconds(), time.monotonic()
        time.sleep(seconds)
        cpu1, wall1 = node.cpu_seconds(), time.monotonic()
    finally:
        node.stop()
        rows = subscriber.stop()
        sim.stop()
        node.close()
    return 100.0 * (cpu1 - cpu0) / (wall1 - wall0), len(rows)


def run(seconds: float) -> list[Result]:
    """Measure at 100 Hz and 1000 Hz; return the table rows."""
    isolate_ros_domain()
    results = []
    for rate in (100.0, 1000.0):
        percent, received = measure(rate, seconds)
        metric = f'CPU of the node process at {rate:.0f} Hz (% of one core)'
        value = f'{percent:.2f} % ({received} messages received by the subscriber)'
        if rate == 100.0:
            results.append(Result(metric, value, f'<= {TARGET_PERCENT_100HZ:g} %',
                                  percent <= TARGET_PERCENT_100HZ))
        else:
            results.append(Result(metric, value))
    return results


def compare(against: Path, rounds: int, seconds: float) -> list[Result]:
    """Measure this checkout and ``against`` at 100 Hz, alternating; return the table rows."""
    isolate_ros_domain()
    trees = {'this checkout': None, f'{against}': against}
    figures: dict[str, list[float]] = {name: [] for name in trees}
    for _ in range(rounds):
        for name, tree in trees.items():
            figures[name].append(measure(100.0, seconds, tree=tree)[0])
    return [Result(f'CPU at 100 Hz, {name} (% of one core): mean (each round)',
                   f"{statistics.mean(values):.2f} % ({', '.join(f'{v:.2f}' for v in values)})")
            for name, values in figures.items()]


def _ab_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--against', type=Path, default=None,
                        help='another checkout of the driver, measured against this one at '
                             '100 Hz (default seconds: 40)')
    parser.add_argument('--rounds', type=int, default=4, help='rounds of --against')


def main() -> None:
    """Run from the command line."""
    args = standard_args(__doc__.splitlines()[1], 30.0, 8.0, more=_ab_options)
    if args.against is not None:
        seconds = args.seconds if '--seconds' in sys.argv else 40.0
        results = compare(args.against.resolve(), args.rounds, seconds)
        report('CPU, A/B', results,
               [f'{args.rounds} rounds, each {seconds:g} s per checkout after '
                f'{WARM_UP_S:g} s of warm-up, the two alternating; a subscriber in another '
                'process.'],
               None if args.no_output else 'cpu_ab.md', other_load=args.other_load)
        return
    results = run(args.seconds)
    report('CPU', results,
           [f'{args.seconds:g} s window after {WARM_UP_S:g} s of warm-up; user + system time '
            "of all the node's threads; a subscriber in another process."],
           None if args.no_output else 'cpu.md',
           other_load=args.other_load)


if __name__ == '__main__':
    main()
