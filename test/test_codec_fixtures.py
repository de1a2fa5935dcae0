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
The 1,900 real 0xCC records of the fixture, decoded and checked for physics.

The fixture (``gx2_real_0xcc_records.txt``) holds the records as they sat in
wireless data packets, without the envelope; we wrap them ourselves. Its
``## set`` lines name the pose of the records that follow (for example
``x_up``: the +X axis along the reaction to gravity). The checks: every record
survives the framing and the parser; at rest the accelerometer reads 1 g along
the named axis; M is a rotation; the published ENU attitude carries the
measured "up" to +Z; NaN magnetometer readings stay NaN; the timer rollover is
unwrapped; the Euler angles follow docs/protocol.md §9's formulas.

The fixture is looked up in ``test/fixtures/``, then in ``../shared/fixtures``
next to the repository, or in the directory named by ``I3DMGX2_FIXTURES``.
"""

import itertools
import math
import re

from fixture_files import real_records_path
from harness.decoders import decode_data_packet
from i3dmgx2_driver.capture.fixtures import FixtureSet, timeline
from i3dmgx2_driver.codec import (
    DataPacket, encode_data_packet, encode_record, SensorStreamParser,
)
from i3dmgx2_driver.codec.orientation import (
    body_vector, euler_from_matrix, orientation, shepperd,
)
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation, TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.device.sample_clock import SampleClock
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_codec_orientation import attitude_enu, attitude_ned

ADDRESS = 95

# Measured worst angles between the accelerometer's "up" and the "up" of the sensor's own
# orientation estimate M, per set. This offset is in the data, not in our conventions: the
# device's own Euler angles show it too (x_up reads pitch 80.8 degrees where the accelerometer
# says 88; z_down reads pitch -12.6 where the accelerometer says -1.6). A wrong convention is
# far off: the transposed M misses by 34 to 48 degrees, a sign error by about 170.
UP_TOLERANCE_DEG = {'red': 14.0, 'green': 5.0, 'blue': 14.0, 'set1': 5.0}


class PoseSet:
    """The records of one '## set' block of the fixture."""

    def __init__(self, name, axis, sign, count, header):
        self.name = name
        self.axis = axis
        self.sign = sign
        self.count = count
        self.header = header
        self.raw = []


def _load():
    sets = []
    pattern = re.compile(r'^## set (\w+): ([xyz])_(up|down)\w* .*: (\d+) records$')
    for raw_line in real_records_path().read_text().splitlines():
        text = raw_line.strip()
        if text.startswith('## set'):
            match = pattern.match(text)
            assert match, f'unreadable set header: {text}'
            name, axis, direction, count = match.groups()
            sets.append(PoseSet(name, 'xyz'.index(axis), 1.0 if direction == 'up' else -1.0,
                                int(count), text))
        elif text and not text.startswith('#'):
            sets[-1].raw.append(bytes.fromhex(text))
    return sets


SETS = _load()
ALL_RAW = [raw for pose in SETS for raw in pose.raw]
SET_IDS = [pose.name for pose in SETS]


def _parse_all():
    """Wrap every record in a data packet, parse the whole stream at once."""
    packets = [encode_data_packet(ADDRESS, raw, index % 256, 255 - index % 256)
               for index, raw in enumerate(ALL_RAW)]
    parser = SensorStreamParser(address=ADDRESS)
    events = parser.feed(b''.join(packets))
    return packets, parser, events


PACKETS, PARSER, EVENTS = _parse_all()
RECORDS = [event.record for event in EVENTS if isinstance(event, DataPacket)]
BY_SET = {}
_start = 0
for _pose in SETS:
    BY_SET[_pose.name] = RECORDS[_start:_start + len(_pose.raw)]
    _start += len(_pose.raw)


def test_fixture_shape():
    """Four sets (three poses) of 300, 300, 300 and 1000 77-byte 0xCC records."""
    assert [(p.name, len(p.raw)) for p in SETS] == [
        ('red', 300), ('green', 300), ('blue', 300), ('set1', 1000)]
    assert all(len(p.raw) == p.count for p in SETS)
    assert len(ALL_RAW) == 1900
    assert all(len(raw) == 77 and raw[0] == 0xCC for raw in ALL_RAW)


def test_all_records_parse_in_one_stream():
    """All 1,900 wrapped records come out of the parser, in order, bit for bit."""
    assert len(EVENTS) == 1900
    assert all(isinstance(e, DataPacket) for e in EVENTS)
    stats = PARSER.stats
    assert stats.good_frames == 1900
    assert (stats.checksum_failures, stats.length_failures, stats.bytes_skipped,
            stats.foreign_frames, stats.acks, stats.nacks) == (0, 0, 0, 0, 0, 0)
    assert stats.bytes_in == 1900 * 88
    assert PARSER.pending == 0
    for index, (event, raw) in enumerate(zip(EVENTS, ALL_RAW, strict=True)):
        assert isinstance(event.record, AccelAngRateMagOrientation)
        assert (event.address, event.lqi, event.rssi) == (
            ADDRESS, index % 256, 255 - index % 256)
        assert encode_record(event.record) == raw


def test_parser_agrees_with_one_shot_decoder():
    """Chunked parsing and decode_data_packet give the same records as the one-stream parse."""
    parser = SensorStreamParser(address=ADDRESS)
    stream = b''.join(PACKETS)
    chunked = [e for k in range(0, len(stream), 1000) for e in parser.feed(stream[k:k + 1000])]
    assert len(chunked) == 1900
    for event, packet, raw in zip(chunked, PACKETS, ALL_RAW, strict=True):
        assert encode_record(event.record) == raw
        assert encode_record(decode_data_packet(packet).record) == raw


@pytest.mark.parametrize('pose', SETS, ids=SET_IDS)
def test_accel_is_one_g_along_the_named_axis(pose):
    """At rest |accel| is about 1 g, pointing along the axis the set's header names."""
    accel = np.array([r.accel for r in BY_SET[pose.name]])
    norms = np.linalg.norm(accel, axis=1)
    assert np.all(np.abs(norms - 1.0) < 0.02), (norms.min(), norms.max())
    expected = np.zeros(3)
    expected[pose.axis] = pose.sign
    angles = np.degrees(np.arccos(np.clip(accel @ expected / norms, -1.0, 1.0)))
    assert angles.max() < 5.0, pose.header
    # The other axes are small: the named one dominates every record.
    assert np.all(np.argmax(np.abs(accel), axis=1) == pose.axis)


