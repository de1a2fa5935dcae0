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
The diagnostics builders, from plain values: every level decision, no node.

The node tests (test_node_diagnostics.py) show the statuses arrive; these
show each one says the right thing in every case, including the ones a
simulator run cannot reach cheaply (a weak radio, an implausible drift).
"""

from diagnostic_msgs.msg import DiagnosticStatus
from i3dmgx2_driver.device.gyro_bias import Calibration
from i3dmgx2_driver.device.identity import DeviceInfo
from i3dmgx2_driver.device.link import RadioStats
from i3dmgx2_driver.device.record_rate import RateMeter
from i3dmgx2_driver.device.sample_clock import ClockStatus
from i3dmgx2_driver.device.status import DeviceStatus, State
from i3dmgx2_driver.ros import diagnostic_statuses as d
import pytest

INFO = DeviceInfo('3DM-GX2', '3095', '3DM-GX2 Wireless', '5g 300deg/s', '2.1.03')
GOOD_RADIO = RadioStats(230, 170, 200, 150, 228.5, 168.0)


def connection(state, wireless=True, capture='off', **changes):
    """Build the connection status from a device snapshot."""
    device = {'state': state, 'port': '/dev/ttyUSB0', 'address': 95, 'wireless': wireless,
              'connections': 1, 'reconnects': 0, 'stalls': 0,
              'last_error': '', 'low_latency_state': 'on', 'ping_ok': True}
    device.update(changes)
    return d.connection_status(DeviceStatus(**device), capture)


@pytest.mark.parametrize('state, changes, level', [
    (State.STREAMING, {}, d.OK),
    (State.STREAMING, {'reconnects': 3, 'last_error': 'old trouble'}, d.OK),
    (State.PAUSED, {}, d.OK),
    (State.STALLED, {}, d.WARN),
    (State.CONNECTING, {'connections': 0}, d.WARN),
    (State.INITIALISING, {}, d.WARN),
    (State.DISCONNECTED, {'last_error': 'serial port gone'}, d.ERROR),
    (State.CONNECTING, {'connections': 2, 'reconnects': 1, 'last_error': 'x'}, d.ERROR),
    (State.STOPPED, {}, d.ERROR),
    (State.READY, {}, d.OK),  # a managed node, inactive: quiet on purpose
])
def test_connection_levels(state, changes, level):
    status = connection(state, **changes)
    assert status.level == level, status
    assert status.value('state') == state.value


def test_connection_shows_what_a_user_needs():
    status = connection(State.DISCONNECTED, last_error='serial port /dev/ttyUSB0 does not exist',
                        reconnects=2, low_latency_state='refused by the port (ValueError)',
                        capture='/tmp/a.gx2: 3 reads, 100 bytes')
    assert 'does not exist' in status.message
    assert status.value('reconnects') == '2'
    assert status.value('low-latency mode') == 'refused by the port (ValueError)'
    assert status.value('raw capture') == '/tmp/a.gx2: 3 reads, 100 bytes'
    assert status.value('port') == '/dev/ttyUSB0'
    wired = connection(State.STREAMING, wireless=False, ping_ok=None)
    assert wired.value('base station ping') == 'n/a (wired)'


@pytest.mark.parametrize('measured, expected, level', [
    (100.0, 100.0, d.OK),
    (95.1, 100.0, d.OK),
    (104.9, 100.0, d.OK),
    (94.0, 100.0, d.WARN),
    (106.0, 100.0, d.WARN),
    (80.0, 100.0, d.WARN),
    (None, 100.0, d.OK),      # the first tick after a start: nothing measured yet
    (100.0, None, d.WARN),    # the divider was never read
])
def test_rate_levels(measured, expected, level):
    assert d.rate_level(measured, expected)[0] == level


DEVICE_FIELDS = ('expected_hz', 'line_use', 'line_warning')


def stream(state=State.STREAMING, measured=100.0, received=100, **changes):
    """Build the stream status from a device snapshot and what the node saw."""
    device = {'state': state, 'divider': 512, 'expected_rate_hz': 100.0}
    for name in DEVICE_FIELDS:
        if name in changes:
            device['expected_rate_hz' if name == 'expected_hz' else name] = changes.pop(name)
    seen = {'measured_hz': measured, 'received': received, 'period': 1.0, 'silent_for': 0.01,
            'published': 1000, 'lost': 3, 'lost_in_period': 1, 'device_resets': 0,
            'other_records': 0, 'mag_published': 1000}
    seen.update({'label' if k == 'stream' else k: v for k, v in changes.items()})
    return d.stream_status(DeviceStatus(**device), d.StreamPeriod(**seen))


def test_stream_ok_warn_stale():
    assert stream().level == d.OK
    assert stream().value('lost (timer gaps)') == '3'
    assert stream().value('published') == '1000'
    off = stream(measured=80.0)
    assert off.level == d.WARN
    assert '80.0 Hz' in off.message and '5%' in off.message
    quiet = stream(state=State.DISCONNECTED, measured=None, received=0, silent_for=4.2)
    assert quiet.level == d.STALE
    assert '4.2 s' in quiet.message
    never = stream(state=State.CONNECTING, measured=None, received=0, silent_for=None)
    assert never.level == d.STALE
    paused = stream(state=State.PAUSED, measured=None, received=0, operation='self test')
    assert paused.level == d.WARN
    assert 'self test' in paused.message


def test_radio_levels():
    assert d.radio_status(True, GOOD_RADIO, fresh=True).level == d.OK
    status = d.radio_status(True, GOOD_RADIO, fresh=True)
    assert [status.value(k) for k in ('LQI', 'RSSI', 'LQI min', 'RSSI min')] == \
        ['230', '170', '200', '150']
    assert status.value('LQI mean') == '228.5'
    weak = d.radio_status(True, GOOD_RADIO._replace(lqi=40), fresh=True)
    assert weak.level == d.WARN and 'LQI 40' in weak.message
    faint = d.radio_status(True, GOOD_RADIO._replace(rssi=20), fresh=True)
    assert faint.level == d.WARN and 'RSSI 20' in faint.message
    assert d.radio_status(True, GOOD_RADIO, fresh=False).level == d.STALE
    assert d.radio_status(True, None, fresh=False).level == d.STALE
    assert d.radio_status(False, None, fresh=True).level == d.OK


def test_parser_warns_only_while_failures_grow():
    before = {'good_frames': 100, 'checksum_failures': 2, 'length_failures': 1,
              'bytes_skipped': 40, 'foreign_frames': 0}
    assert d.parser_status(before, None).level == d.OK
    same = dict(before, good_frames=200, bytes_skipped=60)
    assert d.parser_status(same, before).level == d.OK
    worse = dict(before, good_frames=200, checksum_failures=5)
    status = d.parser_status(worse, before)
    assert status.level == d.WARN
    assert '3 checksum failures' in status.message
    assert status.value('checksum failures') == '5'
    longer = dict(before, length_failures=4)
    assert d.parser_status(longer, before).level == d.WARN
    foreign = dict(before, foreign_frames=7)
    status = d.parser_status(foreign, before)
    assert status.level == d.OK and '7 frames from other sensors' in status.message
    assert status.value('foreign-address frames') == '7'


def assert_values(status, expected: dict[str, str]) -> None:
    """Check the status's values by key, every one (a mismatch shows them all)."""
    assert {key: status.value(key) for key in expected} == expected


