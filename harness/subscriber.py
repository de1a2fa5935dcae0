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
A subscriber in another process: notes when each Imu message arrives.

Subscribes to ``imu/raw_data`` (reliable, deep history, so that nothing is
dropped on its side), and notes the wall-clock time at the start of each
callback with the message's stamp. Prints ``ready`` once subscribed and, on
SIGTERM, SIGINT or end of standard input, writes the rows
``[stamp_sec, stamp_nanosec, receive_time]`` as JSON and exits.

Usage: ``python -m harness.subscriber --out ROWS.json``; started by
``harness.processes.SubscriberProcess``.
"""

import argparse
import json
import signal
import sys
import threading
import time

from i3dmgx2_driver.lifetime import StopSignal
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Imu


def main(argv: list[str] | None = None) -> int:
    """Subscribe until told to stop; then save the receive times."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--out', required=True, help='where to write the rows (JSON)')
    parser.add_argument('--topic', action='append',
                        help='a topic to subscribe to (again: several; default imu/raw_data)')
    parser.add_argument('--values', action='store_true',
                        help="also save each message's topic, frame_id and angular velocity")
    args = parser.parse_args(argv)
    # SIGINT, SIGTERM or the end of standard input (a run that dies closes it) stop it, so
    # that it never outlives the run and saves what it gathered: rclpy's own handlers stay
    # off. A StopSignal, not a threading.Event, whose set() in a signal handler can wait for
    # good on the lock of the wait() it interrupted (lifetime.py).
    stop = StopSignal().install((signal.SIGINT, signal.SIGTERM))

    def watch_stdin() -> None:
        sys.stdin.read()
        stop.set()

    threading.Thread(target=watch_stdin, daemon=True).start()
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('i3dmgx2_benchmark_subscriber')
    rows: list[tuple[int, int, float]] = []
    clock = time.time

    def on_message(msg: Imu, topic: str) -> None:
        now = clock()
        stamp = msg.header.stamp
        if args.values:
            w = msg.angular_velocity
            rows.append((stamp.sec, stamp.nanosec, now, topic, msg.header.frame_id,
                         w.x, w.y, w.z))
        else:
            rows.append((stamp.sec, stamp.nanosec, now))

    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5000,
                     reliability=ReliabilityPolicy.RELIABLE)
    for topic in args.topic or ['imu/raw_data']:
        node.create_subscription(Imu, topic, lambda msg, t=topic: on_message(msg, t), qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print('ready', flush=True)
    try:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
    finally:
        with open(args.out, 'w') as handle:
            json.dump(rows, handle)
        executor.shutdown(timeout_sec=0.5)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