@pytest.mark.parametrize('pose', SETS, ids=SET_IDS)
def test_sensor_is_at_rest(pose):
    """At rest the gyros read only a small bias (well under 0.05 rad/s)."""
    rates = np.array([r.angular_rate for r in BY_SET[pose.name]])
    assert np.abs(rates).max() < 0.05


def test_matrices_are_rotations():
    """Every M is orthonormal to ~1e-6 with determinant +1 (float32 precision)."""
    for record in RECORDS:
        m = np.array(record.matrix, dtype=float).reshape(3, 3)
        assert np.abs(m @ m.T - np.eye(3)).max() < 1e-6
        assert abs(np.linalg.det(m) - 1.0) < 1e-6


@pytest.mark.parametrize('convention', ['enu', 'ned'])
def test_quaternions_are_unit_and_match_scipy(convention):
    """The published quaternion is unit-norm, w >= 0, and the rotation scipy finds."""
    for record in RECORDS:
        q = orientation(record.matrix, convention)
        assert abs(math.sqrt(sum(c * c for c in q)) - 1.0) < 1e-12
        assert q.w >= 0.0
        if convention == 'enu':
            att = np.array(attitude_enu(record.matrix)).reshape(3, 3)
        else:
            att = np.array(attitude_ned(record.matrix)).reshape(3, 3)
        reference = Rotation.from_matrix(att).as_quat()
        if reference[3] < 0:
            reference = -reference
        assert np.abs(np.array(q) - reference).max() < 1e-6