def test_device_status():
    status = d.device_status(DeviceStatus(info=INFO, connections=1, divider=512,
                                          expected_rate_hz=100.0, eeprom_writes=1), 95, 25.3)
    assert status.level == d.OK
    assert_values(status, {'EEPROM writes': '1', 'serial number': '3095', 'firmware': '2.1.03',
                           'options': '5g 300deg/s', 'model': '3DM-GX2 Wireless',
                           'accel temperature (C)': '25.3'})
    assert d.device_status(DeviceStatus(connections=1, divider=512), 95, None).level == d.WARN
    assert d.device_status(DeviceStatus(), 95, None).level == d.STALE


def test_time_status():
    clock = ClockStatus(samples=500, drift_ppm=-38.2, restarts={'start': 1, 'reset': 2},
                        rollovers=3, gaps=4, last_restart='reset', last_reset_at=100.0)
    ok = d.time_status('device', clock, 100.0 + d.RESET_WARNING_S + 1)
    assert ok.level == d.OK
    assert_values(ok, {'clock drift (ppm)': '-38.2',
                       'fit started afresh': 'start 1, reset 2, resync 0, reconnect 0',
                       'last fresh start': 'reset', 'timer rollovers': '3', 'gaps bridged': '4'})
    # A restart of the sensor's timer is a warning for a while, then history.
    recent = d.time_status('device', clock, 130.0)
    assert recent.level == d.WARN
    assert 'restarted 30 s ago' in recent.message
    assert d.time_status('device', ClockStatus(), 0.0).level == d.STALE
    assert d.time_status('device', ClockStatus(samples=500, drift_ppm=5000.0), 0.0).level \
        == d.WARN
    assert d.time_status('device', ClockStatus(samples=500, drift_ppm=float('nan')),
                         0.0).level == d.WARN
    assert d.time_status('host', ClockStatus(), 0.0).level == d.OK


