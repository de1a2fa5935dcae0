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
The node's published stamps through a sensor power cycle, as a robot meets it (#23).

The node runs as its own process; a subscriber in this process receives
``/imu/raw_data`` and ``/diagnostics``; each message is matched to the
simulator's record by its values and its stamp compared with the true sample
time. The sensor loses power for a second and comes back in polled mode with
its timer restarted: far from the timer's rollover, and 0.4 s before it,
where the timer's fall alone looks like a rollover (the issue's run: stamps
8 % slow for 5 s, then a 408 ms jump). Every stamp must stay true
(stamp_series.check_series), the node must say the timer restarted, and the
time status on /diagnostics must show the reset.
"""

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from harness.processes import isolate_ros_domain, Listener, NodeProcess, stamp_seconds
from harness.stamp_runs import check_series
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu
from test_node_messages import match, stream_truth

# alone: the stamps of a node process held to 5 ms in the graces and its fit's trend to 300
# ppm 4 s after a power cycle; beside three busy workers its reads come late by milliseconds
# (6.6 ms and -314 ppm seen), which this process cannot see.
pytestmark = [pytest.mark.slow, pytest.mark.alone]


def time_status(listener: Listener) -> DiagnosticStatus | None:
    """Return the latest 'time' status the node published, if any."""
    for array in reversed(listener.received('/diagnostics')):
        for status in array.status:
            if status.name.endswith('time'):
                return status
    return None


@pytest.mark.parametrize('before_rollover', [None, 0.4])
def test_power_cycle_keeps_every_stamp_true(before_rollover):
    isolate_ros_domain()
    # The rollover comes 9 s after power-up: the cut is made at the chosen timer value.
    start_timer = TIMER_MODULUS - round(9.0 * TICKS_PER_SECOND)
    sim = PtySimulator(SimulatorConfig(seed=23, timer_start=start_timer)).start()
    listener = Listener({'imu/raw_data': Imu, '/diagnostics': DiagnosticArray})
    node = NodeProcess({'port': sim.port, 'address': 95, 'read_timeout': 0.3})
    try:
        assert node.wait_for_output('streaming 0xCC'), node.output()
        listener.wait_for('imu/raw_data', 100, timeout=20)
        # Cut power when the timer is where the test wants it (or 1.5 s from now).
        cut_timer = (TIMER_MODULUS - round(before_rollover * TICKS_PER_SECOND)
                     if before_rollover is not None else None)
        deadline = time.monotonic() + (8.0 if cut_timer is not None else 1.5)
        while time.monotonic() < deadline:
            last = sim.truth[-1]
            if cut_timer is not None and last.timer >= cut_timer - 2 * 196_608:
                break
            time.sleep(0.002)
        else:
            assert cut_timer is None, 'the simulated timer never reached the cut'
        event = time.time()
        sim.power_cycle(off_seconds=1.0, timer_start=0)
        time.sleep(4.0)
        messages = listener.received('imu/raw_data')
        pairs = [(msg, entry) for msg, entry in match(messages, stream_truth(sim), 'enu')
                 if entry is not None]
        series = [(entry.sample_time, stamp_seconds(msg) - entry.sample_time)
                  for msg, entry in pairs]
        assert len(series) > 300
        figures = check_series(series, event, node.output())
        assert figures['back'] is not None
        assert node.wait_for_output('timer restarted', timeout=5.0), node.output()
        status = time_status(listener)
        assert status is not None
        values = {kv.key: kv.value for kv in status.values}
        assert 'reset 1' in values['fit started afresh'], values
        assert status.level == DiagnosticStatus.WARN, status.message
        assert 'restarted' in status.message
    finally:
        node.close()
        listener.close()
        sim.stop()
