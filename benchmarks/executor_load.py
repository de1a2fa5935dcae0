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

The node streams at 100 Hz (timed as in latency.py) while another process
keeps parameter requests (get, set, list, describe, in turn) in flight
against it as fast as it answers, and, in another run, also calls the
node's ``~/self_test`` service (std_srvs/Trigger, seconds long) in a loop.
Reported: the latency write -> publish() returned without load, with the
parameter load, and with both; and how many requests were served. A
control run replaces the requests by two CPU-bound processes that never
talk to the node: on a 2-core machine the requests cost what any two busy
processes cost (the CPU is shared), and nothing more.

The load is this script too, run by itself with ``--load`` in a process of
its own: it prints ``ready`` once the node's services are there and, on
SIGTERM, SIGINT or the end of its standard input, writes how many requests
of each kind were answered as JSON to ``--out`` and exits.
"""

import subprocess
import sys
import threading
from typing import Any

from bench_common import BENCH_DIR, report, Result, standard_args, summarise
from harness.processes import ChildProcess, isolate_ros_domain, spin_until, start_helper_node
from latency import CONFIGS, run_once, TARGET_DRIVER_P99_S

SLOW_SERVICE = 'self_test'
#: Parameter requests the load keeps in flight.
IN_FLIGHT = 4
#: Parameters asked about; ``qos_depth`` is read-only, so a set is refused (and still served).
NAMES = ['port', 'address', 'frame_id', 'time_source', 'qos_depth', 'low_latency']


# -- the load, in a process of its own -------------------------------------------------------

def _requests() -> list[tuple[str, type, object]]:
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import (
        DescribeParameters, GetParameters, ListParameters, SetParameters,
    )
    set_request = SetParameters.Request()
    set_request.parameters = [Parameter(
        name='qos_depth', value=ParameterValue(type=ParameterType.PARAMETER_INTEGER,
                                               integer_value=20))]
    return [
        ('get_parameters', GetParameters, GetParameters.Request(names=NAMES)),
        ('set_parameters', SetParameters, set_request),
        ('list_parameters', ListParameters, ListParameters.Request()),
        ('describe_parameters', DescribeParameters, DescribeParameters.Request(names=NAMES)),
    ]


def load(out: str, slow_service: str, target: str = '/i3dmgx2_driver') -> int:
    """Load the node until told to stop; then save the counts to ``out``."""
    import json

    from rclpy.executors import MultiThreadedExecutor
    from std_srvs.srv import Trigger

    stop, node = start_helper_node('i3dmgx2_benchmark_load')
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    counts: dict[str, int] = {}
    lock = threading.Lock()
    kinds = _requests()
    clients = {name: node.create_client(srv, f'{target}/{name}') for name, srv, _ in kinds}
    slow = node.create_client(Trigger, f'{target}/{slow_service}') if slow_service else None
    for client in [*clients.values(), *([slow] if slow else [])]:
        while not client.wait_for_service(timeout_sec=0.5):
            executor.spin_once(timeout_sec=0.1)
            if stop.is_set():
                return 1

    def send(index: int) -> None:
        if stop.is_set():
            return
        name, _, request = kinds[index % len(kinds)]
        future = clients[name].call_async(request)
        future.add_done_callback(lambda _, n=name, i=index: done(n, i))

    def done(name: str, index: int) -> None:
        with lock:
            counts[name] = counts.get(name, 0) + 1
        send(index + IN_FLIGHT)

    def call_slow(future: Any = None) -> None:
        if future is not None:
            result = future.result()
            key = f'{slow_service} ({"ok" if result and result.success else "failed"})'
            with lock:
                counts[key] = counts.get(key, 0) + 1
        if not stop.is_set():
            slow.call_async(Trigger.Request()).add_done_callback(call_slow)

    print('ready', flush=True)
    for index in range(IN_FLIGHT):
        send(index)
    if slow is not None:
        call_slow()

    def save() -> None:
        with lock, open(out, 'w') as handle:
            json.dump(counts, handle)

    spin_until(stop, executor, node, save)
    return 0


class LoadProcess(ChildProcess):
    """Parameter requests (and a slow service) against the node from another process."""

    def __init__(self, slow_service: str = '') -> None:
        self._argv = [sys.executable, str(BENCH_DIR / 'executor_load.py'), '--load',
                      '--slow-service', slow_service]
        self.counts: dict[str, int] = {}
        self.started = False

    def start(self) -> None:
        """Start loading the node (returns once the requests flow)."""
        super().__init__(self._argv, 'ready', timeout=30.0)
        self.started = True

    def stop(self, timeout: float = 15.0) -> dict[str, int]:
        """Stop; return and keep how many requests of each kind were answered."""
        if self.started:
            self.counts = super().stop(timeout)
            self.started = False
        return self.counts


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


# -- the benchmark ---------------------------------------------------------------------------

def run(seconds: float) -> list[Result]:
    """Measure without load, with parameter load, and with a slow service too."""
    isolate_ros_domain()
    results = []
    runs = (('no load', None),
            ('parameter requests from another process', LoadProcess()),
            (f'parameter requests + ~/{SLOW_SERVICE} calls in a loop',
             LoadProcess(slow_service=SLOW_SERVICE)),
            ('control: 2 CPU-bound processes, no requests', CpuBurners(2)))
    for label, loader in runs:
        measured = run_once(CONFIGS['default'], seconds, 100.0, load=loader)
        pub, driver = summarise(measured.end_to_end), summarise(measured.driver)
        results.append(Result(f'latency write -> publish() at 100 Hz, {label}: '
                              f'p50 / p99 / max', pub.ms()))
        results.append(Result(f'  of which read() returned -> publish() returned (driver), '
                              f'{label}', driver.ms(), 'p99 <= 0.100 ms',
                              driver.p99 <= TARGET_DRIVER_P99_S))
        if isinstance(loader, LoadProcess):
            served = ', '.join(f'{name} {count / seconds:.0f}/s'
                               for name, count in sorted(loader.counts.items()))
            results.append(Result(f'  requests answered during that run ({label})',
                                  served or 'none'))
    return results


def _options(parser: Any) -> None:
    parser.add_argument('--load', action='store_true',
                        help='be the load process (this benchmark starts it itself)')
    parser.add_argument('--out', help='--load: where to write the counts (JSON)')
    parser.add_argument('--slow-service', default='',
                        help='--load: also call this Trigger service of the node in a loop')


def main() -> int:
    """Run from the command line: the benchmark, or (``--load``) its load."""
    args = standard_args(__doc__.splitlines()[1], 30.0, more=_options)
    if args.load:
        return load(args.out, args.slow_service)
    results = run(args.seconds)
    report('Publishing under executor load (issue #6)', results,
           [f'{args.seconds:g} s per run; {IN_FLIGHT} parameter requests kept in flight; '
            f'~/{SLOW_SERVICE} pauses the stream while it talks to the device, so '
            f'fewer records are published in that run.'],
           'executor_load.md', other_load=args.other_load)
    return 0


if __name__ == '__main__':
    sys.exit(main())
