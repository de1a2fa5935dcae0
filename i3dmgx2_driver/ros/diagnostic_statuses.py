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
What ``/diagnostics`` says: each status built by a pure function, and its message form.

Each status is built from plain values (numbers, strings, the device
layer's small records) into a ROS-free :class:`Status`, so every level
decision can be unit-tested without a node, a port or a clock;
:func:`to_message` turns statuses into ``DiagnosticStatus`` messages, for
the publisher (diagnostics.py) and the diagnostic self test (services.py).

Levels follow ``diagnostic_msgs/DiagnosticStatus``: OK, WARN, ERROR, and
STALE for "no data to judge by" (nothing arrives, nothing measured yet).
"""

from collections.abc import Iterable, Mapping
import math
from typing import NamedTuple

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from ..device.gyro_bias import Calibration
from ..device.operation import format_vector
from ..device.record_rate import RATE_TOLERANCE
from ..device.sample_clock import ClockStatus, Restart
from ..device.status import DeviceStatus, RadioStats, State

OK = 0
WARN = 1
ERROR = 2
STALE = 3

#: Prefix of every status name, as diagnostic_aggregator analyzers expect.
PREFIX = 'i3dmgx2_driver: '
#: Below these the radio link counts as poor. The base station reports LQI and
#: RSSI as raw bytes with no documented scale; a good link reads about 230 and
#: 170 (the real-records fixture, the simulator), so these are well below that.
LOW_LQI = 100
LOW_RSSI = 60
#: A drift estimate beyond this is implausible (the device clock is good to
#: 100 ppm, NTP slews the host's by at most 500 ppm): the stamps are suspect.
MAX_DRIFT_PPM = 600.0
#: How long (s) the time status stays WARN after the sensor's timer was found restarted.
RESET_WARNING_S = 60.0

#: The states the connection is well in whatever else is seen, and what it says of each.
_WELL = {State.STREAMING: 'streaming',
         State.READY: 'port open, device quiet: not streaming (node inactive)',
         State.PAUSED: 'stream paused for a device operation'}
#: Parser counters that mean a damaged frame, and when they grow, a WARN.
PARSER_FAILURES = ('checksum_failures', 'length_failures')
#: Parser counters shown, with their labels.
PARSER_KEYS = (
    ('good_frames', 'good frames'), ('checksum_failures', 'checksum failures'),
    ('length_failures', 'length failures'), ('bytes_skipped', 'bytes skipped'),
    ('foreign_frames', 'foreign-address frames'), ('acks', 'ACKs'), ('nacks', 'NACKs'),
    ('bytes_in', 'bytes read'))


class Status(NamedTuple):
    """One diagnostic status, ROS-free: level, short name, message, key-values."""

    level: int
    name: str
    message: str
    values: tuple[tuple[str, str], ...] = ()

    def value(self, key: str) -> str | None:
        """Return the value of ``key``, or None (for tests and logs)."""
        return next((value for name, value in self.values if name == key), None)


def _fmt(value: float | None, digits: int) -> str:
    return 'n/a' if value is None or math.isnan(value) else f'{value:.{digits}f}'


def connection_status(device: DeviceStatus, capture: str, fault_capture: str = '') -> Status:
    """
    Say whether the port is open and the device streaming.

    Disconnected is an ERROR (nothing can work until the port is back);
    connecting, initialising and stalled are WARN (the supervisor is on it);
    paused for an operation the driver itself started is OK. ``advice`` is
    what the line observer found while no record arrived (another address,
    the other framing, unreadable bytes, silence): an ERROR that says what
    to change. ``capture`` says what the raw capture is doing,
    ``fault_capture`` what the fault capture keeps and where it last wrote
    ('' leaves its line out).
    """
    state, advice, last_error = device.state, device.advice, device.last_error
    if state in _WELL:
        level, message = OK, _WELL[state]
    elif advice:
        level, message = ERROR, f'no records: {advice}'
    elif state is State.STALLED:
        level, message = WARN, 'stream stalled: re-requesting continuous mode'
    elif state in (State.CONNECTING, State.INITIALISING) and not device.reconnects \
            and device.connections <= 1 and not last_error:
        level, message = WARN, f'{state.value}'
    elif state is State.STOPPED:
        level, message = ERROR, 'driver stopped'
    elif state in (State.CONNECTING, State.INITIALISING):
        level, message = ERROR, f'{state.value} after a failure: {last_error or "?"}'
    else:
        level, message = ERROR, f'disconnected: {last_error or "port lost"}'
    return Status(level, 'connection', message, (
        ('port', device.port), ('node address', str(device.address)),
        ('link', 'wireless' if device.wireless else 'wired'), ('state', state.value),
        ('connections', str(device.connections)), ('reconnects', str(device.reconnects)),
        ('stalls', str(device.stalls)), ('last error', last_error or '-'),
        ('low-latency mode', device.low_latency_state or 'not opened yet'),
        ('base station ping', {None: 'not tried', True: 'ok', False: 'no answer'}[
            device.ping_ok] if device.wireless else 'n/a (wired)'),
        ('raw capture', capture), *((('fault capture', fault_capture),) if fault_capture else ()),
        ('observed on the line', advice or '-')))


def rate_level(measured_hz: float | None, expected_hz: float | None,
               tolerance: float = RATE_TOLERANCE) -> tuple[int, str]:
    """Judge a measured data rate against the configured one (±``tolerance``)."""
    if measured_hz is None:
        return OK, 'measuring the rate'
    if not expected_hz:
        return WARN, f'{measured_hz:.1f} Hz; configured rate unknown'
    error = measured_hz / expected_hz - 1.0
    text = f'{measured_hz:.1f} Hz (configured {expected_hz:.1f} Hz, {error:+.1%})'
    return (OK, text) if abs(error) <= tolerance else (
        WARN, f'rate off by more than {tolerance:.0%}: {text}')


class StreamPeriod(NamedTuple):
    """What the node saw of the stream over the last diagnostics period, and in all."""

    #: The stream's label ('0xCC (full)').
    label: str = ''
    measured_hz: float | None = None
    received: int = 0
    #: Length of the period (s), and how long since the last record (None: none yet).
    period: float = 1.0
    silent_for: float | None = None
    published: int = 0
    lost: int = 0
    lost_in_period: int = 0
    device_resets: int = 0
    other_records: int = 0
    mag_published: int = 0
    #: The device operation a service runs now ('' if none).
    operation: str = ''


def stream_status(device: DeviceStatus, seen: StreamPeriod) -> Status:
    """
    Judge the IMU stream over the last period: whether it arrives, at its rate.

    STALE when no record arrived in the period (there is no data to judge),
    WARN when paused or the measured rate is off by more than 5 %, and WARN
    whenever the device's rate is more than the line carries for the stream
    (``line_warning``): records are being skipped, whatever the rate shows.
    """
    state, line_warning, expected_hz = device.state, device.line_warning, device.expected_rate_hz
    if line_warning and state is not State.PAUSED:
        level, message = WARN, line_warning
    elif state is State.PAUSED:
        operation = seen.operation or 'a device operation'
        level, message = WARN, f'no data: stream paused for {operation}'
    elif state is State.READY:
        level, message = OK, 'no data: stream stopped on purpose (node inactive)'
    elif seen.received == 0:
        since = f' for {seen.silent_for:.1f} s' if seen.silent_for is not None else ' yet'
        level, message = STALE, f'no data{since}'
    else:
        level, message = rate_level(seen.measured_hz, expected_hz)
    return Status(level, 'stream', message, (
        ('stream', seen.label or 'n/a'), ('line use', device.line_use or 'rate unknown'),
        ('measured rate (Hz)', _fmt(seen.measured_hz, 2)),
        ('configured rate (Hz)', _fmt(expected_hz, 2)),
        ('records in last period', str(seen.received)), ('period (s)', _fmt(seen.period, 2)),
        ('published', str(seen.published)), ('lost (timer gaps)', str(seen.lost)),
        ('lost in last period', str(seen.lost_in_period)),
        ('magnetometer published', str(seen.mag_published)),
        ('other records', str(seen.other_records)),
        ('device resets', str(seen.device_resets))))


def radio_status(wireless: bool, radio: RadioStats | None, fresh: bool,
                 low_lqi: int = LOW_LQI, low_rssi: int = LOW_RSSI) -> Status:
    """
    Judge the radio link by the latest LQI and RSSI the base station reported.

    WARN when either is low; STALE when no packet arrived in the last period
    (the numbers are old); OK with nothing to show on a wired sensor.
    """
    if not wireless:
        return Status(OK, 'radio link', 'wired sensor: no radio', ())
    if radio is None:
        return Status(STALE, 'radio link', 'no packet received yet', ())
    values = (('LQI', str(radio.lqi)), ('RSSI', str(radio.rssi)),
              ('LQI min', str(radio.lqi_min)), ('RSSI min', str(radio.rssi_min)),
              ('LQI mean', f'{radio.lqi_mean:.1f}'), ('RSSI mean', f'{radio.rssi_mean:.1f}'),
              ('LQI warn below', str(low_lqi)), ('RSSI warn below', str(low_rssi)))
    if not fresh:
        return Status(STALE, 'radio link', 'no packet in the last period', values)
    low = [f'{name} {value} < {limit}' for name, value, limit in
           (('LQI', radio.lqi, low_lqi), ('RSSI', radio.rssi, low_rssi)) if value < limit]
    if low:
        return Status(WARN, 'radio link', 'weak link: ' + ', '.join(low), values)
    return Status(OK, 'radio link', f'LQI {radio.lqi}, RSSI {radio.rssi}', values)


def parser_status(totals: Mapping[str, int], previous: Mapping[str, int] | None,
                  strays: Mapping[int, int] | None = None) -> Status:
    """
    Show the parser's counters; WARN while damaged frames keep arriving.

    ``strays``, on a port several sensors share: the packets of addresses
    none of them has, by address, named so that a sensor left out of
    ``addresses`` is found.

    Checksum and length failures that grew since the previous period mean a
    noisy line or radio (or another protocol on the port); skipped bytes
    alone are normal at start-up and after a reconnect.
    """
    values = tuple((label, str(totals.get(key, 0))) for key, label in PARSER_KEYS)
    named = ''
    if strays:
        named = ', '.join(f'node {address}: {count}' for address, count in sorted(strays.items()))
        values += (('packets of unlisted addresses', named),)
    if previous is None:
        return Status(OK, 'parser', 'counting', values)
    grown = {key: totals.get(key, 0) - previous.get(key, 0) for key in PARSER_FAILURES}
    foreign = totals.get('foreign_frames', 0) - previous.get('foreign_frames', 0)
    if any(count > 0 for count in grown.values()):
        text = ', '.join(f'{count} {key.replace("_", " ")}'
                         for key, count in grown.items() if count > 0)
        return Status(WARN, 'parser', f'damaged frames in the last period: {text}', values)
    if foreign > 0:
        seen = f' ({named})' if named else ''
        return Status(OK, 'parser', f'{foreign} frames from other sensors ignored{seen}', values)
    return Status(OK, 'parser', 'no damaged frames in the last period', values)


def device_status(device: DeviceStatus, address: int, temperature_c: float | None,
                  temperature_unavailable: str = '') -> Status:
    """
    Show what the device said it is; WARN when it did not say.

    STALE before the first connection (nothing asked yet). A temperature
    its firmware does not give (``temperature_unavailable``, why) is said,
    and is no fault.
    """
    info, divider, connected_once = device.info, device.divider, device.connections > 0
    values = [('node address', str(address)),
              ('rate divider (EEPROM 0xFCA2)', str(divider) if divider else 'unknown'),
              ('EEPROM writes', str(device.eeprom_writes)),
              ('configured rate (Hz)', _fmt(device.expected_rate_hz, 2))]
    if temperature_c is not None:
        values.append(('accel temperature (C)', _fmt(temperature_c, 1)))
    elif temperature_unavailable:
        values.append(('accel temperature (C)',
                       f'unavailable on this firmware: {temperature_unavailable}'))
    if info is None:
        level = WARN if connected_once else STALE
        text = ('the device did not tell its identity (0xEA, 0xE9)' if connected_once
                else 'not connected yet')
        return Status(level, 'device', text, tuple(values))
    values = [('model', info.model_name or '?'), ('model number', info.model_number or '?'),
              ('serial number', info.serial_number or '?'), ('firmware', info.firmware or '?'),
              ('options', info.options or '-'), *values]
    return Status(OK, 'device', f'{info.model_name or info.model_number or "?"}, serial '
                                f'{info.serial_number or "?"}, firmware {info.firmware or "?"}',
                  tuple(values))


def time_status(time_source: str, clock: ClockStatus, now: float,
                max_drift_ppm: float = MAX_DRIFT_PPM, time_offset: float = 0.0) -> Status:
    """
    Show how stamps are made and what the device clock went through.

    ``clock`` is the stamping clock's snapshot, ``now`` the monotonic time.
    WARN for ``RESET_WARNING_S`` after the sensor's timer was found to have
    restarted (a power cycle the driver may not otherwise notice), and when
    the fit is implausible; STALE before the first sample (device time).
    ``time_offset`` is the ``time_offset`` parameter, added to every stamp.
    """
    samples, drift_ppm = clock.samples, clock.drift_ppm
    restarts = ', '.join(f'{reason.value} {clock.restarts.get(reason.value, 0)}'
                         for reason in Restart)
    values = (
        ('time source', time_source), ('time offset (s)', f'{time_offset:+.6f}'),
        ('clock drift (ppm)', f'{drift_ppm:.1f}' if samples else 'n/a'),
        ('samples in this fit', str(samples)), ('fit started afresh', restarts),
        ('last fresh start', clock.last_restart or 'n/a'),
        ('timer rollovers', str(clock.rollovers)), ('gaps bridged', str(clock.gaps)))
    if time_source != 'device':
        return Status(OK, 'time', 'host time: stamps are packet read times', values)
    if not samples:
        return Status(STALE, 'time', 'no samples to align the device clock yet', values)
    if clock.last_reset_at is not None and now - clock.last_reset_at < RESET_WARNING_S:
        ago = now - clock.last_reset_at
        return Status(WARN, 'time', f"the sensor's timer restarted {ago:.0f} s ago (power "
                                    f'cycle or brown-out?): the clock fit started afresh',
                      values)
    if not math.isfinite(drift_ppm) or abs(drift_ppm) > max_drift_ppm:
        return Status(WARN, 'time', f'implausible clock drift {drift_ppm:.0f} ppm '
                                    f'(over {max_drift_ppm:.0f}): stamps are suspect', values)
    return Status(OK, 'time', f'device clock, drift {drift_ppm:.1f} ppm', values)


def calibration_status(last: Calibration | None, good: Calibration | None,
                       now: float, mag_calibrated: bool = False) -> Status:
    """
    Show the gyro bias captured in this session, and WARN if the last try failed.

    ``last`` is the last attempt, ``good`` the last accepted one;
    ``mag_calibrated``: whether mag_hard_iron or mag_soft_iron correct the field.
    """
    values = (('gyro bias captured', 'yes' if good else 'no'),
              ('magnetometer calibration', 'loaded' if mag_calibrated else 'none'))
    if good is not None and good.bias is not None:
        values += (('gyro bias (rad/s)', format_vector(good.bias)),
                   ('captured (s ago)', f'{now - good.time:.0f}'),
                   ('sampling time (ms)', str(good.sampling_ms)))
    if last is not None and not last.accepted:
        return Status(WARN, 'calibration', f'last gyro bias capture failed: {last.summary}',
                      (*values, ('last attempt', last.summary)))
    if good is None:
        return Status(OK, 'calibration', 'no gyro bias captured in this session: the device '
                                         'uses its stored bias', values)
    return Status(OK, 'calibration', f'gyro bias captured {now - good.time:.0f} s ago', values)


def lifecycle_status(label: str, state: State | None) -> Status:
    """
    Say which lifecycle state the managed node is in, and whether that is well.

    Unconfigured and inactive are states a bringup manager chose: OK. Active
    is OK while the stream runs (or is paused for a service), WARN while the
    supervisor recovers it (stalled, disconnected, reconnecting): the node
    stays active through it. ``state`` is the supervisor's, None with no
    configuration.
    """
    device = state.value if state is not None else 'no port (not configured)'
    values = (('lifecycle state', label), ('device state', device))
    if label == 'active':
        if state in (State.STREAMING, State.PAUSED):
            return Status(OK, 'lifecycle', 'active', values)
        return Status(WARN, 'lifecycle', f'active, recovering the stream: {device}', values)
    text = {'unconfigured': 'unconfigured: port closed, waiting for configure',
            'inactive': 'inactive: port open, not streaming, waiting for activate',
            'finalized': 'finalized: shutting down'}.get(label, f'{label} (in transition)')
    return Status(OK, 'lifecycle', text, values)


def to_message(statuses: Iterable[Status], hardware_id: str,
               prefix: str = PREFIX) -> list[DiagnosticStatus]:
    """
    Turn statuses into ``DiagnosticStatus`` messages, names prefixed.

    The node passes its own name as the prefix, so that two drivers side by
    side (two sensors) publish statuses an aggregator tells apart.
    """
    return [DiagnosticStatus(level=bytes((status.level,)), name=prefix + status.name,
                             message=status.message, hardware_id=hardware_id,
                             values=[KeyValue(key=key, value=value)
                                     for key, value in status.values])
            for status in statuses]
