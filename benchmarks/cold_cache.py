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
What a record's Python costs warm, and after the idle between two records.

At 100 Hz the reader thread sleeps 10 ms between records, and on a virtual
machine whatever the host ran meanwhile has the caches: every step of the
hot path then costs many times what it costs in a loop. This times each
step of one record (the parser, the sample clock, the two packers) and a
few single operations, in a loop and after ``--gap`` s asleep (a record's
period), each in this thread: the medians of ``--samples`` tries. The
figures are docs/cpu.md's "Why a record costs what it costs".

    python benchmarks/cold_cache.py
    python benchmarks/cold_cache.py --gap 0.001 --samples 300
"""

import argparse
from collections.abc import Callable
import statistics
import struct
import sys
import time

from bench_common import emit, machine_table, RunNote

from i3dmgx2_driver.codec import commands, framing
from i3dmgx2_driver.codec.parser import SensorStreamParser
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.device.sample_clock import SampleClock
from i3dmgx2_driver.ros.conversions import MessageFactory, MessageSettings

#: Ticks between two records at 100 Hz (the device timer's 19,660.8 ticks a second).
TICKS_AT_100_HZ = 1966
#: One record's time on the line at 115200 baud, what the clock is told (s).
WIRE_S = 0.0076


def steps() -> dict[str, Callable[[int], object]]:
    """Return each step to time, called with the record's index."""
    record = AccelAngRateMagOrientation((0.125, -0.5, -1.0), (0.01, -0.02, 0.03), (0.2, -0.1, 0.4),
                                        (0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0), 123456)
    packets = [framing.encode_data_packet(
        95, commands.encode_record(record._replace(timer=1000 + i * TICKS_AT_100_HZ)), 200, 100)
        for i in range(4096)]
    parser = SensorStreamParser(95)
    clock = SampleClock()
    factory = MessageFactory(MessageSettings('imu_link', 'enu'))
    host = time.monotonic() + 1000.0
    values = parser.feed(packets[0])[0].values
    unpack = struct.Struct('>' + 'f' * 18 + 'I').unpack_from
    return {
        'parser.feed, one packet': lambda i: parser.feed(packets[i]),
        'SampleClock.stamp': lambda i: clock.stamp(1000 + i * TICKS_AT_100_HZ,
                                                   host + i * 0.01, WIRE_S),
        'MessageFactory.imu_cdr': lambda i: factory.imu_cdr(values, 1_700_000_000, i),
        'MessageFactory.mag_cdr': lambda i: factory.mag_cdr(values, 1_700_000_000, i),
        'an empty lambda': lambda i: None,
        'one struct unpack (19 fields)': lambda i: unpack(packets[i], 8),
        'sum of 83 bytes (the checksum)': lambda i: sum(packets[i][1:84]),
    }


def median_us(step: Callable[[int], object], gap: float, samples: int) -> float:
    """Return the median time of ``step`` (us), each try after ``gap`` s asleep (0: none)."""
    clock = time.perf_counter
    times = []
    for i in range(samples):
        if gap:
            time.sleep(gap)
        start = clock()
        step(i % 4096)
        times.append(clock() - start)
    return statistics.median(times[samples // 10:]) * 1e6


def main(argv: list[str] | None = None) -> int:
    """Time every step warm and after the gap; print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--gap', type=float, default=0.01, help='s asleep before each try')
    parser.add_argument('--samples', type=int, default=400)
    args = parser.parse_args(argv)
    note = RunNote('cold_cache.py', argv)
    lines = ["## A record's Python, warm and after the idle between records", '',
             machine_table(), '',
             f'| step | in a loop (us) | after {args.gap * 1e3:g} ms asleep (us) | ratio |',
             '|---|---|---|---|']
    for name, step in steps().items():
        warm = median_us(step, 0.0, args.samples)
        cold = median_us(step, args.gap, args.samples)
        lines.append(f'| {name} | {warm:.1f} | {cold:.1f} | {cold / warm:.0f} |')
    lines += ['', note.text(f'{args.samples} tries a step; medians without the first tenth; ')]
    emit('\n'.join(lines) + '\n', 'cold_cache.md')
    return 0


if __name__ == '__main__':
    sys.exit(main())
