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
Entry point of ``ros2 run i3dmgx2_driver node``, and the run loop of both executables.

SIGINT and SIGTERM are handled here rather than by rclpy, so that the
driver can stop the device's stream (0xFA) and close the port while ROS is
still up, then shut ROS down: a clean exit (code 0) well within 2 s. An
invalid parameter exits with code 2 and a message that names it and its
valid range; so does a port that can never work (a path that is no serial
port), with one FATAL line that says what the path is and how to find the
right one: at once when the node is made, or later when the node reports it
as ``fatal_error``. :func:`run` does all of it for any driver node class (the plain
node here, the managed node in ``lifecycle_node.py``): the class is made
with no arguments and provides ``shutdown()`` and ``finished`` (True once
it is done by itself, as a managed node after its shutdown transition).
Once the node is made, the start-up heap is frozen (device/realtime.py says
why).
"""

from collections.abc import Callable
import signal
import sys
import threading
import time
from typing import Any

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import MultiThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from .imu_node import ImuDriverNode
from .parameters import ParameterError
from ..device import realtime
from ..device.port import PortUnusable

EXIT_BAD_PARAMETER = 2
#: How often the main loop looks at the stop flag (s); signals wake it anyway.
_SPIN_PERIOD = 0.1
#: Once a node is finished by itself, how long to keep spinning (s), so that
#: the reply to the request that finished it still goes out.
_FINISH_GRACE = 0.3
#: Worker threads of the executor. Its pool starts them one by one, as callbacks
#: overlap, and keeps them: a node's thread count may rise by a few and stay.
EXECUTOR_THREADS = 4


def run(make_node: Callable[[], Any], args: list[str] | None = None) -> int:
    """Run the node ``make_node()`` returns until SIGINT, SIGTERM or it is finished."""
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:
        # rcl's own words name the argument it could not parse.
        print(f'[FATAL] [i3dmgx2_driver]: invalid ROS arguments: {exc}', file=sys.stderr)
        return EXIT_BAD_PARAMETER
    stop = threading.Event()

    def request_stop(signum: int, frame: object) -> None:
        stop.set()

    previous = {sig: signal.signal(sig, request_stop)
                for sig in (signal.SIGINT, signal.SIGTERM)}
    node = None
    # Several threads, so that a long service call (a 30 s gyro bias capture)
    # holds only its own callback group: diagnostics keep ticking, parameters
    # answer, and a signal is acted on at once rather than after the call.
    executor = MultiThreadedExecutor(num_threads=EXECUTOR_THREADS)
    code = 0
    try:
        try:
            node = make_node()
        except (ParameterError, PortUnusable) as exc:
            rclpy.logging.get_logger('i3dmgx2_driver').fatal(str(exc))
            return EXIT_BAD_PARAMETER
        executor.add_node(node)
        # Start-up is over: out of the collector's sight with its heap (realtime.py says why).
        frozen = realtime.freeze_startup_heap()
        node.get_logger().info(f'start-up heap frozen ({frozen} objects)')
        while not stop.is_set() and rclpy.ok() and not node.finished:
            executor.spin_once(timeout_sec=_SPIN_PERIOD)
            if getattr(node, 'fatal_error', None) is not None:
                code = EXIT_BAD_PARAMETER  # said once, as the node found it
                break
        grace = time.monotonic() + _FINISH_GRACE
        while node.finished and not stop.is_set() and time.monotonic() < grace \
                and rclpy.ok():
            executor.spin_once(timeout_sec=0.05)
    finally:
        if node is not None:
            node.shutdown()
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown(timeout_sec=0.5)
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return code


def main(args: list[str] | None = None) -> int:
    """Run the driver node until SIGINT or SIGTERM."""
    return run(ImuDriverNode, args)


if __name__ == '__main__':
    sys.exit(main())
