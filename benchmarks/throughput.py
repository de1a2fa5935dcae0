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
Throughput: the most records a second, end to end through the node and in the codec alone.

End to end: a real 115200-baud line carries at most ~131 packets/s; a
pseudo-terminal has no baud limit, so the simulated device (its own
process) streams at rates the device could never reach (``rate_hz``
override), with the node in this process and a subscriber (reliable, deep
history) in a third. Each rate runs for a while, then the radio goes
silent, the node drains, and every valid packet the simulator wrote is
looked for among what the node published (its hot-path observer and its
own counter) and what the subscriber got. Target: >= 1,000 records/s with
none lost.

The codec alone (``--codec``): a long stream of wireless data packets
carrying the real 0xCC records of test/fixtures/, 1 % of them damaged by
one bit flip each, cut into 4096-byte chunks as a serial port delivers
them, and a SensorStreamParser that finds, checks and decodes every record,
as the driver does; one process pinned to one core, the best of five runs.
Target: >= 250,000 frames/s.
"""

import os
import random
import statistics
import time

from bench_common import InProcessNode, REPO, report, Result, stamp_key, standard_args
from harness.processes import ADDRESS, isolate_ros_domain, SimProcess, SubscriberProcess

from i3dmgx2_driver import codec

TARGET_RATE = 1000.0
RATES = (500.0, 1000.0, 2000.0, 4000.0, 8000.0)
#: The codec: frames per second it must parse, and how its stream is made.
CODEC_TARGET = 250_000
FRAMES = 200_000
CORRUPTION = 0.01
CHUNK = 4096
REPEAT = 5
#: What the radio can carry at 115200 baud: 11,520 bytes/s over 88-byte packets.
LINE_LIMIT = 11_520 // 88


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


def run(seconds: float) -> list[Result]:
    """Sweep the rates; return the table rows."""
    isolate_ros_domain()
    results = []
    best = 0.0
    for rate in RATES:
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


def codec_stream(seed: int = 1) -> tuple[list[bytes], int, int]:
    """Return the chunks, the number of frames that must come out, and how many were damaged."""
    rng = random.Random(seed)
    lines = (REPO / 'test' / 'fixtures' / 'gx2_real_0xcc_records.txt').read_text().splitlines()
    records = [bytes.fromhex(t.strip()) for t in lines if t.strip() and not t.startswith('#')]
    stream = bytearray()
    expected = damaged = 0
    for index in range(FRAMES):
        packet = bytearray(codec.encode_data_packet(
            ADDRESS, records[index % len(records)], index % 256, (7 * index) % 256))
        if rng.random() < CORRUPTION:
            bit = rng.randrange(len(packet) * 8)
            packet[bit // 8] ^= 1 << (bit % 8)
            damaged += 1
            # LQI and RSSI are outside the checksum: such a packet still counts as good.
            expected += bit // 8 in (len(packet) - 4, len(packet) - 3)
        else:
            expected += 1
        stream += packet
    return [bytes(stream[i:i + CHUNK]) for i in range(0, len(stream), CHUNK)], expected, damaged


def parse_once(chunks: list[bytes]) -> tuple[float, float, int]:
    """Feed every chunk to a fresh parser; return (wall s, CPU s, records)."""
    feed = codec.SensorStreamParser(address=ADDRESS).feed
    count = 0
    cpu0, wall0 = time.process_time(), time.perf_counter()
    for chunk in chunks:
        for event in feed(chunk):
            if event.__class__ is codec.DataPacket:
                count += 1
    return time.perf_counter() - wall0, time.process_time() - cpu0, count


def codec_rows() -> list[Result]:
    """Time the parser on one core; return its rows (the best of the runs)."""
    core = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})
    chunks, expected, damaged = codec_stream()
    runs = [parse_once(chunks) for _ in range(REPEAT)]
    if any(count != expected for _, _, count in runs):
        raise RuntimeError(f'{[r[2] for r in runs]} records came out, {expected} expected')
    rates = [FRAMES / wall for wall, _, _ in runs]
    best = max(rates)
    return [
        Result(f'codec: parse and decode 0xCC data packets, {damaged} of {FRAMES:,} with one '
               f'flipped bit, {CHUNK}-byte chunks, one core (pinned to core {core})',
               f'frames/s best {best:,.0f}, median {statistics.median(rates):,.0f}; '
               f'{FRAMES / min(cpu for _, cpu, _ in runs):,.0f} frames per CPU second; '
               f'{best / LINE_LIMIT:,.0f}x what 115200 baud carries',
               f'>= {CODEC_TARGET:,} frames/s', best >= CODEC_TARGET)]


def main() -> None:
    """Run from the command line: end to end, or the codec alone."""
    def more(parser) -> None:
        parser.add_argument('--codec', action='store_true', help='the codec alone, one core')

    args = standard_args(__doc__.splitlines()[1], 60.0, more)
    if args.codec:
        report('Codec throughput', codec_rows(), [f'Best of {REPEAT} runs.'],
               'codec_throughput.md', other_load=args.other_load)
        return
    report('Sustained rate', run(args.seconds), [
        f'Rates swept: {", ".join(f"{r:.0f}" for r in RATES)} Hz, {args.seconds:g} s each; '
        f'node QoS reliable, depth 1000; subscriber reliable, depth 5000.'],
        'throughput.md', other_load=args.other_load)


if __name__ == '__main__':
    main()
