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
Every benchmark starts: its imports resolve and its command line answers ``--help``.

Benchmarks run by hand, so nothing else would notice one that a refactoring
broke (executor_load.py, since retired, and run_all.py through it, imported a class that
latency.py no longer had, unnoticed for weeks). Only the start is tested:
what a benchmark prints are numbers, never a pass or a fail.
"""

import os
import pathlib
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow

BENCHMARKS = pathlib.Path(__file__).resolve().parent.parent / 'benchmarks'
#: Modules that are no command of their own, or take the node's ROS arguments instead.
NOT_COMMANDS = {'bench_common.py', 'floor_node.py'}
SCRIPTS = sorted(p.name for p in BENCHMARKS.glob('*.py') if p.name not in NOT_COMMANDS)


def test_the_list_is_not_empty():
    assert 'latency.py' in SCRIPTS and 'shutdown.py' in SCRIPTS


@pytest.mark.parametrize('script', SCRIPTS)
def test_a_benchmark_answers_help(script):
    done = subprocess.run([sys.executable, str(BENCHMARKS / script), '--help'],
                          capture_output=True, text=True, timeout=120, cwd=BENCHMARKS.parent,
                          env={**os.environ, 'PYTHONPATH': os.pathsep.join(
                              [str(BENCHMARKS.parent), os.environ.get('PYTHONPATH', '')])})
    assert done.returncode == 0, done.stderr[-2000:]
    assert 'usage' in done.stdout.lower()


def test_the_floor_node_refuses_to_start_without_a_port():
    done = subprocess.run([sys.executable, str(BENCHMARKS / 'floor_node.py')],
                          capture_output=True, text=True, timeout=120, cwd=BENCHMARKS.parent)
    assert done.returncode != 0
    assert 'port' in done.stderr


_FLOOR_DIAGNOSTICS = """
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.serialization import deserialize_message
import floor_node
data = floor_node._diagnostics()
array = deserialize_message(data, DiagnosticArray)
print(len(array.status), sum(len(s.values) for s in array.status),
      len(data) - floor_node.DIAGNOSTICS_BYTES)
"""


def test_the_floor_publishes_a_diagnostics_array_of_the_drivers_shape():
    # The floor does the driver's work at the edge, its /diagnostics once a second included:
    # 7 statuses, 60 values, its size in bytes (run where the benchmarks run, not imported).
    done = subprocess.run([sys.executable, '-c', _FLOOR_DIAGNOSTICS], capture_output=True,
                          text=True, timeout=120, cwd=BENCHMARKS)
    assert done.returncode == 0, done.stderr[-2000:]
    statuses, values, over = map(int, done.stdout.split())
    assert (statuses, values) == (7, 60) and 0 <= over < 8, done.stdout
