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
How long ``discover`` takes on one port: the factory range, a stream, nothing.

The simulated base station and sensor run in a process of their own, as a
real one would. Each case probes the port five times in this process
(``probe_port``, what the command runs per port) and reports the median and
the worst, with the time the ping sweep alone took; one more run times the
whole command (``python -m i3dmgx2_driver.tools.discover``, interpreter start
included). The simulator answers a ping at once, so the sweep measures the
host side and the pseudo-terminal, not a radio: a real base station adds its
own ping time to each of the 99.

    python benchmarks/discover_speed.py [--full]
"""

import argparse
import os
import statistics
import subprocess
import sys
import time
import tty

from bench_common import OtherLoad, REPO, report, Result
from harness.processes import ros_env, SimProcess

from i3dmgx2_driver.tools.discover import probe_port, ProbeConfig  # noqa: I100 - after the path

#: Probes of each case.
RUNS = 5


def _probe_times(path: str, runs: int, config: ProbeConfig) -> tuple[list[float], list[float],
                                                                     int]:
    totals, sweeps, found = [], [], 0
    for _ in range(runs):
        result = probe_port(path, config)
        totals.append(result.seconds)
        sweeps.append(result.ping_seconds)
        found = len(result.sensors)
    return totals, sweeps, found


def _row(name: str, totals: list[float], sweeps: list[float], pings: int,
         found: int) -> Result:
    per_ping = statistics.median(sweeps) / pings * 1000 if pings else 0.0
    value = (f'{statistics.median(totals):.2f} s (worst {max(totals):.2f}); sweep '
             f'{statistics.median(sweeps) * 1000:.0f} ms, {per_ping:.2f} ms a ping; '
             f'{found} found')
    return Result(name, value)


def main() -> int:
    """Measure and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--full', action='store_true', help='also sweep 1..65534 once')
    args = parser.parse_args()
    load = OtherLoad()
    config = ProbeConfig()
    results = []
    cases = [('factory range 1..99, one polled sensor (95)', {}),
             ('factory range, one sensor streaming 0xCC at 100 Hz', {'streaming_at_start': 204}),
             ('factory range, no sensor there (address 4242)', {'address': 4242}),
             ('a wired sensor (no base station: 2 silent pings, then asked directly)',
              {'wireless': False})]
    for name, spec in cases:
        sim = SimProcess(**spec)
        try:
            totals, sweeps, found = _probe_times(sim.port, RUNS, config)
            pings = 98 if spec.get('streaming_at_start') else 99
            if spec.get('wireless') is False:
                pings = config.silent_pings
            results.append(_row(name, totals, sweeps, pings, found))
            if not spec:
                start = time.monotonic()
                subprocess.run([sys.executable, '-m', 'i3dmgx2_driver.tools.discover',
                                '--port', sim.port], env=ros_env(), cwd=str(REPO),
                               capture_output=True, check=True)
                results.append(Result('the whole command on that port (interpreter start '
                                      'included)', f'{time.monotonic() - start:.2f} s'))
            if args.full and spec.get('address') == 4242:
                totals, sweeps, found = _probe_times(
                    sim.port, 1, ProbeConfig(addresses=range(1, 65535)))
                results.append(_row('full range 1..65534 (sensor at 4242)', totals, sweeps,
                                    65534, found))
        finally:
            sim.stop()
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        totals, sweeps, found = _probe_times(os.ttyname(slave), RUNS, config)
        results.append(_row('a port with no base station and no sensor', totals, sweeps,
                            config.silent_pings, found))
    finally:
        os.close(slave)
        os.close(master)
    report('discover: time to probe one port', results,
           [f'Defaults: listen {config.listen_s} s, ping timeout {config.ping_timeout} s, '
            f'{RUNS} runs a case.'],
           output='discover_speed.md', other_load=load)
    return 0


if __name__ == '__main__':
    sys.exit(main())