def test_calibration_status():
    assert d.calibration_status(None, None, 100.0).level == d.OK
    assert d.calibration_status(None, None, 100.0).value('gyro bias captured') == 'no'
    good = Calibration(90.0, True, (-0.0033, -0.0217, -0.0052), 500, 'bias ...')
    status = d.calibration_status(good, good, 100.0)
    assert status.level == d.OK
    assert status.value('gyro bias (rad/s)') == '(-0.00330, -0.02170, -0.00520)'
    assert status.value('captured (s ago)') == '10'
    bad = Calibration(95.0, False, (0.2, 0.0, 0.0), 500, 'the sensor moved')
    status = d.calibration_status(bad, good, 100.0)
    assert status.level == d.WARN
    assert 'moved' in status.message
    assert status.value('gyro bias captured') == 'yes'


def test_rate_meter_measures_between_last_records_and_restarts():
    meter = RateMeter()
    assert meter.update(10, 100.0, running=True) is None
    assert meter.update(110, 101.0, running=True) == pytest.approx(100.0)
    assert meter.update(110, 101.0, running=True) is None   # nothing new
    assert meter.update(110, 101.0, running=False) is None  # paused: restart
    assert meter.update(120, 105.0, running=True) is None   # not across the pause
    assert meter.update(200, 106.0, running=True) == pytest.approx(80.0)


def test_to_message_prefixes_names_and_sets_levels():
    statuses = [d.Status(d.OK, 'a', 'fine', (('k', 'v'),)),
                d.Status(d.STALE, 'b', 'nothing', ())]
    msgs = d.to_message(statuses, '3095')
    assert [m.name for m in msgs] == ['i3dmgx2_driver: a', 'i3dmgx2_driver: b']
    assert msgs[0].level == DiagnosticStatus.OK
    assert msgs[1].level == DiagnosticStatus.STALE
    assert {m.hardware_id for m in msgs} == {'3095'}
    assert (msgs[0].values[0].key, msgs[0].values[0].value) == ('k', 'v')


def test_a_stream_that_does_not_fit_the_line_is_a_warning_whatever_the_rate():
    use = '0xCC at 299.4 Hz: 88 B packets, 26,349 of 11,520 bytes/s (229% of the line)'
    warning = 'the device is set to a rate the line cannot carry, records will be skipped: ...'
    status = stream(stream='0xCC (full)', line_use=use, line_warning=warning)
    assert (status.level, status.message) == (d.WARN, warning)
    assert status.value('stream') == '0xCC (full)'
    assert status.value('line use') == use
    # Paused says why there is no data; it fits: the rate decides.
    assert stream(state=State.PAUSED, line_warning=warning).message.startswith('no data')
    assert stream(stream='0xC2 (inertial)', line_use='fits').level == d.OK
    assert stream().value('line use') == 'rate unknown'


def test_stream_stopped_on_purpose_is_no_staleness():
    status = stream(State.READY, measured=None, received=0, silent_for=30.0, published=500)
    assert status.level == d.OK
    assert 'node inactive' in status.message


@pytest.mark.parametrize('label, state, level, words', [
    ('unconfigured', None, d.OK, 'waiting for configure'),
    ('inactive', State.READY, d.OK, 'waiting for activate'),
    ('active', State.STREAMING, d.OK, 'active'),
    ('active', State.PAUSED, d.OK, 'active'),
    ('active', State.STALLED, d.WARN, 'recovering the stream: stalled'),
    ('active', State.DISCONNECTED, d.WARN, 'recovering the stream: disconnected'),
    ('active', State.INITIALISING, d.WARN, 'recovering the stream: initialising'),
    ('configuring', State.INITIALISING, d.OK, 'configuring (in transition)'),
])
def test_lifecycle_status(label, state, level, words):
    status = d.lifecycle_status(label, state)
    assert status.level == level, status
    assert words in status.message
    assert status.value('lifecycle state') == label
    assert status.value('device state') == (state.value if state else
                                            'no port (not configured)')


def test_the_ticks_end_quietly_when_the_node_is_destroyed_without_stop():
    """A node destroyed under its diagnostics thread: the thread ends, nothing said as an error."""
    import threading
    import time

    from i3dmgx2_driver.ros.diagnostics import DiagnosticsPublisher
    import rclpy
    from rclpy.node import Node

    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node('diagnostics_destroyed_test', context=context)
    errors = []
    node.get_logger().error = errors.append
    diagnostics = DiagnosticsPublisher(node, lambda: None, period=0.005)
    time.sleep(0.05)  # a few ticks published
    node.destroy_node()
    try:
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline and any(
                t.name == 'gx2-diagnostics' and t.is_alive() for t in threading.enumerate()):
            time.sleep(0.01)
        assert not any(t.name == 'gx2-diagnostics' and t.is_alive()
                       for t in threading.enumerate())
        assert errors == []
    finally:
        diagnostics.stop()
        rclpy.shutdown(context=context)
