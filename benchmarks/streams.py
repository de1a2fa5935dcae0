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
Every stream at the fastest rate a 115200-baud line carries, through the simulator.

For each stream: its packet size (from the layout table), the line's limit
by arithmetic (11,520 bytes/s over the packet), the highest rate the device
can run at that fits with the 5 % margin (what the driver accepts), and then
a run: the simulated device in its own process, honouring the line's byte
rate (``limit_to_line_rate``: a record the line is still busy for is
skipped, as the device does), the node in this process set to that rate
with ``data_rate``. Every valid record written is looked for among those
published; the rate is measured from the records' write times; the latency
is from a packet's last byte written to ``publish()`` returned. Target:
within 2 % of the rate that fits, nothing lost.

Several sensors on one base station (``--sensors``): N of them (1, 2 and 4)
behind one simulated base station (its own process), every one streaming
``--stream`` (``full``, 0xCC, by default) at the highest rate N of them fit
on the line with the driver's margin (the line budget: 124 Hz alone, 62 Hz
for two, 31 Hz for four), one node process serving them all (``address``
for one, ``addresses`` for several), one subscriber in a third process on
every sensor's topic. After a warm-up the node's CPU time is read over a
window, and each sensor's rate is what the subscriber received of it in
that window. ``--stream inertial`` measures the smaller record (272, 136
and 68 Hz).
"""

import math
import time

from bench_common import (
    InProcessNode, report, Result, standard_args, summarise, write_latencies,
)
from harness.processes import isolate_ros_domain, NodeProcess, SimProcess, SubscriberProcess

from i3dmgx2_driver.codec import line_budget, streams

BAUD = 115200
#: Seconds of streaming left out of the latency figures (start-up, DDS discovery).
WARM_UP_S = 2.0
#: Measured rate within this fraction of the rate that fits meets the target.
RATE_TOLERANCE = 0.02
#: Several sensors: their addresses, and the warm-up before the CPU window (s).
ADDRESSES = (17, 95, 40, 3)
SENSORS_WARM_UP_S = 5.0


class StreamRun:
    """One stream at its highest rate that fits: written, published, rate, latency."""

    def __init__(self, stream: streams.Stream, seconds: float) -> None:
        self.stream = stream
        self.packet = line_budget.packet_size(stream.code, wireless=True)
        self.line_max = line_budget.line_bytes_per_second(BAUD) / self.packet
        self.fits = line_budget.max_rate(stream.code, BAUD, wireless=True)
        sim = SimProcess(limit_to_line_rate=True, wire_baud=BAUD)
        node = None
        try:
            node = InProcessNode(sim.port, stream=stream.name, data_rate=self.fits,
                                 **{'qos_overrides./imu/raw_data.publisher.depth': 1000})
            if not node.wait_published(1, timeout=20.0):
                raise RuntimeError(f'{stream.name}: the node published nothing within 20 s')
            time.sleep(WARM_UP_S)
            first = len(node.published)
            time.sleep(seconds)
            measured = node.published[first:]
            sim.silence()
            node.wait_quiet()
            self.node_lost = node.node.core.records.stats.lost
        finally:
            if node is not None:
                node.close()
            sim.stop()
        written = sim.written_stream()
        published = {p.timer for p in node.published}
        self.written = len(written)
        # Between the first and the last record written, every record the device made
        # must have been written (not skipped for the line, not left behind by a late
        # simulator) and published. (Before the first, the reply to the request for
        # continuous mode may hold the line: that is start-up, not the stream.)
        first, last = written[0].sample_time, written[-1].sample_time
        self.unwritten = sum(1 for e in sim.truth if e.source == 'stream'
                             and first < e.sample_time < last and e.write_time is None)
        self.unpublished = sum(1 for e in written if e.timer not in published)
        self.lost = self.unwritten + self.unpublished
        times = sorted(e.write_time for e in written)
        self.rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 else 0.0
        self.latency = summarise(write_latencies(sim.truth, measured))

    @property
    def ok(self) -> bool:
        """Within the tolerance of the rate that fits, and nothing lost."""
        return (self.lost == 0 and self.node_lost == 0
                and abs(self.rate / self.fits - 1.0) <= RATE_TOLERANCE)

    def row(self) -> str:
        """Return the table row of docs/benchmarks.md."""
        s = self.stream
        lost = max(self.lost, self.node_lost)
        return (f'| `{s.name}` | 0x{s.code:02X} | {self.packet} | {self.line_max:.1f} | '
                f'{self.fits:.1f} | {self.rate:.1f} ({self.rate / self.fits - 1:+.1%}) | '
                f'{self.written} / {lost} | {self.latency.p50 * 1e3:.3f} / '
                f'{self.latency.p99 * 1e3:.3f} |')


TABLE_HEAD = ('| stream | record | packet bytes | line limit (Hz) | fits with 5 % margin (Hz) '
              '| measured (Hz) | records written / lost | write \u2192 publish p50 / p99 (ms) |\n'
              '|---|---|---|---|---|---|---|---|')


def run(seconds: float) -> tuple[list[Result], str]:
    """Run every stream; return the result rows and the table of docs/benchmarks.md."""
    isolate_ros_domain()
    results, rows = [], []
    for stream in streams.STREAMS:
        measured = StreamRun(stream, seconds)
        rows.append(measured.row())
        results.append(Result(
            f'stream {stream.name} (0x{stream.code:02X}) at {measured.fits:.1f} Hz, '
            f'115200 baud, line-rate simulator: measured rate; lost',
            f'{measured.rate:.1f} Hz; {measured.lost} lost of {measured.written} '
            f'({measured.unwritten} not written, {measured.unpublished} written but not '
            f'published; the node counted {measured.node_lost} from timer gaps); '
            f'latency p50 / p99 / max {measured.latency.ms()}',
            f'within {RATE_TOLERANCE:.0%} of {measured.fits:.1f} Hz, none lost', measured.ok))
    return results, '\n'.join([TABLE_HEAD, *rows])


def budget_rate(stream: streams.Stream, count: int) -> float:
    """Return the data rate N sensors of ``stream`` fit on the line (whole Hz, rounded down)."""
    rate = line_budget.max_shared_rate([stream.code] * count, 115200, True)
    return float(math.floor(rate))


def measure_sensors(count: int, stream: streams.Stream,
                    seconds: float) -> tuple[float, float, dict]:
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
        time.sleep(SENSORS_WARM_UP_S)
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


def sensors_run(seconds: float, stream: streams.Stream) -> list[Result]:
    """Measure 1, 2 and 4 sensors at the line budget; return the table rows."""
    isolate_ros_domain()
    results = []
    for count in (1, 2, 4):
        rate, cpu, rates = measure_sensors(count, stream, seconds)
        each = ', '.join(f'{topic.split("/")[0]} {hz:.1f}' for topic, hz in rates.items())
        results.append(Result(
            f'{count} x {stream.name} at {rate:g} Hz (the line budget for {count})',
            f'node CPU {cpu:.2f} % of one core; received per sensor (Hz): {each}'))
    return results


def main() -> None:
    """Run from the command line: every stream, or several sensors on one base station."""
    def more(parser) -> None:
        parser.add_argument('--sensors', action='store_true',
                            help='1, 2 and 4 sensors on one base station instead')
        parser.add_argument('--stream', default='full',
                            help='--sensors: the stream every sensor sends')

    args = standard_args(__doc__.splitlines()[1], 20.0, more)
    if args.sensors:
        stream = streams.parse(args.stream)
        report(f'Several sensors on one base station ({stream.name})',
               sensors_run(args.seconds, stream),
               [f'{args.seconds:g} s window after {SENSORS_WARM_UP_S:g} s of warm-up; one node '
                'serving every sensor; a subscriber in another process on every topic; rates '
                'are what it received in the window.'],
               f'several_sensors_{stream.name}.md',
               other_load=args.other_load)
        return
    results, table = run(args.seconds)
    report('Streams at the line limit', results,
           [f'{args.seconds:g} s per stream after {WARM_UP_S:g} s of warm-up; wireless '
            f'framing; simulated device (line-rate mode) and node in two processes.',
            'README table:\n\n' + table],
           'streams.md', other_load=args.other_load)


if __name__ == '__main__':
    main()
