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
Issue #18: a node's memory against the faults it has met, to see whether it levels off.

The long soak's managed processes meet about 180 faults an hour and grow
by 1-2 MiB/h of anonymous memory; whether that is a warm-up (it levels
off) or a leak (it keeps its pace) needs many more faults than that. Here
one plain driver node (its own process, the instrumented one, which writes
its heaps in use) reads the simulator (in this process) streaming ``full``
at 100 Hz, and meets a fault every ``--every`` seconds, in turn: an unplug,
a power cycle, a stall long enough for a reconnect, and a burst of
garbage, corrupted and foreign packets. Every minute a row: faults so far,
anonymous RSS, the C heap in use, CPython's blocks; at the end, the slopes
of each by thirds of the run, per hour and per 100 faults. A warm-up shows
as thirds that fall off; a leak as thirds alike.

Prints numbers; passes or fails nothing.
"""

import argparse
import itertools
import json
import os
import sys
import tempfile
import time

import bench_common  # noqa: F401 - puts the repository on the path
from harness.instrumented_node import STATS_ENV
from harness.process_sampler import rss_kinds, slope_per_hour
from harness.processes import ADDRESS, isolate_ros_domain, NodeProcess, ros_env
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig


def _fault(sim: PtySimulator, kind: str) -> None:
    """Inflict one fault and return once it has ended."""
    if kind == 'unplug':
        sim.unplug(None)
        time.sleep(0.5)
        sim.replug()
    elif kind == 'power cycle':
        sim.power_cycle(0.3)
    elif kind == 'stall':
        sim.stall(1.5)
        time.sleep(1.5)
    else:  # noise
        sim.set_faults(garbage_probability=0.1, corrupt_checksum_probability=0.05,
                       foreign_probability=0.05)
        time.sleep(1.0)
        sim.set_faults(FaultConfig())


def _heap(path: str) -> tuple[int, int | None]:
    """Return (CPython blocks, C heap in use KiB) the node last wrote."""
    for _ in range(20):
        try:
            with open(path) as handle:
                heap = json.load(handle)['heap']
            return heap['python_blocks'], heap['malloc_in_use_kib']
        except (OSError, ValueError, KeyError):
            time.sleep(0.1)
    raise RuntimeError(f'the node wrote no heap figures to {path}')


def run(minutes: float, every: float, warm_up: float) -> None:
    """Stream ``warm_up`` s, then a fault every ``every`` s for ``minutes``; print the figures."""
    isolate_ros_domain()
    kinds = itertools.cycle(('unplug', 'power cycle', 'stall', 'noise'))
    rows: list[tuple[float, int, int, int, int]] = []  # (t, faults, anon KiB, C KiB, blocks)
    with tempfile.TemporaryDirectory(prefix='i3dmgx2-memory-') as workdir, \
            PtySimulator(SimulatorConfig(address=ADDRESS, seed=3, rate_hz=100)) as sim:
        path = os.path.join(workdir, 'stats.json')
        node = NodeProcess({'port': sim.port, 'address': ADDRESS},
                           command=(sys.executable, '-m', 'harness.instrumented_node'),
                           env=ros_env({STATS_ENV: path}))
        try:
            if not node.wait_for_output('first record received', timeout=30):
                raise RuntimeError('the node did not stream: ' + node.output()[-2000:])
            time.sleep(warm_up)
            print(f'{"min":>4} {"faults":>6} {"anon KiB":>9} {"C heap KiB":>10} '
                  f'{"blocks":>7}', flush=True)
            start = time.monotonic()
            faults = 0
            next_row = start
            while True:
                now = time.monotonic()
                if now >= next_row:
                    blocks, native = _heap(path)
                    anon = (rss_kinds(node.proc.pid) or (0, 0, 0))[0]
                    rows.append((now - start, faults, anon, native or 0, blocks))
                    print(f'{(now - start) / 60:4.0f} {faults:6d} {anon:9d} {native or 0:10d} '
                          f'{blocks:7d}', flush=True)
                    next_row += 60.0
                    if now - start >= minutes * 60.0:
                        break
                began = time.monotonic()
                _fault(sim, next(kinds))
                faults += 1
                time.sleep(max(0.0, every - (time.monotonic() - began)))
        finally:
            node.stop()
    _slopes(rows)


def _slopes(rows: list[tuple[float, int, int, int, int]]) -> None:
    """Print each figure's slope by thirds of the run: per hour, and per 100 faults."""
    third = rows[-1][0] / 3.0
    print('slopes by thirds of the run (per hour | per 100 faults):')
    for column, name, scale in ((2, 'anonymous RSS', 1 / 1024), (3, 'C heap', 1 / 1024),
                                (4, 'CPython blocks', 1.0)):
        parts = []
        for k in range(3):
            part = [r for r in rows if k * third <= r[0] <= (k + 1) * third]
            hourly = slope_per_hour([(r[0], r[column] * scale) for r in part])
            per_fault = slope_per_hour([(r[1], r[column] * scale) for r in part])
            unit = ' MiB' if scale != 1.0 else ''
            parts.append('n/a' if hourly is None or per_fault is None else
                         f'{hourly:+.3f}{unit} | {per_fault / 36:+.3f}{unit}')
        print(f'  {name:15s} ' + ';  '.join(parts))


def main() -> None:
    """Run from the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=45.0, help='minutes of faults')
    parser.add_argument('--every', type=float, default=3.0, help='seconds between faults')
    parser.add_argument('--warm-up', type=float, default=120.0,
                        help="seconds of streaming before the first row (the start-up's own)")
    run(**vars(parser.parse_args()))


if __name__ == '__main__':
    main()
