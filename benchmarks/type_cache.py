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
Issue #18: what holds the CPython blocks a streaming node keeps (a bounded cache).

The long soak saw CPython's block count of a streaming node grow by about
1.5 a second, and tracemalloc placed the survivors in rclpy's ``publish()``
of ``/diagnostics``. They are the attribute names the generated message
code looks up by C string (``PyObject_GetAttrString`` makes a new ``str``
each time): CPython's type method cache keeps a reference to the name of
each lookup it caches, in a table of 4,096 entries (``MCACHE_SIZE_EXP``
12) indexed by the name's *address*, so fresh names at new addresses fill
it slowly and it keeps at most 4,096 of them. This run shows it: the driver
node streams ``full`` at 100 Hz from the simulator (in another process)
for ``--minutes``; every minute it prints the blocks alive whose allocation
lies in ``publish()``; then ``sys._clear_type_cache()`` empties the cache,
and the count falls to a few dozen, and refills, never past the table.

With ``--faults N`` it looks for what grows with the faults instead: the
node (in this process) reads the simulator (in this process too, its
allocations left out) and meets faults in turn, as in ``memory_curve.py``,
each ended and the stream back before the next; after ``--warm-up-faults``
and again after ``N`` more, tracemalloc's snapshot and the live objects by
type are taken, and what grew between them is printed, by allocation site
(with its callers) and by type. Something that keeps a little of every fault
shows as a site whose count grows with ``N``.

Prints numbers; passes or fails nothing.
"""

import argparse
import collections
import gc
import itertools
import sys
import threading
import time
import tracemalloc

import bench_common  # noqa: F401 - puts the repository on the path
from harness.processes import ADDRESS, isolate_ros_domain, SimProcess
from memory_curve import inflict, KINDS

#: Entries of CPython's type method cache (1 << MCACHE_SIZE_EXP): the most it keeps.
TYPE_CACHE_ENTRIES = 4096


def kept_in_publish() -> int:
    """Return how many live blocks were allocated inside rclpy's ``Publisher.publish``."""
    snapshot = tracemalloc.take_snapshot()
    return sum(1 for trace in snapshot.traces
               if any(frame.filename.endswith('rclpy/publisher.py') for frame in trace.traceback))


def run(minutes: float) -> None:
    """Stream for ``minutes``, then empty the type cache; print the counts as they come."""
    import rclpy
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.parameter import Parameter

    from i3dmgx2_driver.ros.imu_node import ImuDriverNode

    isolate_ros_domain()
    sim = SimProcess(rate_hz=100)
    rclpy.init()
    tracemalloc.start(3)
    node = ImuDriverNode(parameter_overrides=[Parameter('port', value=sim.port),
                                              Parameter('address', value=ADDRESS)])
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()

    def sample(label: str) -> None:
        gc.collect()
        print(f'{label:36s} blocks {sys.getallocatedblocks():7d}, '
              f'kept from publish() {kept_in_publish():5d}', flush=True)

    try:
        time.sleep(30.0)
        for minute in range(max(1, round(minutes))):
            time.sleep(60.0)
            sample(f'streaming, after {minute + 1} min')
        sys._clear_type_cache()
        sample('right after sys._clear_type_cache()')
        time.sleep(60.0)
        sample('one minute later')
    finally:
        node.shutdown()
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown()
        sim.stop()
    print(f'(the type cache has {TYPE_CACHE_ENTRIES} entries: what it keeps is bounded)')


def _by_type() -> collections.Counter:
    """Count the objects the garbage collector tracks, by type name."""
    gc.collect()
    return collections.Counter(type(o).__qualname__ for o in gc.get_objects())


#: Left out of the snapshots: the simulator's threads (its ground truth grows by design),
#: tracemalloc's own and the import machinery's.
_NOT_THE_NODE = (tracemalloc.Filter(False, '*/simulator/*', all_frames=True),
                 tracemalloc.Filter(False, tracemalloc.__file__),
                 tracemalloc.Filter(False, '<frozen importlib._bootstrap*>'))


def run_faults(faults: int, warm_up: int, top: int) -> None:
    """Meet ``warm_up`` faults, then ``faults`` more; print what grew in between."""
    import rclpy
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.parameter import Parameter

    from i3dmgx2_driver.ros.imu_node import ImuDriverNode
    from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig

    isolate_ros_domain()
    rclpy.init()
    tracemalloc.start(12)
    kinds = itertools.cycle(KINDS)
    with PtySimulator(SimulatorConfig(address=ADDRESS, seed=3, rate_hz=100)) as sim:
        node = ImuDriverNode(parameter_overrides=[Parameter('port', value=sim.port),
                                                  Parameter('address', value=ADDRESS)])
        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        threading.Thread(target=executor.spin, daemon=True).start()

        def published() -> int:
            return node.core.records.stats.published

        def back_after(count: int, timeout: float = 20.0) -> bool:
            deadline = time.monotonic() + timeout
            while published() < count + 10:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.02)
            return True

        def meet(n: int) -> None:
            for _ in range(n):
                kind = next(kinds)
                inflict(sim, kind)
                if not back_after(published()):
                    print(f'{kind}: the stream was not back within 20 s', flush=True)

        try:
            back_after(0, 30.0)
            meet(warm_up)
            before, types_before = tracemalloc.take_snapshot(), _by_type()
            blocks_before = sys.getallocatedblocks()
            began = time.monotonic()
            meet(faults)
            after, types_after = tracemalloc.take_snapshot(), _by_type()
            print(f'{faults} faults in {time.monotonic() - began:.0f} s after {warm_up}: '
                  f'CPython blocks {blocks_before} -> {sys.getallocatedblocks()}')
        finally:
            node.shutdown()
            executor.shutdown()
            node.destroy_node()
            rclpy.shutdown()
    growth = after.filter_traces(_NOT_THE_NODE).compare_to(
        before.filter_traces(_NOT_THE_NODE), 'traceback')
    print(f'allocation sites that grew most (blocks, KiB), top {top}:')
    for stat in [s for s in growth if s.count_diff > 0][:top]:
        print(f'  {stat.count_diff:+6d} blocks {stat.size_diff / 1024:+8.1f} KiB, at')
        for line in stat.traceback.format(limit=6, most_recent_first=True):
            print(f'      {line}')
    grew = (types_after - types_before).most_common(top)
    print('objects by type that grew: ' + (', '.join(f'{name} +{n}' for name, n in grew)
                                           or 'none'))


def main() -> None:
    """Run from the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=5.0, help='minutes of streaming')
    parser.add_argument('--faults', type=int, default=0,
                        help='look for what grows with this many faults instead')
    parser.add_argument('--warm-up-faults', type=int, default=40,
                        help='faults before the first snapshot (with --faults)')
    parser.add_argument('--top', type=int, default=15, help='sites and types printed')
    args = parser.parse_args()
    if args.faults:
        run_faults(args.faults, args.warm_up_faults, args.top)
    else:
        run(args.minutes)


if __name__ == '__main__':
    main()
