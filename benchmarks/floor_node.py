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
The floor under the driver's share: a process that only reads the port and publishes.

A process built as the driver's is (an rclpy node, the same publishers and
QoS, a multi-threaded executor spinning in a thread of its own without a
timeout, the main thread blocked on the stop, the start-up heap frozen as
main.py freezes it) whose reader thread does the least any rclpy driver
must: wait in ``select()`` until a whole packet is in (the terminal's VMIN,
as the driver's ``SerialPort.wake_for`` sets it), read it, and publish what
the driver publishes for 0xCC, a ready-serialized Imu and MagneticField
message of the same sizes, with no parsing, stamping or packing; and, as the
driver does, a /diagnostics array of its size once a second, from a thread
of its own (its 7 statuses and 60 values, about 2.65 kB serialized). Its read()
returned -> publish() returned is what the driver's share cannot go below
with rclpy on this machine; the rest of the driver's share is the driver's
own Python.

It records its timings as the driver does when ``I3DMGX2_TIMINGS`` names a
file (device/hot_path.py's TimingsRecorder: the read and the publish of each
packet; it parses, stamps and packs nothing), so that ``latency.py`` runs it
as one more configuration. The simulator must stream from power-up (nobody
here asks it to). Prints ``start-up heap frozen`` once it reads the port;
stops on SIGINT or SIGTERM.

Usage: ``I3DMGX2_TIMINGS=out.json floor_node.py --ros-args -p port:=PATH
[-p realtime_priority:=N]``.
"""

import inspect
import itertools
import os
from pathlib import Path
import select
import signal
import struct
import sys
import termios
import threading
import time
from typing import NamedTuple

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import rclpy  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402, I100
from sensor_msgs.msg import Imu, MagneticField  # noqa: E402

from i3dmgx2_driver.codec import layouts  # noqa: E402, I100
from i3dmgx2_driver.codec.framing import DATA_FLAGS, DATA_TRAILER_SIZE, HEADER_SIZE  # noqa: E402
from i3dmgx2_driver.device import realtime  # noqa: E402
from i3dmgx2_driver.device.hot_path import recorder_from_environment  # noqa: E402
from i3dmgx2_driver.device.port import TTY_READ_CHUNK  # noqa: E402

_LAYOUT = layouts.LAYOUTS[layouts.ACCEL_ANG_RATE_MAG_ORIENTATION]
PACKET_SIZE = HEADER_SIZE + _LAYOUT.record_size + DATA_TRAILER_SIZE
#: The timer: the last four bytes of the record, big-endian.
_TIMER = struct.Struct('>I')
_TIMER_AT = HEADER_SIZE + _LAYOUT.record_size - 4
#: The serialized size of the driver's /diagnostics at 100 Hz 0xCC (7 statuses, 60 values).
DIAGNOSTICS_BYTES = 2650


class _Record(NamedTuple):
    """What an older tree's recorder takes of a record (``published(record, stamp)``)."""

    timer: int


def _messages(stamp: float) -> tuple[bytes, bytes]:
    """Return the Imu and MagneticField the floor publishes, the driver's sizes, serialized."""
    imu, mag = Imu(), MagneticField()
    for message in (imu, mag):
        message.header.frame_id = 'imu_link'  # the driver's default frame
        message.header.stamp.sec = int(stamp)
    return serialize_message(imu), serialize_message(mag)


def _diagnostics() -> bytes:
    """Return a DiagnosticArray of the driver's shape at 100 Hz, serialized (2,650 bytes)."""
    array = DiagnosticArray()
    array.status = [DiagnosticStatus(name=f'i3dmgx2_driver: status {i}', hardware_id='3095',
                                     message='ok', values=[KeyValue(key=f'key {j}', value='0' * 12)
                                                           for j in range(60 // 7 + (i < 4))])
                    for i in range(7)]
    while len(serialize_message(array)) < DIAGNOSTICS_BYTES:
        array.status[0].values[0].value += '0'
    return serialize_message(array)


def _parameters(ros_args: list[str]) -> dict[str, str]:
    return {arg.split(':=', 1)[0]: arg.split(':=', 1)[1]
            for flag, arg in itertools.pairwise(ros_args)
            if flag == '-p' and ':=' in arg}


def main() -> int:
    """Read and publish until told to stop; save the timings."""
    params = _parameters(sys.argv[1:])
    if 'port' not in params:
        raise SystemExit('floor_node.py: -p port:=PATH is required')
    timings, path = recorder_from_environment()
    if timings is None:
        raise SystemExit('floor_node.py: I3DMGX2_TIMINGS must name the file for the timings')
    stop = threading.Event()
    realtime.name_os_threads()  # the wakes per thread are told apart by name
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    rclpy.init(args=sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('i3dmgx2_floor')
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE)
    publish_imu = node.create_publisher(Imu, 'imu/raw_data', qos).publish
    publish_mag = node.create_publisher(MagneticField, 'imu/mag', qos).publish
    publish_diagnostics = node.create_publisher(DiagnosticArray, '/diagnostics', qos).publish
    diagnostics = _diagnostics()
    stamp = time.time()
    imu, mag = _messages(stamp)
    # Built with rclpy alone, the floor runs on another tree's package too (latency.py
    # --against); an older recorder takes the record at the publish, not at the pack.
    older = 'record' in inspect.signature(timings.published).parameters
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    policy = realtime.ThreadPolicy(int(params.get('realtime_priority', '0')))
    fd = os.open(params['port'], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    attributes = termios.tcgetattr(fd)  # select() says readable once a whole packet is in
    attributes[6][termios.VMIN], attributes[6][termios.VTIME] = PACKET_SIZE, 0
    termios.tcsetattr(fd, termios.TCSANOW, attributes)

    def reader() -> None:
        realtime.apply_to_current_thread(policy)
        buf = bytearray()
        while not stop.is_set():
            readable, _, _ = select.select([fd], [], [], 0.2)
            if not readable:
                continue
            data = more = os.read(fd, 4096)
            while len(more) == TTY_READ_CHUNK:  # the rest of the packet, as read_some reads it
                try:
                    more = os.read(fd, 4096)
                except BlockingIOError:
                    break
                data += more
            timings.read(len(data), time.time())
            buf += data
            while len(buf) >= PACKET_SIZE:
                if buf[0] != 0xAA or buf[1] != DATA_FLAGS:
                    del buf[0]
                    continue
                timer = _TIMER.unpack_from(buf, _TIMER_AT)[0]
                del buf[:PACKET_SIZE]
                if older:
                    publish_imu(imu)
                    timings.published(_Record(timer), stamp)
                else:
                    timings.packed(timer)
                    publish_imu(imu)
                    timings.published(stamp)
                publish_mag(mag)

    def tick() -> None:
        while not stop.wait(1.0):
            publish_diagnostics(diagnostics)

    thread = threading.Thread(target=reader, name='gx2-reader', daemon=True)
    thread.start()
    threading.Thread(target=tick, name='gx2-diagnostics', daemon=True).start()
    frozen = realtime.freeze_startup_heap()
    print(f'floor: start-up heap frozen ({frozen} objects)', flush=True)
    spinner = threading.Thread(target=executor.spin, name='gx2-executor', daemon=True)
    spinner.start()
    try:
        stop.wait()
    finally:
        stop.set()
        thread.join(1.0)
        timings.save(path)
        os.close(fd)
        executor.shutdown(timeout_sec=0.5)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
