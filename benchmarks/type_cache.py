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

Prints numbers; passes or fails nothing.
"""

import argparse
import gc
import sys
import threading
import time
import tracemalloc

import bench_common  # noqa: F401 - puts the repository on the path
from harness.processes import ADDRESS, isolate_ros_domain, SimProcess

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


def main() -> None:
    """Run from the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=5.0, help='minutes of streaming')
    run(parser.parse_args().minutes)


if __name__ == '__main__':
    main()
