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
"""

import time

from bench_common import (
    isolate_ros_domain, NodeProcess, report, Result, SimProcess, standard_args,
    SubscriberProcess,
)

TARGET_PERCENT_100HZ = 3.0
WARM_UP_S = 5.0


def measure(rate_hz: float, seconds: float, warm_up: float = WARM_UP_S) -> tuple[float, int]:
    """Return the node's CPU (% of one core) and how many messages the subscriber got."""
    sim = SimProcess(rate_hz=rate_hz)
    subscriber = SubscriberProcess()
    node = NodeProcess(sim.port, qos_depth=1000)
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
        node.remove_log()
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


def main() -> None:
    """Run from the command line."""
    args = standard_args(__doc__.splitlines()[1], 30.0, 8.0)
    results = run(args.seconds)
    report('CPU', results,
           [f'{args.seconds:g} s window after {WARM_UP_S:g} s of warm-up; user + system time '
            "of all the node's threads; a subscriber in another process."],
           None if args.no_output else 'cpu.md',
           other_load=args.other_load)


if __name__ == '__main__':
    main()
