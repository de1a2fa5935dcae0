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
What the fault capture costs: the ring's memory, and the node's CPU with and without it.

Memory: a ring of the default 30 s filled in this process, as the reader
fills it at 100 Hz (one wireless 0xCC packet per read, each a new bytes
object), measured with ``tracemalloc``, beside its cap at 115200 baud.
CPU: the node at 100 Hz against the simulated device (its own process),
with a subscriber in a third, its user + system time over a window, with
the fault capture on (the default) and off (``fault_capture_dir: ''``),
the two alternating round by round in one run, so that both see the same
machine (latency.py's ``cpu`` configuration, its parameter set each way).
"""

import statistics
import time
import tracemalloc

from bench_common import report, Result, standard_args
from harness.processes import isolate_ros_domain
from i3dmgx2_driver.capture import CHUNK_COST, RecentBytes, RING_BUDGET_FACTOR
from i3dmgx2_driver.codec.line_budget import packet_size
from latency import CONFIGS, run_once, WARM_UP_S

SECONDS_KEPT = 30.0
RATE_HZ = 100.0
BAUD = 115200
CCODE = 0xCC


def ring_memory(seconds: float = SECONDS_KEPT, rate_hz: float = RATE_HZ) -> tuple[int, int, int]:
    """Return the bytes a full ring holds (tracemalloc), its reads, and its cap."""
    size = packet_size(CCODE, True)
    cap = int(seconds * BAUD / 10 * RING_BUDGET_FACTOR)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    ring = RecentBytes(seconds, cap)
    t = 1.8e9
    for i in range(int(2 * seconds * rate_hz)):  # twice the seconds: a full, trimming ring
        ring.on_bytes(bytes(size), t + i / rate_hz)
    used = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    return used, ring.held[0], cap


def append_cost(reads: int = 200_000) -> float:
    """Return the reader's cost of one append to a full ring (µs), the trimming included."""
    size = packet_size(CCODE, True)
    ring = RecentBytes(SECONDS_KEPT, int(SECONDS_KEPT * BAUD / 10 * RING_BUDGET_FACTOR))
    chunks = [bytes(size) for _ in range(64)]
    t = 1.8e9
    for i in range(int(SECONDS_KEPT * RATE_HZ)):
        ring.on_bytes(chunks[i % 64], t + i / RATE_HZ)
    t += SECONDS_KEPT
    on_bytes = ring.on_bytes
    start = time.perf_counter()
    for i in range(reads):
        on_bytes(chunks[i % 64], t + i / RATE_HZ)
    return (time.perf_counter() - start) / reads * 1e6


def measure(seconds: float, on: bool, directory: str) -> float:
    """Return the node's CPU at 100 Hz (% of one core), the fault capture on or off."""
    config = CONFIGS['cpu']
    config = config._replace(params=(*config.params,
                                     ('fault_capture_dir', directory if on else "''")))
    return run_once(config, seconds, RATE_HZ).cpu_percent


def run(seconds: float, rounds: int) -> list[Result]:
    """Measure the ring's memory and the CPU on and off; return the table rows."""
    import tempfile
    used, reads, cap = ring_memory()
    results = [Result(f'memory of a full {SECONDS_KEPT:g} s ring at {RATE_HZ:g} Hz '
                      '(0xCC, wireless, one packet per read)',
                      f'{used / 1024:.0f} KiB ({reads} reads; counted '
                      f'{reads * (packet_size(CCODE, True) + CHUNK_COST) / 1024:.0f} KiB; '
                      f'cap {cap / 1024:.0f} KiB at {BAUD} baud)')]
    micros = append_cost()
    results.append(Result('reader thread: one read appended to a full ring (trimming included)',
                          f'{micros:.2f} µs: {micros * RATE_HZ / 1e4:.4f} % of one core at '
                          f'{RATE_HZ:g} reads a second'))
    isolate_ros_domain()
    figures: dict[bool, list[float]] = {True: [], False: []}
    with tempfile.TemporaryDirectory() as directory:
        for _ in range(rounds):
            for on in (True, False):
                figures[on].append(measure(seconds, on, directory))
    for on, values in figures.items():
        results.append(Result(
            f'CPU at {RATE_HZ:g} Hz, fault capture {"on" if on else "off"} (% of one core): '
            'mean (each round)',
            f"{statistics.mean(values):.2f} % ({', '.join(f'{v:.2f}' for v in values)})"))
    return results


def _options(parser) -> None:
    parser.add_argument('--rounds', type=int, default=3, help='rounds of on and off')


def main() -> None:
    """Run from the command line."""
    args = standard_args(__doc__.splitlines()[1], 30.0, more=_options)
    results = run(args.seconds, args.rounds)
    report('Fault capture cost', results,
           [f'{args.rounds} rounds, each {args.seconds:g} s per setting after {WARM_UP_S:g} s '
            'of warm-up, on and off alternating; a subscriber in another process.'],
           'fault_capture.md', other_load=args.other_load)


if __name__ == '__main__':
    main()