@pytest.mark.parametrize('pose', SETS, ids=SET_IDS)
def test_enu_attitude_carries_measured_up_to_plus_z(pose):
    """The FLU accel at rest, rotated by the ENU attitude, points up (+Z), within a bound."""
    worst = 0.0
    for record in BY_SET[pose.name]:
        att = np.array(attitude_enu(record.matrix)).reshape(3, 3)
        up = att @ np.array(body_vector(record.accel, 'enu'))
        up /= np.linalg.norm(up)
        angle = math.degrees(math.acos(min(1.0, up[2])))
        # The same angle from the device's own convention, with no ROS axes in between:
        # up in NED is (0, 0, -1), so the sensor sees it as M @ (0, 0, -1) = -(third column).
        m = np.array(record.matrix, dtype=float).reshape(3, 3)
        accel = np.array(record.accel)
        own = math.degrees(math.acos(min(1.0, -m[:, 2] @ accel / np.linalg.norm(accel))))
        assert abs(angle - own) < 1e-4
        worst = max(worst, angle)
    assert worst < UP_TOLERANCE_DEG[pose.name], (pose.header, worst)


def test_nan_magnetometer_stays_nan():
    """The fixture's NaN magnetometer comes out as NaN, with the very same bits."""
    for record, raw in zip(RECORDS, ALL_RAW, strict=True):
        assert all(math.isnan(v) for v in record.mag)
        assert encode_record(record)[25:37] == raw[25:37] == bytes.fromhex('FFC00000') * 3
        for convention in ('enu', 'ned'):
            assert all(math.isnan(v) for v in body_vector(record.mag, convention))


@pytest.mark.parametrize('pose', SETS, ids=SET_IDS)
def test_timer_steps_match_the_poll_rate(pose):
    """Records came about 3 per second: most timer steps are 1/3 s or 1/4 s."""
    timers = [r.timer for r in BY_SET[pose.name]]
    steps = [(b - a) % TIMER_MODULUS for a, b in itertools.pairwise(timers)]
    regular = sum(1 for s in steps if 0.2 < s / TICKS_PER_SECOND < 0.4)
    assert regular / len(steps) > 0.9


def stamped(pose: PoseSet) -> tuple[SampleClock, list[int], list[bool]]:
    """
    Stamp the set's records with the driver's clock, read when a replay of the fixture plays them.

    A replay (``capture.timeline``) plays each record a timer step later than
    the one before, every step taken forward modulo 2^32. Returns the clock,
    its unwrapped ticks and whether each record restarted the fit.
    """
    clock = SampleClock(offset=lambda: 0.0)
    ticks, restarted = [], []
    for seconds, _, raw in timeline([FixtureSet(pose.name, pose.header, pose.raw)]):
        clock.stamp(int.from_bytes(raw[-4:], 'big'), seconds)
        ticks.append(clock.ticks)
        restarted.append(clock.restarted)
    return clock, ticks, restarted


@pytest.mark.parametrize('pose', SETS[:3], ids=SET_IDS[:3])
def test_timer_without_rollover(pose):
    """The three short sets never wrap: the unwrapped timer is the raw one, increasing."""
    clock, out, restarted = stamped(pose)
    assert out == [r.timer for r in BY_SET[pose.name]]
    assert all(b > a for a, b in itertools.pairwise(out))
    assert restarted[1:] == [False] * (len(out) - 1)
    assert clock.rollovers == 0 and 'reset' not in clock.status().restarts


