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
How light a record's trip is: the package's own Python calls on the reader thread, a record.

Runs the simulated device at 100 Hz streaming 0xCC and the real node in a
process of its own, started through this file (``--child``): it installs
``threading.setprofile`` before the node makes its threads, counts on the
``gx2-reader`` thread alone every Python call whose code lives in the
package (rclpy's, the standard library's and C calls are not counted) and
every record published (``RecordPublisher.on_record`` called), and writes
both at exit. The first ``--warm-up`` seconds' records are left out: the
figure is the steady state. Nothing of the node is replaced; the profile
function is this file's. ``--tree DIR`` counts another checkout's driver
(``git worktree add /tmp/before <commit>``).

    python benchmarks/record_calls.py                   # 180 s, as issue 55 measures
    python benchmarks/record_calls.py --seconds 60 --tree /tmp/before
"""

import argparse
from collections import Counter
import json
import os
from pathlib import Path
import sys
import tempfile
import threading
import time

#: The thread whose calls are counted.
READER_THREAD = 'gx2-reader'
#: Environment variable naming the child's output file.
OUT_ENV = 'I3DMGX2_CALLS'


def _child(argv: list[str]) -> int:
    """Run the node with the reader thread's calls counted (the node's own process)."""
    import i3dmgx2_driver
    from i3dmgx2_driver.ros import main as node_main

    root = os.path.dirname(i3dmgx2_driver.__file__)
    warm_up = float(os.environ.get('I3DMGX2_CALLS_WARM_UP', '5'))
    calls: Counter = Counter()
    state = {'records': 0, 'counting': False, 'start': 0.0, 'calls': 0, 'from': 0}
    ours: dict = {}

    def profile(frame, event, _arg):
        if event != 'call':
            return
        code = frame.f_code
        mine = ours.get(code)
        if mine is None:
            mine = ours[code] = code.co_filename.startswith(root)
        if not mine:
            return
        if code.co_name == 'on_record':
            state['records'] += 1
            if not state['counting'] and time.monotonic() - state['start'] > warm_up:
                state['counting'] = True
                state['from'] = state['records'] - 1
        if state['counting']:
            state['calls'] += 1
            calls[f'{os.path.relpath(code.co_filename, root)}:{code.co_name}'] += 1

    def install(frame, event, arg):
        # Every new thread starts with this; only the reader keeps a profile. The node's
        # own hook (realtime.name_os_threads names the OS thread) runs first.
        if chained:
            chained[-1](frame, event, arg)
        if threading.current_thread().name == READER_THREAD:
            sys.setprofile(profile)
            profile(frame, event, arg)
        else:
            sys.setprofile(None)

    state['start'] = time.monotonic()
    chained: list = []
    threading.setprofile(install)
    threading.setprofile = chained.append  # the node's hook is chained, not put in ours' place
    try:
        return node_main.main(argv)
    finally:
        sys.setprofile(None)
        records = state['records'] - state['from'] if state['counting'] else 0
        with open(os.environ[OUT_ENV], 'w') as handle:
            json.dump({'records': records, 'calls': state['calls'],
                       'by_function': calls.most_common()}, handle)


def main(argv: list[str] | None = None) -> int:
    """Run the node against the simulator, print the calls a record."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n', 1)[0])
    parser.add_argument('--seconds', type=float, default=180.0,
                        help='streaming time (default 180 s, as issue 55 counted)')
    parser.add_argument('--warm-up', type=float, default=5.0,
                        help='seconds of records left out at the start (default 5)')
    parser.add_argument('--rate', type=float, default=100.0, help='data rate (Hz)')
    parser.add_argument('--tree', type=Path, help="another checkout's driver")
    parser.add_argument('--top', type=int, default=25, help='functions listed (default 25)')
    args = parser.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_common import machine_table
    from harness.processes import (
        ADDRESS, isolate_ros_domain, NodeProcess, ros_env, SimProcess,
    )

    isolate_ros_domain()
    handle, out = tempfile.mkstemp(prefix='i3dmgx2-calls-', suffix='.json')
    os.close(handle)
    sim = SimProcess(rate_hz=args.rate)
    try:
        env = ros_env({OUT_ENV: out, 'I3DMGX2_CALLS_WARM_UP': str(args.warm_up)})
        node = NodeProcess({'port': sim.port, 'address': ADDRESS, 'data_rate': args.rate},
                           command=[sys.executable, str(Path(__file__).resolve()), '--child'],
                           env=env, tree=args.tree)
        try:
            if not node.wait_for_output('streaming 0x', 60.0):
                raise SystemExit(f'the node did not stream: {node.output()}')
            time.sleep(args.seconds)
        finally:
            node.stop()
        with open(out) as handle:
            document = json.load(handle)
    finally:
        sim.stop()
        os.unlink(out)
    records, calls = document['records'], document['calls']
    print(f'# Calls of the package on the reader thread ({args.seconds:.0f} s at '
          f'{args.rate:g} Hz, 0xCC; the first {args.warm_up:g} s left out)\n')
    print(f'records published: {records}')
    print(f'calls: {calls}, **{calls / max(records, 1):.1f} a record**\n')
    print('| function | calls a record |\n|---|---|')
    for name, count in document['by_function'][:args.top]:
        print(f'| `{name}` | {count / max(records, 1):.2f} |')
    print('\n' + machine_table())
    return 0


if __name__ == '__main__':
    if sys.argv[1:2] == ['--child']:
        sys.exit(_child(sys.argv[2:]))
    sys.exit(main())
