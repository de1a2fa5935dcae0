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
The run loop's executor thread: it serves, ends when halted, passes on errors.

``main.run`` spins the executor in a thread of its own (blocked until it has
work) while the main thread waits for a signal. What the main thread did
itself before must still happen: callbacks run, a callback that raises
stops the node and its error reaches ``run``, and a halt ends the thread
at once even when nothing wakes the executor (no timer due: the process
used to abort at exit with the thread still in rclpy's wait); the stop it sets is run()'s
(``lifetime.StopSignal``), which any thread may set; and spinning for
long keeps nothing behind. Real rclpy, in a process of its own.
"""

import subprocess
import sys

from harness.processes import isolate_ros_domain, REPO, ros_env
import pytest

pytestmark = pytest.mark.slow

_SCRIPT = """
import threading
import time
import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from i3dmgx2_driver.lifetime import StopSignal
from i3dmgx2_driver.ros.main import _Spinner

rclpy.init()
node = Node('spinner_probe')
ran = threading.Event()
node.create_timer(0.01, ran.set)
executor = MultiThreadedExecutor(num_threads=2)
executor.add_node(node)
stop = StopSignal()  # what run() hands it
spinner = _Spinner(executor, node, stop)
spinner.start()
print('callbacks ran', ran.wait(10.0))
print('stopped before halt', stop.is_set())
spinner.halt()
print('ended by halt', not spinner._thread.is_alive(), stop.is_set())

def fail():
    raise RuntimeError('boom')

node.create_timer(0.01, fail)
stop = StopSignal()  # what run() hands it
spinner = _Spinner(executor, node, stop)
spinner.start()
print('stopped by the error', stop.wait(10.0), repr(spinner.error))
spinner.halt()
executor.shutdown()
node.destroy_node()

# Nothing due: no timer, no request, and the executor's wait has no timeout (idle costs
# nothing). A wake alone only rebuilds that wait; the thread must end all the same, and at
# once, or it is in rclpy's wait when the interpreter exits (the process aborts).
idle = Node('spinner_idle')
executor = MultiThreadedExecutor(num_threads=2)
executor.add_node(idle)
spinner = _Spinner(executor, idle, StopSignal())
spinner.start()
time.sleep(0.3)
start = time.monotonic()
spinner.halt()
print('halted with nothing due', not spinner._thread.is_alive(), time.monotonic() - start < 0.5)
executor.shutdown()
idle.destroy_node()

# Spinning keeps nothing: a thousand wakes a second for two seconds. rclpy's
# spin_once_until_future_complete adds a callback to its future at every call, and a
# future done only at the halt kept them all (25 objects a fault in the memory curve).
import gc
import sys
busy = Node('spinner_busy')
busy.create_timer(0.001, lambda: None)
executor = MultiThreadedExecutor(num_threads=2)
executor.add_node(busy)
spinner = _Spinner(executor, busy, StopSignal())
spinner.start()
time.sleep(1.0)
gc.collect()
before = sys.getallocatedblocks()
time.sleep(2.0)
gc.collect()
grown = sys.getallocatedblocks() - before
print('kept nothing while spinning', grown < 500, grown if grown >= 500 else '')
spinner.halt()
executor.shutdown()
busy.destroy_node()
rclpy.try_shutdown()
"""


def test_executor_thread_serves_halts_and_passes_on_a_callbacks_error():
    isolate_ros_domain()
    done = subprocess.run([sys.executable, '-c', _SCRIPT], capture_output=True, text=True,
                          env=ros_env(), cwd=REPO, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines() == [
        'callbacks ran True',
        'stopped before halt False',
        'ended by halt True True',
        "stopped by the error True RuntimeError('boom')",
        'halted with nothing due True True',
        'kept nothing while spinning True ',
    ], done.stdout + done.stderr
