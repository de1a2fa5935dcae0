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
Several sensors on one base station: node CPU and each sensor's rate, 1, 2 and 4 sensors.

Each run puts N simulated sensors behind one simulated base station (its
own process), every one streaming ``full`` (0xCC) at the highest rate N of
them fit on the 115200-baud line with the driver's margin (the line budget:
124 Hz alone, 62 Hz for two, 31 Hz for four), one node serving them all
(``address`` for one, ``addresses`` for several), and one subscriber in a
third process on every sensor's topic. After a warm-up the node's CPU time
is read over a window, and each sensor's rate is what the subscriber
received of it in that window. ``--stream inertial`` measures the smaller
record (272, 136 and 68 Hz).
"""

import math
import time

from bench_common import report, Result, standard_args
from harness.processes import isolate_ros_domain, NodeProcess, SimProcess, SubscriberProcess
from i3dmgx2_driver.codec import line_budget, streams

ADDRESSES = (17, 95, 40, 3)
WARM_UP_S = 5.0


def budget_rate(stream: streams.Stream, count: int) -> float:
    """Return the data rate N sensors of ``stream`` fit on the line (whole Hz, rounded down)."""
    rate = line_budget.max_shared_rate([stream.code] * count, 115200, True)
    return float(math.floor(rate))


def measure(count: int, stream: streams.Stream, seconds: float) -> tuple[float, float, dict]:
    """Return the rate asked, the node's CPU (% of one core) and each sensor's rate (Hz)."""
    addresses = ADDRESSES[:count]
    rate = budget_rate(stream, count)
    topics = (['imu/raw_data'] if count == 1 else [f'imu_{a}/raw_data' for a in addresses])
    sim = SimProcess(addresses=list(addresses) if count > 1 else [], address=addresses[0])
    subscriber = SubscriberProcess(topics=topics, values=True)
    params = {'port': sim.port, 'stream': stream.name, 'data_rate': rate, 'qos_depth': 1000}
    params.update({'address': addresses[0]} if count == 1 else {'addresses': list(addresses)})
    node = NodeProcess(params)
    try:
        for address in addresses:
            if not node.wait_for_output(f'from node {address} on', timeout=30.0):
                raise RuntimeError(f'node {address} did not stream:\n{node.output()}')
        time.sleep(WARM_UP_S)
        cpu0, wall0, t0 = node.cpu_seconds(), time.monotonic(), time.time()
        time.sleep(seconds)
        cpu1, wall1, t1 = node.cpu_seconds(), time.monotonic(), time.time()
    finally:
        node.stop()
        rows = subscriber.stop()
        sim.stop()
        node.close()
    rates = {topic: sum(1 for row in rows if row[3] == topic and t0 <= row[2] < t1) / (t1 - t0)
             for topic in topics}
    return rate, 100.0 * (cpu1 - cpu0) / (wall1 - wall0), rates


def _options(parser) -> None:
    parser.add_argument('--stream', default='full', help='the stream every sensor sends')


def run(seconds: float, stream: streams.Stream = streams.DEFAULT) -> list[Result]:
    """Measure 1, 2 and 4 sensors at the line budget; return the table rows."""
    isolate_ros_domain()
    results = []
    for count in (1, 2, 4):
        rate, cpu, rates = measure(count, stream, seconds)
        each = ', '.join(f'{topic.split("/")[0]} {hz:.1f}' for topic, hz in rates.items())
        results.append(Result(
            f'{count} x {stream.name} at {rate:g} Hz (the line budget for {count})',
            f'node CPU {cpu:.2f} % of one core; received per sensor (Hz): {each}'))
    return results


def main() -> None:
    """Run from the command line."""
    args = standard_args(__doc__.splitlines()[1], 20.0, 6.0, more=_options)
    stream = streams.parse(args.stream)
    results = run(args.seconds, stream)
    report(f'Several sensors on one base station ({stream.name})', results,
           [f'{args.seconds:g} s window after {WARM_UP_S:g} s of warm-up; one node serving '
            'every sensor; a subscriber in another process on every topic; rates are what '
            'it received in the window.'],
           None if args.no_output else f'several_sensors_{stream.name}.md',
           other_load=args.other_load)


if __name__ == '__main__':
    main()
