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
Issue #31: what a node's /rosout publisher keeps of the messages it logged, and its ceiling.

Every rclpy node publishes what it logs on /rosout, through a publisher
whose history keeps the last 1,000 messages (rcl's default: keep last 1000,
transient local). Each message's buffer is kept at the largest message it
has held, so a node that logs messages of varying length gains C heap long
after the history is full, ever more slowly, up to 1,000 times its longest
message. Here a bare rclpy node (no driver) logs ``--messages`` warnings of
``lo`` to ``hi`` characters, each length drawn at random, in a process of its
own per case; after each milestone the C heap in use (glibc's ``mallinfo2``)
above what it was before the first message is printed. With
``--disable-rosout-logs`` the same logging keeps nothing.

Prints numbers; passes or fails nothing.
"""

import argparse
import gc
import os
import random
import subprocess
import sys

import bench_common  # noqa: F401 - puts the repository on the path
from harness.glibc_heap import mallinfo2
from harness.processes import isolate_ros_domain

#: Messages after which the heap is read.
MILESTONES = (1, 100, 500, 1000, 2000, 5000, 10000, 20000, 50000, 100000, 150000)


def one_case(lo: int, hi: int, messages: int, rosout: bool) -> None:
    """Log ``messages`` warnings of lo..hi characters; print the heap's growth as it goes."""
    import rclpy
    from rclpy.node import Node

    rclpy.init(args=['--ros-args'] + ([] if rosout else ['--disable-rosout-logs']))
    node = Node('rosout_memory', enable_rosout=rosout)
    logger = node.get_logger()
    rng = random.Random(1)
    if mallinfo2() is None:
        sys.exit("rosout_memory: the C heap's figures need glibc 2.33 or later (mallinfo2)")
    gc.collect()
    base = mallinfo2().uordblks
    for i in range(1, messages + 1):
        logger.warning('x' * rng.randint(lo, hi))
        if i in MILESTONES or i == messages:
            gc.collect()
            print(f'{i} {(mallinfo2().uordblks - base) / 1024:.1f}', flush=True)
    node.destroy_node()
    rclpy.shutdown()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--messages', type=int, default=150000)
    parser.add_argument('--lengths', default='20-220,20-300,20-1020',
                        help='message length ranges, lo-hi, comma separated')
    parser.add_argument('--one', nargs=4, metavar=('LO', 'HI', 'N', 'ROSOUT'),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        lo, hi, n, rosout = args.one
        one_case(int(lo), int(hi), int(n), rosout == 'on')
        return
    isolate_ros_domain()
    print(bench_common.machine_table())
    cases = [(*map(int, r.split('-')), 'on') for r in args.lengths.split(',')]
    cases.append((*cases[-1][:2], 'off'))
    columns = []
    for lo, hi, rosout in cases:
        done = subprocess.run(
            [sys.executable, __file__, '--one', str(lo), str(hi), str(args.messages), rosout],
            capture_output=True, text=True, check=True, env=os.environ)
        columns.append(dict(line.split() for line in done.stdout.split('\n') if line))
    print('C heap in use above the start (KiB) after N messages logged\n')
    print('| messages | ' + ' | '.join(f'{lo}-{hi} chars, /rosout {r}' for lo, hi, r in cases)
          + ' |')
    print('|---' * (len(cases) + 1) + '|')
    for n in sorted({int(k) for c in columns for k in c}):
        print(f'| {n} | ' + ' | '.join(c.get(str(n), '') for c in columns) + ' |')


if __name__ == '__main__':
    main()
