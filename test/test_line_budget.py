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
The line budget and the stream table, by arithmetic alone (no ROS, no port).

Sizes are checked against docs/protocol.md §6's table (wired replies; a wireless
packet is the wired reply less its 2-byte checksum, plus the 7-byte header
and the 4-byte trailer), and every limit is checked to be the highest
divider rate that fits: the next divider up does not.
"""

import math

from i3dmgx2_driver.codec import data_rate, line_budget, streams
import pytest

# docs/protocol.md §6: wired reply bytes of each streamed record.
WIRED = {0xCC: 79, 0xC8: 67, 0xCB: 43, 0xC2: 31, 0xCF: 31, 0xD2: 43}


@pytest.mark.parametrize('code', sorted(WIRED))
def test_packet_sizes_follow_the_protocol(code):
    assert line_budget.packet_size(code, wireless=False) == WIRED[code]
    assert line_budget.packet_size(code, wireless=True) == WIRED[code] - 2 + 7 + 4


def test_the_0xcc_packet_is_88_bytes_and_its_wire_time():
    assert line_budget.packet_size(0xCC, True) == 88
    assert line_budget.wire_time(0xCC, 115200, True) == pytest.approx(88 * 10 / 115200)
    assert line_budget.wire_time(0xC2, 115200, False) == pytest.approx(31 * 10 / 115200)


def test_a_record_without_a_reply_has_no_packet():
    with pytest.raises(ValueError, match='0xFA has no reply record'):
        line_budget.packet_size(0xFA, True)


@pytest.mark.parametrize('stream', streams.STREAMS, ids=lambda s: s.name)
@pytest.mark.parametrize('wireless', [True, False])
@pytest.mark.parametrize('baud', [9600, 57600, 115200, 230400, 921600])
def test_max_rate_is_the_highest_divider_rate_that_fits(stream, wireless, baud):
    limit = line_budget.max_rate(stream.code, baud, wireless)
    usable = baud / 10 * 0.95
    size = line_budget.packet_size(stream.code, wireless)
    assert limit is not None
    divider = round(data_rate.RATE_BASE_HZ / limit)
    assert data_rate.rate_of_divider(divider) == limit
    assert size * limit <= usable
    assert line_budget.shared_fits([(stream.code, limit)], baud, wireless)
    if divider > data_rate.MIN_DIVIDER:
        faster = data_rate.rate_of_divider(divider - 1)
        assert size * faster > usable
        assert not line_budget.shared_fits([(stream.code, faster)], baud, wireless)


@pytest.mark.parametrize('name, wireless, limit', [
    ('full', True, 51200 / 412), ('inertial_orientation', True, 51200 / 356),
    ('inertial_mag', True, 51200 / 244), ('inertial', True, 51200 / 188),
    ('euler', True, 51200 / 188), ('stabilised', True, 51200 / 244),
    ('full', False, 51200 / 370), ('inertial', False, 51200 / 170),
])
def test_limits_at_115200_baud(name, wireless, limit):
    assert line_budget.max_rate(streams.BY_NAME[name].code, 115200, wireless) == limit


def test_not_even_1_hz_fits_a_tiny_line():
    assert line_budget.max_rate(0xCC, 300, True) is None
    budget = streams.line_budget(streams.DEFAULT, 1.0, 300, True)
    assert not budget.fits
    assert 'no data rate fits' in streams.advice(streams.DEFAULT, budget)


def test_budget_numbers():
    b = streams.line_budget(streams.DEFAULT, 100.0, 115200, True)
    assert (b.packet_bytes, b.needed, b.capacity, b.usable) == (88, 8800.0, 11520.0, 10944.0)
    assert b.fits and b.share == pytest.approx(8800 / 11520)
    assert streams.describe(b) == \
        '0xCC at 100 Hz: 88 B packets, 8,800 of 11,520 bytes/s (76% of the line)'


def test_the_rate_is_the_one_the_device_runs_at():
    """300 Hz asked is divider 171: 299.4 Hz, and that is what the budget weighs."""
    b = streams.line_budget(streams.DEFAULT, 300.0, 115200, True)
    assert b.rate_hz == 51200 / 171
    assert b.needed == pytest.approx(88 * 51200 / 171)


def test_the_refusal_says_what_fits():
    b = streams.line_budget(streams.DEFAULT, 300.0, 115200, True)
    assert not b.fits
    assert streams.advice(streams.DEFAULT, b) == (
        '0xCC (full) at 299.4 Hz needs 26,349 bytes/s; 115200 baud carries 11,520 (10,944 '
        "with the 5% margin kept free): choose data_rate \u2264 124 Hz, or stream 'inertial' "
        "(\u2264 272 Hz), 'euler' (\u2264 272 Hz)")


def test_advised_rates_fit_when_typed_as_data_rate():
    """The limits shown are rounded down, so typing one back always fits."""
    for stream in streams.STREAMS:
        for wireless in (True, False):
            limit = line_budget.max_rate(stream.code, 115200, wireless)
            typed = math.floor(limit)
            assert streams.line_budget(stream, typed, 115200, wireless).fits


def test_streams_read_their_contents_from_the_layouts():
    contents = {s.name: (s.accel, s.angular_rate, s.mag, s.orientation)
                for s in streams.STREAMS}
    assert contents == {
        'full': ('accel', 'angular_rate', 'mag', streams.MATRIX),
        'inertial_orientation': ('accel', 'angular_rate', None, streams.MATRIX),
        'inertial_mag': ('accel', 'angular_rate', 'mag', None),
        'inertial': ('accel', 'angular_rate', None, None),
        'euler': (None, 'angular_rate', None, streams.EULER),
        'stabilised': ('accel', 'angular_rate', 'mag', None),
    }
    assert streams.DEFAULT.code == 0xCC
    assert {s.code for s in streams.STREAMS} == set(WIRED)


@pytest.mark.parametrize('text, code', [
    ('full', 0xCC), ('inertial', 0xC2), (' Euler ', 0xCF), ('0xC2', 0xC2), ('0xc2', 0xC2),
    ('C8', 0xC8), ('0xCB', 0xCB), ('0xD2', 0xD2), ('stabilised', 0xD2),
])
def test_parse_names_and_command_bytes(text, code):
    assert streams.parse(text).code == code


@pytest.mark.parametrize('text', ['', 'fast', '0xC5', '0xCCC', '204', 'x'])
def test_parse_refuses_what_is_not_offered(text):
    with pytest.raises(ValueError, match="one of 'full', 'inertial_orientation'"):
        streams.parse(text)


def test_divider_arithmetic():
    assert data_rate.divider_for_rate(100.0) == 512
    assert data_rate.divider_for_rate(300.0) == 171
    assert data_rate.divider_for_rate(1000.0) == data_rate.MIN_DIVIDER
    assert data_rate.divider_for_rate(0.5) == data_rate.MAX_DIVIDER
    assert data_rate.ticks_per_cycle(512) == 384 * 512
    assert data_rate.TICKS_PER_DIVIDER * data_rate.RATE_BASE_HZ == 19_660_800
