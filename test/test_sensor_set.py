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
Which sensors the parameters ask for, their names, frames and streams, and their budget.

Pure functions, no node: every rule of ros/sensor_set.py and its message,
and the README's table of what N sensors fit on the line, against the code.
"""

import math
import os
import re

from harness.processes import REPO
from i3dmgx2_driver.codec import line_budget, streams
from i3dmgx2_driver.ros.sensor_set import sensor_settings, shared_budget_refusal
import pytest


#: The parameters as a node without a parameters file gives them.
DEFAULTS = {'address': 0, 'addresses': (), 'names': (), 'frame_ids': (), 'stream_texts': (),
            'rates': (), 'frame_id': 'imu_link', 'stream': 'full', 'data_rate': 0.0,
            'wireless': True}
#: The node's own names of the three above that are shorter here.
NODE_NAMES = {'names': 'sensor_names', 'stream_texts': 'streams', 'rates': 'data_rates'}


def settings(**given):
    unknown = given.keys() - DEFAULTS.keys()
    assert not unknown, f'no such parameter: {sorted(unknown)}'
    values = {NODE_NAMES.get(name, name): value for name, value in {**DEFAULTS, **given}.items()}
    return sensor_settings(values)


def test_one_sensor_is_named_imu_as_always():
    [one] = settings(address=95)
    assert (one.address, one.name, one.frame_id, one.stream) == (95, 'imu', 'imu_link', 'full')


def test_several_sensors_get_names_frames_and_their_own_streams():
    first, second = settings(addresses=(17, 95))
    assert (first.name, first.frame_id, second.name, second.frame_id) == \
        ('imu_17', 'imu_17_link', 'imu_95', 'imu_95_link')
    left, right = settings(addresses=(17, 95), names=('left_arm', 'right_arm'),
                           stream_texts=('full', '0xC2'), rates=(50.0, 100.0))
    assert (left.name, left.frame_id, left.stream_choice.name, left.data_rate) == \
        ('left_arm', 'left_arm_link', 'full', 50.0)
    assert (right.stream_choice.name, right.data_rate) == ('inertial', 100.0)
    both = settings(addresses=(17, 95), stream_texts=('inertial',), rates=(80.0,),
                    frame_ids=('a', 'b'))
    assert [(s.stream, s.data_rate, s.frame_id) for s in both] == \
        [('inertial', 80.0, 'a'), ('inertial', 80.0, 'b')]


@pytest.mark.parametrize('given, words', [
    ({'address': 95, 'addresses': (17, 95)}, "'address' (95) and 'addresses'"),
    ({'addresses': (17, 17)}, 'must not list a sensor twice'),
    ({'addresses': (17, 0)}, 'node addresses 1..65534, got 0'),
    ({'addresses': (17, 95), 'names': ('a',)}, "'sensor_names' must give one name per sensor"),
    ({'addresses': (17, 95), 'names': ('a', 'a')}, 'must not name two sensors alike'),
    ({'addresses': (17, 95), 'names': ('a', '9b')}, "starting with a letter, got '9b'"),
    ({'addresses': (17, 95), 'frame_ids': ('f', 'f')}, "'frame_ids' must name each"),
    ({'addresses': (17, 95, 3), 'stream_texts': ('full', 'full')}, '(or one for all)'),
    ({'addresses': (17, 95), 'stream_texts': ('nope',)}, "'streams' must hold one of"),
    ({'addresses': (17, 95), 'rates': (500.0,)}, "'data_rates' must hold 0"),
    ({'addresses': (17, 95), 'wireless': False}, "'wireless' is false"),
])
def test_bad_combinations_name_the_parameter(given, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        settings(**given)


def test_the_budget_counts_every_sensor_and_says_what_fits_per_sensor():
    assert shared_budget_refusal(
        settings(addresses=(17, 95), stream='inertial', data_rate=136.0), 115200, True) is None
    assert shared_budget_refusal(settings(addresses=(17, 95), data_rate=0.0), 115200,
                                 True) is None
    text = shared_budget_refusal(settings(addresses=(17, 95), stream='inertial', data_rate=140.0),
                                 115200, True)
    assert '2 sensors need 11,' in text and '10,944 with the 5% margin' in text
    assert "2 x 'inertial' at \u2264 136 Hz" in text and "2 x 'full' at \u2264 62 Hz" in text
    assert 'these streams at \u2264 ' in shared_budget_refusal(
        settings(addresses=(17, 95), stream_texts=('full', 'inertial'), data_rate=100.0),
        115200, True)


def test_the_readme_table_of_shared_rates_is_the_codes():
    with open(os.path.join(REPO, 'README.md')) as handle:
        readme = handle.read()
    for stream in streams.STREAMS:
        rates = [math.floor(line_budget.max_shared_rate([stream.code] * n, 115200, True))
                 for n in (1, 2, 3, 4)]
        row = (f'| `{stream.name}` | {line_budget.packet_size(stream.code, True)} | '
               + ' | '.join(f'{rate} Hz' for rate in rates) + ' |')
        assert row in readme, row


def test_packets_of_unlisted_addresses_are_named_on_diagnostics():
    from i3dmgx2_driver.ros.diagnostic_statuses import parser_status
    status = parser_status({'foreign_frames': 12}, {'foreign_frames': 2}, {40: 10, 3: 2})
    assert status.message == '10 frames from other sensors ignored (node 3: 2, node 40: 10)'
    assert status.value('packets of unlisted addresses') == 'node 3: 2, node 40: 10'
    assert parser_status({}, None).value('packets of unlisted addresses') is None


def test_rates_found_on_the_devices_are_checked_together_on_the_shared_port():
    from i3dmgx2_driver.codec import layouts
    from i3dmgx2_driver.device.settings import DeviceConfig
    from i3dmgx2_driver.device.shared_port import SharedPort

    class Log:
        def __init__(self) -> None:
            self.warnings: list[str] = []

        def warning(self, text: str) -> None:
            self.warnings.append(text)

    log = Log()
    shared = SharedPort(DeviceConfig(port='/dev/null', address=17), log)
    full = layouts.ACCEL_ANG_RATE_MAG_ORIENTATION
    assert shared.line_warning(17, full, 100.0) == ''  # one sensor: its own check
    text = shared.line_warning(95, full, 100.0)
    assert text.startswith('the sensors on this port are set to rates the line cannot carry')
    assert "2 x 'full' at \u2264 62 Hz" in text
    assert shared.line_warning(17, full, 100.0) == text and len(log.warnings) == 1
    shared.line_warning(95, full, 50.0)
    assert shared.line_warning(17, full, 50.0) == ''
