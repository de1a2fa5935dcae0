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
Throughput of the host-side codec: 0xCC data packets through SensorStreamParser.

Builds a long stream of wireless data packets carrying 0xCC records (the real
fixture records when they can be found, synthetic ones otherwise), damages a
fraction of the packets with one bit flip each, cuts the stream into 4096-byte
chunks as a serial port would deliver them, and times a SensorStreamParser that
finds, checks and decodes every record, as the driver does. One process, one
thread: the figure is for one core.

    python benchmarks/codec_throughput.py [--frames N] [--corruption 0.01]
"""

import argparse
import os
import pathlib
import platform
import random
import statistics
import struct
import sys
import time

REPO = pathlib.Path(__file__).resolve().parents[1]
FIXTURE_NAME = 'gx2_real_0xcc_records.txt'
FIXTURE_DIRS = (REPO / 'test' / 'fixtures', REPO.parent / 'shared' / 'fixtures')
CHUNK = 4096
ADDRESS = 95
TARGET = 250_000
#: What the radio can carry at 115200 baud: 11,520 bytes/s over 88-byte packets.
LINE_LIMIT = 11_520 // 88


def _codec():
    """Import the codec from this checkout (the script runs without installing it)."""
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    from i3dmgx2_driver import codec
    return codec


def _fixture_records():
    for directory in FIXTURE_DIRS:
        path = directory / FIXTURE_NAME
        if path.is_file():
            lines = path.read_text().splitlines()
            return [bytes.fromhex(t.strip()) for t in lines
                    if t.strip() and not t.startswith('#')], str(path)
    return None, None


def _synthetic_records(codec, rng, count=512):
    records = []
    for index in range(count):
        floats = [struct.unpack('>f', struct.pack('>f', rng.uniform(-2.0, 2.0)))[0]
                  for _ in range(18)]
        record = codec.records.AccelAngRateMagOrientation(
            tuple(floats[0:3]), tuple(floats[3:6]), tuple(floats[6:9]), tuple(floats[9:18]),
            (index * 196_608) % (1 << 32))
        records.append(codec.encode_record(record))
    return records


def build_stream(codec, frames, corruption, seed):
    """Return the chunks, the number of frames that must come out, and the source."""
    rng = random.Random(seed)
    records, source = _fixture_records()
    if not records:
        records, source = _synthetic_records(codec, rng), 'synthetic 0xCC records'
    stream = bytearray()
    expected = 0
    damaged = 0
    for index in range(frames):
        packet = bytearray(codec.encode_data_packet(
            ADDRESS, records[index % len(records)], index % 256, (7 * index) % 256))
        if rng.random() < corruption:
            bit = rng.randrange(len(packet) * 8)
            packet[bit // 8] ^= 1 << (bit % 8)
            damaged += 1
            # LQI and RSSI are outside the checksum: such a packet still counts as good.
            if bit // 8 in (len(packet) - 4, len(packet) - 3):
                expected += 1
        else:
            expected += 1
        stream += packet
    chunks = [bytes(stream[i:i + CHUNK]) for i in range(0, len(stream), CHUNK)]
    return chunks, expected, damaged, len(stream), source


def run_once(codec, chunks):
    """Feed every chunk to a fresh parser; return (wall s, CPU s, records, parser)."""
    parser = codec.SensorStreamParser(address=ADDRESS)
    feed = parser.feed
    count = 0
    cpu0 = time.process_time()
    wall0 = time.perf_counter()
    for chunk in chunks:
        for event in feed(chunk):
            if event.__class__ is codec.DataPacket:
                count += 1
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0
    return wall, cpu, count, parser


def _cpu_name():
    try:
        with open('/proc/cpuinfo') as cpuinfo:
            for line in cpuinfo:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _pin_to_one_core():
    if hasattr(os, 'sched_setaffinity'):
        try:
            core = min(os.sched_getaffinity(0))
            os.sched_setaffinity(0, {core})
            return f'pinned to core {core}'
        except OSError:
            pass
    return 'not pinned'


def main(argv=None):
    """Run the benchmark and print its figures; return the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--frames', type=int, default=200_000,
                        help='data packets in the stream (default 200000)')
    parser.add_argument('--corruption', type=float, default=0.01,
                        help='fraction of packets with one flipped bit (default 0.01)')
    parser.add_argument('--repeat', type=int, default=5,
                        help='timed runs; the best is reported (default 5)')
    parser.add_argument('--seed', type=int, default=1, help='random seed (default 1)')
    parser.add_argument('--require', type=float, default=0.0, metavar='RATE',
                        help='exit with status 1 if the best rate is below RATE frames/s')
    args = parser.parse_args(argv)
    if args.frames < 1 or not 0.0 <= args.corruption <= 1.0 or args.repeat < 1:
        parser.error('need --frames >= 1, 0 <= --corruption <= 1, --repeat >= 1')

    codec = _codec()
    pinned = _pin_to_one_core()
    chunks, expected, damaged, size, source = build_stream(
        codec, args.frames, args.corruption, args.seed)
    results = [run_once(codec, chunks) for _ in range(args.repeat)]
    wall, cpu, count, last = min(results, key=lambda r: r[0])
    if count != expected or any(r[2] != expected for r in results):
        print(f'ERROR: {count} records came out, {expected} expected', file=sys.stderr)
        return 2
    rates = [args.frames / r[0] for r in results]
    best = args.frames / wall

    print(f'source        : {source}')
    print(f'stream        : {args.frames:,} data packets of 88 bytes ({size:,} bytes), '
          f'{damaged:,} with one flipped bit ({100.0 * damaged / args.frames:.2f} %), '
          f'fed in {len(chunks):,} chunks of {CHUNK} bytes')
    print(f'records out   : {count:,} decoded 0xCC records (all expected ones)')
    print(f'counters      : {last.stats!r}')
    print(f'runs          : {args.repeat}, frames/s best {best:,.0f}, median '
          f'{statistics.median(rates):,.0f}, worst {min(rates):,.0f}; '
          f'CPU time of the best run {cpu:.3f} s for {wall:.3f} s wall')
    print(f'per frame     : {1e6 * wall / args.frames:.2f} us (bytes in, record out); '
          f'{args.frames / min(r[1] for r in results):,.0f} frames per CPU second '
          '(less sensitive to other load)')
    print(f'machine       : {_cpu_name()}, {platform.machine()}, {os.cpu_count()} CPUs, '
          f'{pinned}')
    print(f'python        : {platform.python_implementation()} {platform.python_version()} '
          f'({platform.system()} {platform.release()})')
    print(f'line limit    : 115200 baud carries at most ~{LINE_LIMIT} such packets/s: '
          f'{best / LINE_LIMIT:,.0f}x headroom')
    print(f'target        : {TARGET:,} frames/s: {"met" if best >= TARGET else "NOT met"}')
    print()
    print(f'README: The codec parses and decodes about {round(best, -4):,.0f} 0xCC data packets '
          'per second '
          f'on one core ({_cpu_name()}, {platform.python_implementation()} '
          f'{platform.python_version()}; {args.corruption:.0%} of packets corrupted, '
          f'{CHUNK}-byte chunks; `python benchmarks/codec_throughput.py`).')
    if best < args.require:
        print(f'FAIL: {best:,.0f} frames/s is below the required {args.require:,.0f}',
              file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
