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
The floor under the driver's share: a thread that only reads the port and publishes.

A process built as the driver's is (an rclpy node, the same publisher and
QoS, a multi-threaded executor spinning in the main thread, the start-up
heap frozen as main.py freezes it) whose reader thread does the least any rclpy
driver must: wait in ``select()``, read, and once a whole packet is in,
publish a ready-serialized Imu message of the same size, with no parsing,
stamping or packing. Its read() returned -> publish() returned is what the
driver's share cannot go below with rclpy on this machine; the rest of the
driver's share is the driver's own Python.

Output as ``latency_node.py`` (rows: timer, read time, publish() returned),
so that ``latency_levers.py`` runs it as one more configuration. The
simulator must stream from power-up (nobody here asks it to).

Usage: ``publish_floor.py [--realtime-priority N] [--cpu C] --out OUT.json
--ros-args -p port:=PATH``.
"""

import argparse
import json
import os
from pathlib import Path
import select
import signal
import struct
import sys
import threading
import time

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import rclpy  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from i3dmgx2_driver.codec import layouts, streams  # noqa: E402, I100
from i3dmgx2_driver.codec.framing import DATA_FLAGS, DATA_TRAILER_SIZE, HEADER_SIZE  # noqa: E402
from i3dmgx2_driver.device import realtime  # noqa: E402
from i3dmgx2_driver.ros.conversions import MessageFactory, probe_records  # noqa: E402

_LAYOUT = layouts.LAYOUTS[layouts.ACCEL_ANG_RATE_MAG_ORIENTATION]
PACKET_SIZE = HEADER_SIZE + _LAYOUT.record_size + DATA_TRAILER_SIZE
#: The timer: the last four bytes of the record, big-endian.
_TIMER = struct.Struct('>I')
_TIMER_AT = HEADER_SIZE + _LAYOUT.record_size - 4


def _port_of(ros_args: list[str]) -> str:
    for i, arg in enumerate(ros_args):
        if arg == '-p' and ros_args[i + 1].startswith('port:='):
            return ros_args[i + 1].split(':=', 1)[1]
    raise SystemExit('publish_floor.py: -p port:=PATH is required')


def main() -> int:
    """Read and publish until told to stop; save the rows."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1], allow_abbrev=False)
    parser.add_argument('--out', required=True)
    parser.add_argument('--realtime-priority', type=int, default=0)
    parser.add_argument('--cpu', type=int, default=-1)
    args, ros_args = parser.parse_known_args()
    port = _port_of(ros_args)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    rclpy.init(args=[sys.argv[0], *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('i3dmgx2_publish_floor')
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE)
    publisher = node.create_publisher(Imu, 'imu/raw_data', qos)
    factory = MessageFactory('imu_link', 'enu', 0.0, 0.0, 0.0, 0.0, streams.DEFAULT)
    message = factory.imu_cdr(probe_records(streams.DEFAULT)[0], time.time())
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    rows: list[tuple[int, float, float]] = []
    policy = realtime.ThreadPolicy(args.realtime_priority)
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY)

    threads: dict[str, dict] = {}

    def reader() -> None:
        if args.cpu >= 0:
            os.sched_setaffinity(0, {args.cpu})
        realtime.apply_to_current_thread(policy)
        threads['gx2-reader'] = {'policy': os.sched_getscheduler(0),
                                 'priority': os.sched_getparam(0).sched_priority,
                                 'cpus': sorted(os.sched_getaffinity(0))}
        buf = bytearray()
        ready = False
        while not stop.is_set():
            readable, _, _ = select.select([fd], [], [], 0.2)
            if not readable:
                continue
            data = os.read(fd, 4096)
            now = time.time()
            buf += data
            while len(buf) >= PACKET_SIZE:
                if buf[0] != 0xAA or buf[1] != DATA_FLAGS:
                    del buf[0]
                    continue
                timer = _TIMER.unpack_from(buf, _TIMER_AT)[0]
                del buf[:PACKET_SIZE]
                publisher.publish(message)
                rows.append((timer, now, time.time()))
                if not ready:
                    ready = True
                    print('ready', flush=True)

    thread = threading.Thread(target=reader, name='gx2-reader', daemon=True)
    thread.start()
    frozen = realtime.freeze_startup_heap()

    def watch_stdin() -> None:
        sys.stdin.read()
        stop.set()

    threading.Thread(target=watch_stdin, daemon=True).start()
    try:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
    finally:
        stop.set()
        thread.join(1.0)
        with open(args.out, 'w') as handle:
            json.dump({'rows': rows, 'gc': [], 'threads': threads, 'gc_frozen': frozen,
                       'opens': []}, handle)
        os.close(fd)
        executor.shutdown(timeout_sec=0.5)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
