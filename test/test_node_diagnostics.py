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
/diagnostics from the real node against the simulator, through real rclpy.

One simulator and one node serve the whole module (a node start costs
seconds), and the tests run in file order, each putting the simulator back
as it found it: all OK while streaming, WARN when the rate is off, the
parser's counters moving under corruption, and ERROR/STALE after an unplug,
which comes last. Waits are generous; nothing is judged by how fast.
"""

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
import pytest

pytestmark = pytest.mark.slow

PREFIX = 'i3dmgx2_driver: '
NAMES = {'connection', 'stream', 'radio link', 'parser', 'device', 'time', 'calibration'}
OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)


@pytest.fixture(scope='module')
def rig():
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=41)) as sim:
        listener = Listener({'/diagnostics': DiagnosticArray})
        node = NodeProcess({'port': sim.port, 'address': 95, 'read_timeout': 0.5,
                            'reconnect_interval': 0.3})
        with listener, node:
            yield sim, listener, node
            assert node.stop()[0] == 0, node.output()


def by_name(array):
    return {s.name[len(PREFIX):]: s for s in array.status if s.name.startswith(PREFIX)}


def values(status):
    return {kv.key: kv.value for kv in status.values}


def wait_for(listener, node, predicate, what, timeout=15.0):
    """Return the first diagnostics (by name) from now on that satisfy ``predicate``."""
    seen = len(listener.received('/diagnostics'))
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        arrays = listener.received('/diagnostics')
        for array in arrays[seen:]:
            last = by_name(array)
            if predicate(last):
                return last
        seen = len(arrays)
        time.sleep(0.05)
    summary = {k: (s.level, s.message) for k, s in (last or {}).items()}
    raise AssertionError(f'no diagnostics with {what} in {timeout} s; last: {summary}\n'
                         f'{node.output()}')


def test_every_status_ok_while_streaming_with_serial_as_hardware_id(rig):
    sim, listener, node = rig
    statuses = wait_for(listener, node, lambda s: s.keys() >= NAMES and all(
        x.level == OK for x in s.values()) and values(s['stream'])['measured rate (Hz)']
        != 'n/a', 'every status OK', timeout=30)
    assert {s.hardware_id for s in statuses.values()} == {'3095'}
    assert float(values(statuses['stream'])['measured rate (Hz)']) == pytest.approx(100, rel=0.05)
    assert values(statuses['stream'])['configured rate (Hz)'] == '100.00'
    assert int(values(statuses['stream'])['published']) > 0
    assert values(statuses['connection'])['port'] == sim.port
    assert values(statuses['connection'])['state'] == 'streaming'
    device = values(statuses['device'])
    assert (device['serial number'], device['firmware'], device['model']) == \
        ('3095', '2.1.13', '3DM-GX2 Wireless')
    radio = values(statuses['radio link'])
    assert 0 < int(radio['LQI']) <= 255 and 0 < int(radio['RSSI']) <= 255
    assert int(radio['LQI min']) <= float(radio['LQI mean'])
    assert values(statuses['time'])['time source'] == 'device'
    assert values(statuses['calibration'])['gyro bias captured'] == 'no'


def test_rate_off_is_a_warning(rig):
    sim, listener, node = rig

    def measured(statuses):
        text = values(statuses['stream'])['measured rate (Hz)']
        return float(text) if text != 'n/a' else 0.0

    sim.set_rate(80.0)  # the device runs slower than its divider (100 Hz) says
    try:
        # The first period may straddle the change; a whole one measures 80 Hz.
        statuses = wait_for(listener, node, lambda s: s['stream'].level == WARN
                            and abs(measured(s) - 80.0) < 4.0, 'stream WARN at 80 Hz')
        assert 'rate off' in statuses['stream'].message
        assert 'configured 100.0 Hz' in statuses['stream'].message
    finally:
        sim.set_rate(None)
    wait_for(listener, node, lambda s: s['stream'].level == OK, 'stream OK again')


def test_parser_counters_move_under_corruption(rig):
    sim, listener, node = rig
    before = values(wait_for(listener, node, lambda s: True, 'anything')['parser'])
    sim.set_faults(corrupt_checksum_probability=0.2, corrupt_length_probability=0.2)
    try:
        statuses = wait_for(
            listener, node, lambda s: s['parser'].level == WARN
            and int(values(s['parser'])['checksum failures']) > int(before['checksum failures'])
            and int(values(s['parser'])['length failures']) > int(before['length failures']),
            'parser WARN with both counters up')
        assert 'damaged frames' in statuses['parser'].message
        after = values(statuses['parser'])
        assert int(after['good frames']) > int(before['good frames'])
        assert int(after['bytes skipped']) > int(before['bytes skipped'])
    finally:
        sim.set_faults(FaultConfig())
    wait_for(listener, node, lambda s: s['parser'].level == OK, 'parser OK again')


def test_unplug_is_an_error_and_the_stream_stale(rig):
    sim, listener, node = rig
    sim.unplug(seconds=None)
    try:
        statuses = wait_for(
            listener, node, lambda s: s['connection'].level == ERROR
            and s['stream'].level == STALE, 'connection ERROR and stream STALE')
        assert values(statuses['connection'])['last error'] != '-'
        assert 'no data' in statuses['stream'].message
        assert statuses['radio link'].level == STALE
    finally:
        assert sim.replug()
    statuses = wait_for(listener, node, lambda s: s['connection'].level == OK
                        and s['stream'].level == OK, 'recovery', timeout=30)
    assert int(values(statuses['connection'])['reconnects']) >= 1