def test_timer_rollover_is_unwrapped():
    """
    The long set wraps the 32-bit timer; the unwrapped count keeps increasing.

    It wraps three times: at record 616 (4,291,397,513 -> 2,984,329: a step of 6,554,112
    ticks, 1/3 s), at 770, and at 216 after a 60.5 s gap. Between records 750 and 751 the raw
    timer jumps from 858,295,945 to 4,171,399,561: 168.5 s forward, or 49.9 s back. A forward
    step of more than half the range cannot be told from a step back by the timer alone;
    the driver's clock tells them apart by the host time that elapsed, so read as a replay
    plays them (168.5 s later) the records run on through it, with no reset (read 1 s later,
    it is one: test_sample_clock.test_host_time_resolves_the_fixture_gap). Across the clean
    rollover the count moves by exactly the raw step (6,554,112 ticks: 1/3 s, the poll
    period).
    """
    timers = [r.timer for r in BY_SET['set1']]
    assert timers[616] > timers[617] and timers[616] > 4_290_000_000 and timers[617] < 3_000_000
    set1 = next(pose for pose in SETS if pose.name == 'set1')
    clock, out, restarted = stamped(set1)
    assert clock.rollovers == 3
    assert 'reset' not in clock.status().restarts and restarted[1:] == [False] * (len(out) - 1)
    for index in range(1, len(out)):
        assert out[index] > out[index - 1], index
        assert out[index] % TIMER_MODULUS == timers[index]
    assert out[617] - out[616] == 6_554_112
    assert (out[617] - out[616]) / TICKS_PER_SECOND == pytest.approx(1 / 3, abs=1e-4)
    assert out[616] < TIMER_MODULUS * 2 < out[617]
    assert out[751] - out[750] == timers[751] - timers[750]
    assert (out[751] - out[750]) / TICKS_PER_SECOND == pytest.approx(168.5, abs=0.1)
    assert out[-1] == 3 * TIMER_MODULUS + timers[-1]


def test_euler_angles_follow_protocol_formulas():
    """
    Check euler_from_matrix against docs/protocol.md §9's ZYX set.

    pitch asin(-M13), roll atan2(M23, M33), yaw atan2(M12, M11).
    """
    for record in RECORDS:
        m = record.matrix
        roll, pitch, yaw = euler_from_matrix(m)
        assert pitch == pytest.approx(math.asin(-m[2]), abs=1e-12)
        assert roll == pytest.approx(math.atan2(m[5], m[8]), abs=1e-12)
        assert yaw == pytest.approx(math.atan2(m[1], m[0]), abs=1e-12)
        # The same angles from scipy: M^T is the attitude, intrinsic Z-Y-X = yaw, pitch, roll.
        reference = Rotation.from_matrix(np.array(m).reshape(3, 3).T).as_euler('ZYX')
        assert np.allclose([yaw, pitch, roll], reference, atol=2e-6)


@pytest.mark.parametrize('pose', SETS, ids=SET_IDS)
def test_euler_angles_match_the_pose(pose):
    """
    The device's roll and pitch agree with the pose, within the estimate's offset.

    Measured: x_up pitch 79.0 to 80.8; y_up roll -94.7 to -94.1, pitch -4.3 to -3.7;
    z_down roll -3.0 to -2.5, pitch -14.1 to -12.6 (see UP_TOLERANCE_DEG).
    """
    angles = np.degrees([euler_from_matrix(r.matrix) for r in BY_SET[pose.name]])
    roll, pitch = angles[:, 0], angles[:, 1]
    if pose.axis == 0:    # x up: nose up 90 degrees (roll is then undefined)
        assert np.all(np.abs(pitch - 90.0) < 12.0)
        assert np.all(pitch < 90.0)
    elif pose.axis == 1:  # y (right) up: rolled left, roll -90
        assert np.all(np.abs(roll + 90.0) < 6.0) and np.all(np.abs(pitch) < 6.0)
    else:                 # z down: flat
        assert np.all(np.abs(roll) < 5.0) and np.all(np.abs(pitch) < 15.0)


def test_shepperd_on_real_matrices_rebuilds_them():
    """Shepperd's quaternion of each real M^T rebuilds M^T to float32 precision."""
    for record in RECORDS[::7]:
        att = np.array(attitude_ned(record.matrix)).reshape(3, 3)
        q = shepperd(tuple(att.ravel()))
        rebuilt = Rotation.from_quat(np.array(q)).as_matrix()
        assert np.abs(rebuilt - att).max() < 1e-6
