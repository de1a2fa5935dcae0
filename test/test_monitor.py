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

"""The monitor tool shows the node's data, as the README's first command does."""

import signal
import subprocess
import sys
import time

from harness.processes import isolate_ros_domain, NodeProcess, REPO, ros_env
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.tools.monitor import roll_pitch_yaw
import pytest


def test_roll_pitch_yaw_of_known_quaternions():
    assert roll_pitch_yaw(0.0, 0.0, 0.0, 1.0) == (0.0, 0.0, 0.0)
    half = 2 ** -0.5
    assert roll_pitch_yaw(0.0, 0.0, half, half) == pytest.approx((0.0, 0.0, 1.5707963))
    assert roll_pitch_yaw(half, 0.0, 0.0, half) == pytest.approx((1.5707963, 0.0, 0.0))


@pytest.mark.slow
def test_monitor_prints_rate_and_values_of_a_running_node():
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=51)) as sim:
        node = NodeProcess({'port': sim.port, 'address': 95})
        with node:
            assert node.wait_for_output('streaming 0xCC'), node.output()
            out = subprocess.run(
                [sys.executable, '-m', 'i3dmgx2_driver.tools.monitor', '--duration', '4'],
                env=ros_env(), cwd=REPO, capture_output=True, text=True, timeout=60)
            assert out.returncode == 0, out.stdout + out.stderr
            lines = [line for line in out.stdout.splitlines() if ' Hz ' in line]
            assert lines, out.stdout
            assert 'accel [' in lines[-1] and '(imu_link)' in lines[-1]
            rate = float(lines[-1].split('Hz')[0])
            assert 10.0 < rate < 400.0  # the simulator streams 100 Hz; loaded CI is bursty
            assert out.stdout.splitlines()[-1].endswith('messages received')
            assert node.stop()[0] == 0


#: Starts the monitor with SIGINT at the disposition given as argv[1], as a shell would
#: leave it: 'default' (a terminal) or 'ignored' (a background job of a script, as CI
#: runs the tests); exec keeps an ignored signal ignored, so the monitor inherits it.
MONITOR_WITH_SIGINT = (
    'import os, signal, sys\n'
    "signal.signal(signal.SIGINT, signal.SIG_IGN if sys.argv[1] == 'ignored' "
    'else signal.SIG_DFL)\n'
    "os.execv(sys.executable, [sys.executable, '-m', 'i3dmgx2_driver.tools.monitor'])\n")


@pytest.mark.parametrize(('sent', 'sigint'), [
    (signal.SIGINT, 'default'), (signal.SIGINT, 'ignored'), (signal.SIGTERM, 'default')],
    ids=['ctrl_c', 'ctrl_c_started_ignoring_sigint', 'sigterm'])
@pytest.mark.slow
def test_monitor_stops_cleanly_on_ctrl_c(sent, sigint):
    """
    Ctrl-C or SIGTERM ends the monitor with its summary, however SIGINT was set when it started.

    rclpy's handler shuts the context down on both signals; Python raises
    KeyboardInterrupt only for SIGINT at its default disposition. The monitor
    must stop on the context's shutdown alone: one that waits for
    KeyboardInterrupt printed its last message forever when the test suite
    ran as a background job (SIGINT ignored) or on SIGTERM.
    """
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=52)) as sim, \
            NodeProcess({'port': sim.port, 'address': 95}) as node:
        assert node.wait_for_output('streaming 0xCC'), node.output()
        monitor = subprocess.Popen(
            [sys.executable, '-c', MONITOR_WITH_SIGINT, sigint], env=ros_env(), cwd=REPO,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and ' Hz ' not in monitor.stdout.readline():
            pass
        monitor.send_signal(sent)
        out, err = monitor.communicate(timeout=30)
        assert monitor.returncode == 0, err
        assert 'Traceback' not in err, err
        assert out.splitlines()[-1].endswith('messages received')
        assert node.stop()[0] == 0
