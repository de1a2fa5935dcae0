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
Sustained rate: the most records per second the node publishes without losing one.

A real 115200-baud line carries at most ~131 packets/s; a pseudo-terminal has
no baud limit, so the simulated device (its own process) streams at rates
the device could never reach (``rate_hz`` override), with the node in this
process and a subscriber (reliable, deep history) in a third. Each rate runs
for a while, then the radio goes silent, the node drains, and every valid
packet the simulator wrote is looked for among what the node published (its
hot-path observer and its own counter) and what the subscriber got.
Target: >= 1,000 records/s with none lost.
"""

import time

from bench_common import InProcessNode, Result, run_benchmark, stamp_key
from harness.processes import isolate_ros_domain, SimProcess, SubscriberProcess

TARGET_RATE = 1000.0
RATES = (500.0, 1000.0, 2000.0, 4000.0, 8000.0)


class RateRun:
    """One rate: what was written, published and received."""

    def __init__(self, rate_hz: float, seconds: float) -> None:
        self.rate_hz = rate_hz
        sim = SimProcess(rate_hz=rate_hz, wire_baud=None)
        subscriber = SubscriberProcess()
        node = None
        try:
            node = InProcessNode(
                sim.port, **{'qos_overrides./imu/raw_data.publisher.depth': 1000})
            if not node.wait_published(1, timeout=20.0):
                raise RuntimeError('the node published nothing within 20 s')
            time.sleep(seconds)
            sim.silence()
            node.wait_quiet()
            time.sleep(1.0)  # let the subscriber catch up
            self.node_count = node.node.core.records.stats.published
        finally:
            if node is not None:
                node.close()
            rows = subscriber.stop()
            sim.stop()
        written = sim.written_stream()
        published = {p.timer: p for p in node.published}
        self.written = len(written)
        self.published = sum(1 for e in written if e.timer in published)
        self.overflow = sim.stats.get('overflow_packets', 0)
        self.sim_late = sim.stats.get('late_skipped', 0)
        self.lost = self.written - self.published + self.overflow
        # The subscriber counts from its first message: before DDS matched it
        # with the node's publisher, nothing could reach it.
        received = {stamp_key(sec, nanosec) for sec, nanosec, _ in rows}
        keys = [stamp_key(p.stamp_sec, p.stamp_nanosec) for p in node.published]
        start = next((i for i, key in enumerate(keys) if key in received), len(keys))
        self.sent_after_match = len(keys) - start
        self.received = sum(1 for key in keys[start:] if key in received)
        first = min((e.write_time for e in written), default=0.0)
        last = max((e.write_time for e in written), default=0.0)
        self.achieved = (self.written - 1) / (last - first) if last > first else 0.0

    @property
    def ok(self) -> bool:
        """Every valid packet published, and the simulator kept up with its rate."""
        return self.lost == 0 and self.sim_late == 0 and self.written > 0


def run(seconds: float, rates: tuple[float, ...] = RATES) -> list[Result]:
    """Sweep the rates; return the table rows."""
    isolate_ros_domain()
    results = []
    best = 0.0
    for rate in rates:
        measured = RateRun(rate, seconds)
        if measured.ok:
            best = max(best, measured.achieved)
        results.append(Result(
            f'  {rate:.0f} Hz for {seconds:g} s: written / published by the node; '
            f'received by the subscriber / published since it matched',
            f'{measured.written} / {measured.published}; '
            f'{measured.received} / {measured.sent_after_match}'
            f' ({measured.achieved:.0f}/s; lost {measured.lost}'
            + (f', {measured.overflow} of them overflowing the pty while the node was not '
               f'reading' if measured.overflow else '')
            + (f', simulator fell behind by {measured.sim_late}' if measured.sim_late else '')
            + ')'))
    results.insert(0, Result('highest sustained rate with no record lost (pty, no baud limit)',
                             f'{best:.0f} records/s', f'>= {TARGET_RATE:.0f} records/s',
                             best >= TARGET_RATE))
    return results


def main() -> None:
    """Run from the command line."""
    run_benchmark(__doc__, (60.0, 10.0), run, 'Sustained rate', 'throughput.md', lambda seconds: [
        f'Rates swept: {", ".join(f"{r:.0f}" for r in RATES)} Hz, {seconds:g} s each; '
        f'node QoS reliable, depth 1000; subscriber reliable, depth 5000.'])


if __name__ == '__main__':
    main()
