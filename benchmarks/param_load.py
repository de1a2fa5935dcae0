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
Load on the node's executor from another process: parameter requests, slow services.

Keeps several parameter requests (get, set, list, describe, in turn) in flight
at all times against the driver node, as fast as it answers them, and with
``--slow-service NAME`` also calls that std_srvs/Trigger service of the node
again and again (one call at a time). Prints ``ready`` once the node's
services are there and, on SIGTERM, SIGINT or end of standard input, writes
how many requests of each kind were answered as JSON and exits.
"""

import argparse
import json
from pathlib import Path
import sys
import threading

from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import (
    DescribeParameters, GetParameters, ListParameters, SetParameters,
)
from rclpy.executors import MultiThreadedExecutor
from std_srvs.srv import Trigger

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from harness.processes import spin_until, start_helper_node  # noqa: E402, I100

#: Parameters asked about; ``qos_depth`` is read-only, so a set is refused (and still served).
NAMES = ['port', 'address', 'frame_id', 'time_source', 'qos_depth', 'low_latency']


def _requests() -> list[tuple[str, type, object]]:
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


def main(argv: list[str] | None = None) -> int:
    """Load the node until told to stop; then save the counts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--out', required=True, help='where to write the counts (JSON)')
    parser.add_argument('--node', default='/i3dmgx2_driver', help='the driver node')
    parser.add_argument('--in-flight', type=int, default=4,
                        help='parameter requests kept in flight (default 4)')
    parser.add_argument('--slow-service', default='',
                        help='also call this Trigger service of the node in a loop')
    args = parser.parse_args(argv)
    stop, node = start_helper_node('i3dmgx2_benchmark_load')
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    counts: dict[str, int] = {}
    lock = threading.Lock()
    kinds = _requests()
    clients = {name: node.create_client(srv, f'{args.node}/{name}') for name, srv, _ in kinds}
    slow = (node.create_client(Trigger, f'{args.node}/{args.slow_service}')
            if args.slow_service else None)
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
        send(index + args.in_flight)

    def call_slow(future: object = None) -> None:
        if future is not None:
            result = future.result()
            key = f'{args.slow_service} ({"ok" if result and result.success else "failed"})'
            with lock:
                counts[key] = counts.get(key, 0) + 1
        if not stop.is_set():
            slow.call_async(Trigger.Request()).add_done_callback(call_slow)

    print('ready', flush=True)
    for index in range(args.in_flight):
        send(index)
    if slow is not None:
        call_slow()

    def save() -> None:
        with lock, open(args.out, 'w') as handle:
            json.dump(counts, handle)

    spin_until(stop, executor, node, save)
    return 0


if __name__ == '__main__':
    sys.exit(main())
