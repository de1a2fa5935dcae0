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
Issue #6: parameter requests and a slow service must not delay publishing.

The node streams at 100 Hz (in this process, timed as in latency.py) while
another process keeps parameter requests (get, set, list, describe) in
flight against it as fast as it answers, and, in another run, also calls
the node's ``~/self_test`` service (std_srvs/Trigger, seconds long) in a
loop. Reported: the latency write -> publish() returned without load, with
the parameter load, and with both; and how many requests were served. A
control run replaces the requests by two CPU-bound processes that never
talk to the node: on a 2-core machine the requests cost what any two busy
processes cost (the CPU is shared), and nothing more.
"""

import subprocess
import sys

from bench_common import LoadProcess, Result, run_benchmark
from harness.percentiles import summarise
from harness.processes import isolate_ros_domain
from latency import CONFIGS, run_once, TARGET_DRIVER_P99_S

SLOW_SERVICE = 'self_test'


class CpuBurners:
    """Control load: processes that only burn CPU, nothing to do with ROS."""

    def __init__(self, count: int = 2) -> None:
        self.count = count
        self.counts: dict[str, int] = {}
        self._procs: list[subprocess.Popen] = []

    def start(self) -> None:
        """Start the busy processes."""
        self._procs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
                       for _ in range(self.count)]

    def stop(self) -> dict[str, int]:
        """Kill them."""
        for proc in self._procs:
            proc.kill()
            proc.wait()
        self._procs = []
        return self.counts


def run(seconds: float) -> list[Result]:
    """Measure without load, with parameter load, and with a slow service too."""
    isolate_ros_domain()
    results = []
    runs = (('no load', None),
            ('parameter requests from another process', LoadProcess()),
            (f'parameter requests + ~/{SLOW_SERVICE} calls in a loop',
             LoadProcess(slow_service=SLOW_SERVICE)),
            ('control: 2 CPU-bound processes, no requests', CpuBurners(2)))
    for label, load in runs:
        measured = run_once(CONFIGS['default'], seconds, 100.0, load=load)
        pub, driver = summarise(measured.end_to_end), summarise(measured.driver)
        results.append(Result(f'latency write -> publish() at 100 Hz, {label}: '
                              f'p50 / p99 / max', pub.ms()))
        results.append(Result(f'  of which read() returned -> publish() returned (driver), '
                              f'{label}', driver.ms(), 'p99 <= 0.100 ms',
                              driver.p99 <= TARGET_DRIVER_P99_S))
        if isinstance(load, LoadProcess):
            served = ', '.join(f'{name} {count / seconds:.0f}/s'
                               for name, count in sorted(load.counts.items()))
            results.append(Result(f'  requests answered during that run ({label})',
                                  served or 'none'))
    return results


def main() -> None:
    """Run from the command line."""
    run_benchmark(__doc__, (30.0, 8.0), run, 'Publishing under executor load (issue #6)',
                  'executor_load.md', lambda seconds: [
                      f'{seconds:g} s per run; 4 parameter requests kept in flight; '
                      f'~/{SLOW_SERVICE} pauses the stream while it talks to the device, so '
                      f'fewer records are published in that run.'])


if __name__ == '__main__':
    main()
