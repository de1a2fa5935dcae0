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

SIGINT, SIGTERM and SIGHUP (a closed terminal) are handled here rather than
by rclpy, so that the driver can stop the device's stream (0xFA) and close
the port while ROS is still up, then shut ROS down: a clean exit (code 0).
From the moment the stop begins the process has
``lifetime.SHUTDOWN_DEADLINE`` to end, else every thread's stack goes to the
log and the exit code is 1 (lifetime.py says why, and why the handler only
sets a flag). An invalid parameter exits with code 2 and a message that
names it and its valid range; so does a port that can never work, at once
when the node is made or later, when the node reports it as
``fatal_error``. :func:`run` does it for any driver node class (the plain
node here, the managed node in ``lifecycle_node.py``): the class is made
with no arguments and provides ``shutdown()``, ``finished`` (True once it is
done by itself, as a managed node after its shutdown transition) and
``on_done``, which it calls when finished or fatal. Once the node is made,
the start-up heap is frozen (device/realtime.py says why). With
``I3DMGX2_TIMINGS`` naming a file, the plain node records every sample's
hot-path stage times and writes them there as it exits (device/hot_path.py).

Idle costs nothing: at 100 Hz only the reader thread should wake for each
sample (docs/cpu.md). The executor spins in a thread of its own and its
wait has no timeout: it wakes for a timer, a request, or the guard
condition :meth:`_Spinner.halt` triggers. The main thread blocks on the stop
signal, which a signal, the node's ``on_done`` and the executor's end set.
A bounded wait would have woken each thread ten times a second, and each
wake of the executor rebuilds its wait set.
"""

from collections.abc import Callable
import sys
import threading
import time
from typing import Any

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from .imu_node import ImuDriverNode
from .parameters import ParameterError
from .. import lifetime
from ..device import realtime
from ..device.hot_path import recorder_from_environment
from ..device.port import PortUnusable

EXIT_BAD_PARAMETER = 2
#: What rcl says of a transition the current state does not have.
NOT_A_TRANSITION = 'Transition is not registered'
#: Once a node is finished by itself, how long the executor goes on spinning (s), so
#: that the reply to the request that finished it still goes out.
_FINISH_GRACE = 0.3
#: Worker threads of the executor. Its pool starts them one by one, as callbacks
#: overlap, and keeps them: a node's thread count may rise by a few and stay.
EXECUTOR_THREADS = 4
#: How long the executor's shutdown waits for its callbacks to end (s).
EXECUTOR_SHUTDOWN_S = 0.5


class _Spinner:
    """Spins an executor in a thread of its own until halted; keeps what it raised."""

    def __init__(self, executor: MultiThreadedExecutor, node: Any,
                 stop: lifetime.StopSignal) -> None:
        self._executor = executor
        self._stop = stop
        #: Set once halted; the guard condition then ends the executor's wait. Not the
        #: executor's own wake(): that only has the wait set rebuilt and the wait go on,
        #: and a thread still in rclpy's wait when the interpreter exits aborts the
        #: process ("terminate called without an active exception", exit -6). Not a
        #: Future the wait ends on: rclpy's spin_once_until_future_complete adds a
        #: callback to the future at every call, which a future done only at the end
        #: keeps (the memory curve's leak).
        self._halt = threading.Event()
        self._guard = node.create_guard_condition(lambda: None)
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._spin, name='gx2-executor', daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _spin(self) -> None:
        try:
            while not self._halt.is_set() and rclpy.ok():
                try:
                    self._executor.spin_once()
                except RCLError as exc:
                    if NOT_A_TRANSITION not in str(exc):
                        raise
                    # rclpy's lifecycle service raises, rather than answers, a transition
                    # asked for by id that the current state does not have (configure to an
                    # active node, a lifecycle manager's repeated request): the request was
                    # wrong, not the node, which goes on in the state it is in.
                    rclpy.logging.get_logger('i3dmgx2_driver').warning(
                        f'lifecycle request refused, the node stays as it is: {exc}')
        except ExternalShutdownException:
            pass  # ROS shut down under the node: it ends like a signal
        except BaseException as exc:  # a callback's error ends the node, as it did in main
            self.error = exc
        finally:
            self._stop.set()

    def halt(self, timeout: float = 1.0) -> None:
        """Stop spinning: end the executor's wait and let the thread end."""
        self._halt.set()
        self._guard.trigger()
        self._thread.join(timeout)


def run(make_node: Callable[[], Any], args: list[str] | None = None) -> int:
    """
    Run the node ``make_node()`` returns until SIGINT, SIGTERM, SIGHUP or it is finished.

    The stop's deadline (``lifetime.arm_deadline``) is armed as the stop
    begins and stays armed after this returns, for the rest of the process's
    way out (the interpreter waits for the executor's worker threads); a
    caller that goes on afterwards disarms it (``lifetime.cancel_deadline``).
    The signal handlers stay too: a second signal on the way out (a closed
    terminal's SIGHUP, then a script's SIGINT) changes nothing, where the
    default one would raise KeyboardInterrupt in the interpreter's exit.
    """
    # Before anything else: a signal during start-up is a stop once the node is made.
    stop = lifetime.StopSignal().install()
    realtime.name_os_threads()
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:
        # rcl's own words name the argument it could not parse.
        print(f'[FATAL] [i3dmgx2_driver]: invalid ROS arguments: {exc}', file=sys.stderr)
        return EXIT_BAD_PARAMETER
    node = spinner = None
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
        spinner = _Spinner(executor, node, stop)
        spinner.start()
        node.on_done = stop.set
        if node.finished or getattr(node, 'fatal_error', None) is not None:
            stop.set()  # it happened before on_done was there to say so
        stop.wait()
        if getattr(node, 'fatal_error', None) is not None:
            code = EXIT_BAD_PARAMETER  # said once, as the node found it
        elif node.finished:
            time.sleep(_FINISH_GRACE)  # the reply to the request that finished it goes out
        if spinner.error is not None:
            raise spinner.error
    finally:
        # From here the process ends within the deadline, or says where it waited.
        lifetime.arm_deadline()
        try:
            if spinner is not None:
                spinner.halt()
            if node is not None:
                node.shutdown()
                executor.remove_node(node)
                node.destroy_node()
        finally:
            executor.shutdown(timeout_sec=EXECUTOR_SHUTDOWN_S)
            rclpy.try_shutdown()
    return code


def main(args: list[str] | None = None) -> int:
    """Run the driver node until a signal or its parent's end (recording its timings if asked)."""
    lifetime.die_with_parent()
    recorder, path = recorder_from_environment()  # installed as the hot path's observer
    try:
        return run(ImuDriverNode, args)
    finally:
        if recorder is not None:
            # Writing the file is no part of the stop: the deadline counts afresh after it.
            lifetime.cancel_deadline()
            recorder.save(path)
            lifetime.arm_deadline()


if __name__ == '__main__':
    sys.exit(main())
