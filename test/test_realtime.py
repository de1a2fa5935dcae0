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
The latency levers, checked for what they do (never for how fast).

``realtime_priority`` puts the reader thread, and only it, under SCHED_FIFO
at the priority asked for, as the kernel reports; where the kernel refuses
(here: a node started without CAP_SYS_NICE and with an rtprio limit of 0),
one clear warning is logged, once across reconnects, and the driver streams
as usual. The node freezes its start-up heap.
"""

import os
import shutil
import subprocess
import sys
import threading

from harness.processes import isolate_ros_domain, Listener, NodeProcess, REPO, ros_env
from i3dmgx2_driver.device.realtime import (
    apply_to_current_thread, name_os_threads, PolicyOutcome, ThreadPolicy,
)
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


def _in_a_thread(policy: ThreadPolicy) -> tuple[PolicyOutcome, int, int]:
    """Apply ``policy`` in a fresh thread; return the outcome and what the kernel reports."""
    out = []

    def run() -> None:
        outcome = apply_to_current_thread(policy)
        out.append((outcome, os.sched_getscheduler(0), os.sched_getparam(0).sched_priority))

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    return out[0]


def _fifo_allowed() -> bool:
    outcome, *_ = _in_a_thread(ThreadPolicy(realtime_priority=1))
    return not outcome.refused


def _thread_policies(pid: int) -> dict[int, tuple[int, int]]:
    """Policy and priority of every thread of process ``pid``."""
    out = {}
    for name in os.listdir(f'/proc/{pid}/task'):
        tid = int(name)
        try:
            out[tid] = (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
        except OSError:
            continue
    return out


def _refusing_command() -> list[str]:
    """Return a command prefix under which the kernel refuses SCHED_FIFO (or skip)."""
    if os.geteuid() == 0:
        if not shutil.which('setpriv'):
            pytest.skip('running as root and setpriv is missing: cannot drop CAP_SYS_NICE')
        return ['setpriv', '--inh-caps=-sys_nice', '--bounding-set=-sys_nice',
                'prlimit', '--rtprio=0:0', '--']
    if not shutil.which('prlimit'):
        pytest.skip('prlimit is missing: cannot set an rtprio limit of 0')
    return ['prlimit', '--rtprio=0:0', '--']


def test_nothing_asked_changes_nothing():
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    outcome, policy, priority = _in_a_thread(ThreadPolicy())
    assert outcome == PolicyOutcome((), ())
    assert (policy, priority) == before


def test_the_policy_applies_to_the_calling_thread_only():
    if not _fifo_allowed():
        pytest.skip('this system refuses SCHED_FIFO to this process')
    outcome, policy, priority = _in_a_thread(ThreadPolicy(realtime_priority=7))
    assert outcome == PolicyOutcome(('SCHED_FIFO priority 7',), ())
    assert (policy, priority) == (os.SCHED_FIFO, 7)
    assert os.sched_getscheduler(0) == os.SCHED_OTHER


@pytest.mark.slow
def test_refused_realtime_priority_logs_one_line_and_streaming_goes_on():
    command = [*_refusing_command(), sys.executable, '-m', 'i3dmgx2_driver.ros.main']
    with PtySimulator(SimulatorConfig(seed=41)) as sim:
        node = NodeProcess({'port': sim.port, 'address': 95, 'realtime_priority': 50,
                            'reconnect_interval': 0.3}, command=command)
        with Listener({'imu/raw_data': Imu}) as listener, node:
            assert len(listener.wait_for('imu/raw_data', 30, timeout=30)) >= 30, node.output()
            sim.unplug(seconds=0.5)
            assert sim.pty.plugged.wait(10)
            listener.clear()
            assert len(listener.wait_for('imu/raw_data', 30, timeout=30)) >= 30, node.output()
            policies = {policy for policy, _ in _thread_policies(node.proc.pid).values()}
            assert policies == {os.SCHED_OTHER}
            assert node.stop()[0] == 0
            refusals = [line for line in node.output().splitlines()
                        if 'realtime_priority' in line]
            assert len(refusals) == 1, node.output()
            assert refusals[0].startswith('[WARN]')
            assert refusals[0].endswith(
                'realtime_priority 50 refused (Operation not permitted): the reader thread '
                'keeps normal scheduling; allow SCHED_FIFO with an rtprio limit of at least 50 '
                '(ulimit -r, /etc/security/limits.conf)')


@pytest.mark.slow
def test_granted_realtime_priority_applies_to_the_reader_thread_only():
    if not _fifo_allowed():
        pytest.skip('this system refuses SCHED_FIFO to this process')
    with PtySimulator(SimulatorConfig(seed=42)) as sim:
        node = NodeProcess({'port': sim.port, 'address': 95, 'realtime_priority': 30,
                            'reconnect_interval': 0.3})
        with Listener({'imu/raw_data': Imu}) as listener, node:
            assert len(listener.wait_for('imu/raw_data', 30, timeout=30)) >= 30, node.output()

            def fifo_threads() -> list:
                return [(p, prio) for p, prio in _thread_policies(node.proc.pid).values()
                        if p == os.SCHED_FIFO]

            assert fifo_threads() == [(os.SCHED_FIFO, 30)]
            assert 'reader thread: SCHED_FIFO priority 30' in node.output()
            # A new connection gets a new reader thread, with the same policy.
            sim.unplug(seconds=0.5)
            assert sim.pty.plugged.wait(10)
            listener.clear()
            assert len(listener.wait_for('imu/raw_data', 30, timeout=30)) >= 30, node.output()
            assert fifo_threads() == [(os.SCHED_FIFO, 30)]
            assert node.output().count('reader thread: SCHED_FIFO') == 1
            assert node.stop()[0] == 0


@pytest.mark.slow
def test_the_start_up_heap_is_frozen():
    # In a process of its own: freezing would change this test process for good.
    code = ('import gc\n'
            'from i3dmgx2_driver.device import realtime\n'
            'frozen = realtime.freeze_startup_heap()\n'
            'print(frozen, gc.get_freeze_count(), len(gc.get_objects()))\n')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          env=ros_env(), cwd=REPO, check=True)
    frozen, count, tracked = (int(word) for word in done.stdout.split())
    assert frozen == count > 1000
    assert tracked < frozen / 10  # what a collection still walks


@pytest.mark.slow
def test_the_node_freezes_its_start_up_heap():
    with PtySimulator(SimulatorConfig(seed=43)) as sim, \
            NodeProcess({'port': sim.port, 'address': 95}) as node:
        assert node.wait_for_output('start-up heap frozen (', timeout=30), node.output()
        frozen = int(node.output().split('start-up heap frozen (', 1)[1].split()[0])
        assert frozen > 10000
        assert node.stop()[0] == 0


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='thread names in /proc')
def test_threads_started_afterwards_have_their_name_in_the_os_too():
    names = []

    def run() -> None:
        with open(f'/proc/self/task/{threading.get_native_id()}/comm') as handle:
            names.append(handle.read().strip())
        names.append(sys.getprofile())  # the hook took itself off

    name_os_threads()
    try:
        thread = threading.Thread(target=run, name='gx2-a-long-thread-name')
        thread.start()
        thread.join()
    finally:
        threading.setprofile(None)
    assert names == ['gx2-a-long-thre', None]  # 15 bytes: what the kernel keeps
