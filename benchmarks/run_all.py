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
Every benchmark, one table: ``python benchmarks/run_all.py [--quick]``.

Runs the codec throughput (``codec_throughput.py``, in a process of its own
because it pins itself to one core), then latency, sustained rate, CPU,
timestamps, publishing under executor load, every stream at the line's
limit and shutdown at random moments (a few hundred; ``shutdown.py`` runs
thousands), and prints one Markdown table
(metric, value, target, met?) with the machine it ran on; the same text goes
to ``benchmarks/output/results.md``. The full run takes about 15 minutes,
``--quick`` about 3. The figures depend on the machine and on whatever else
runs on it (the load average is printed): benchmarks report, they never fail.
"""

import argparse
import os
import re
import subprocess
import sys
import time

from bench_common import (
    BENCH_DIR, machine_table, markdown_table, OtherLoad, OUTPUT_DIR, REPO, Result,
)
import cpu
import executor_load
from harness.processes import ros_env
import latency
import several_sensors
import shutdown
import streams
import throughput
import timestamps

CODEC_TARGET = 250_000


def codec_results(quick: bool) -> list[Result]:
    """Run codec_throughput.py; return its best frames/s as a table row."""
    argv = [sys.executable, str(BENCH_DIR / 'codec_throughput.py')]
    if quick:
        argv += ['--frames', '50000', '--repeat', '3']
    done = subprocess.run(argv, capture_output=True, text=True, env=ros_env(),
                          cwd=str(REPO), check=False)
    match = re.search(r'frames/s best ([\d,]+)', done.stdout)
    if not match:
        return [Result('codec decode throughput (0xCC packets, one core)',
                       f'failed: {(done.stderr or done.stdout).strip()[-200:]}',
                       f'>= {CODEC_TARGET:,} frames/s', False)]
    best = int(match.group(1).replace(',', ''))
    return [Result('codec decode throughput (0xCC packets, one core)', f'{best:,} frames/s',
                   f'>= {CODEC_TARGET:,} frames/s', best >= CODEC_TARGET)]


def main() -> int:
    """Run every benchmark; print and save the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='short runs (about 3 minutes)')
    args = parser.parse_args()
    quick = args.quick
    started = time.monotonic()
    load_before = os.getloadavg()[0]
    other = OtherLoad()
    steps = [
        ('codec', lambda: codec_results(quick)),
        ('latency', lambda: latency.run(8.0 if quick else 30.0)),
        ('sustained rate', lambda: throughput.run(
            5.0 if quick else 60.0, (1000.0, 4000.0) if quick else throughput.RATES)),
        ('CPU', lambda: cpu.run(8.0 if quick else 30.0)),
        ('timestamps', lambda: timestamps.run(15.0 if quick else 60.0)),
        ('executor load', lambda: executor_load.run(8.0 if quick else 30.0)),
        ('streams', lambda: streams.run(6.0 if quick else 20.0)[0]),
        ('several sensors', lambda: several_sensors.run(6.0 if quick else 20.0)),
        ('shutdown', lambda: shutdown.run(48 if quick else 240)),
    ]
    results: list[Result] = []
    for name, step in steps:
        print(f'-- {name} ...', file=sys.stderr, flush=True)
        try:
            results += step()
        except Exception as exc:  # report the failure in the table, go on
            results.append(Result(f'{name}: benchmark failed', f'{type(exc).__name__}: {exc}'))
    minutes = (time.monotonic() - started) / 60.0
    load_after = os.getloadavg()[0]
    text = '\n'.join([
        f'## Benchmarks{" (--quick)" if quick else ""}', '',
        machine_table(), '',
        markdown_table(results), '',
        f'- Run: `python benchmarks/run_all.py{" --quick" if quick else ""}`, '
        f'{minutes:.1f} min; load average (1 min) {load_before:.2f} before, '
        f'{load_after:.2f} after; other processes kept {other.cores():.2f} of '
        f'{os.cpu_count()} cores busy on average meanwhile.',
        '- Latency: `time.time()` right after the simulator (its own process) wrote a '
        "packet's last byte to the pty, to right after `publish()` returned in the node.",
        '- Original C++ node (thesis): 0.99 ms mean, 1.16 ms max.',
    ]) + '\n'
    print(text, flush=True)
    OUTPUT_DIR.mkdir(parents=True, exist_ok=True)
    (OUTPUT_DIR / 'results.md').write_text(text)
    print(f'(written to {(OUTPUT_DIR / "results.md").relative_to(REPO)})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
