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
``ros2 run i3dmgx2_driver monitor``: a live, one-line view of the IMU topic.

What ``ros2 topic echo`` would show, condensed for a person: the message
rate, the latest acceleration and angular rate, the attitude as roll, pitch
and yaw, and the age of the stamp, refreshed twice a second. It is also how
the README's first command shows that data flows without the ``ros2`` CLI.
"""

import argparse
import contextlib
import math
import sys
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Imu

from .. import lifetime


def roll_pitch_yaw(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Z-Y-X Euler angles (rad) of a unit quaternion."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def describe(msg: Imu, rate: float, now: float) -> str:
    """One line about the latest message."""
    a, g, q = msg.linear_acceleration, msg.angular_velocity, msg.orientation
    roll, pitch, yaw = (math.degrees(v) for v in roll_pitch_yaw(q.x, q.y, q.z, q.w))
    age = now - (msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
    return (f'{rate:6.1f} Hz  accel [{a.x:+6.2f} {a.y:+6.2f} {a.z:+6.2f}] m/s2  '
            f'rate [{g.x:+6.3f} {g.y:+6.3f} {g.z:+6.3f}] rad/s  '
            f'rpy [{roll:+7.1f} {pitch:+6.1f} {yaw:+7.1f}] deg  '
            f'stamp age {age * 1e3:5.1f} ms  ({msg.header.frame_id})')


class Monitor(Node):
    """
    Subscribe to the IMU topic and keep the latest message and how many came.

    Only the spinning thread writes them (one reference, one count), so the
    printing loop reads them without a lock.
    """

    def __init__(self, topic: str, best_effort: bool) -> None:
        super().__init__('i3dmgx2_monitor')
        qos = qos_profile_sensor_data if best_effort else QoSProfile(depth=10)
        self.create_subscription(Imu, topic, self._store, qos)
        self.latest: Imu | None = None
        #: Messages received in all.
        self.received = 0

    def _store(self, msg: Imu) -> None:
        self.latest = msg
        self.received += 1


def _spin(executor: SingleThreadedExecutor, stopped: lifetime.StopSignal) -> None:
    """
    Spin until main stops the executor, or something else shuts the context down.

    ``stopped`` tells the printing loop that no message will come any more
    (main's SIGINT/SIGTERM/SIGHUP handler sets it too, whatever SIGINT's disposition
    was when the process started: a background job of a script starts with
    it ignored).
    """
    try:
        with contextlib.suppress(ExternalShutdownException):
            executor.spin()
    finally:
        stopped.set()


def main(argv: list[str] | None = None) -> int:
    """Print the IMU topic's rate and values until Ctrl-C or --duration."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--topic', default='imu/raw_data')
    parser.add_argument('--duration', type=float, default=0.0,
                        help='stop after this many seconds (0: until Ctrl-C)')
    parser.add_argument('--best-effort', action='store_true',
                        help='subscribe best effort (for a best_effort publisher)')
    parser.add_argument('--period', type=float, default=0.5, help='seconds between lines')
    args = parser.parse_args(rclpy.utilities.remove_ros_args(argv or sys.argv)[1:])
    lifetime.die_with_parent()
    # Signals only set a flag, as in the driver's main: rclpy's own handler would shut the
    # context down under the spinning thread while this one tears it down too (it crashed).
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = Monitor(args.topic, args.best_effort)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    # Not a threading.Event: a signal handler may not take a lock (lifetime.py says why).
    stopped = lifetime.StopSignal().install()
    spinner = threading.Thread(target=_spin, args=(executor, stopped), daemon=True)
    spinner.start()
    start = last = time.monotonic()
    seen = 0
    try:
        with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
            while not args.duration or time.monotonic() - start < args.duration:
                if stopped.wait(args.period):
                    break
                now, msg, received = time.monotonic(), node.latest, node.received
                rate = (received - seen) / (now - last)
                print(f'waiting for {node.resolve_topic_name(args.topic)} ...' if msg is None
                      else describe(msg, rate, time.time()), flush=True)
                last, seen = now, received
    finally:
        # The spinning thread must be out of rclpy's C++ before the interpreter
        # exits, or the process aborts ("terminate called without an active
        # exception"): stop the executor, join the thread, then tear down.
        executor.shutdown(timeout_sec=1.0)
        spinner.join(timeout=5.0)
        node.destroy_node()
        rclpy.try_shutdown()
    print(f'{node.received} messages received', flush=True)
    return 0 if node.received else 1


if __name__ == '__main__':
    sys.exit(main())
