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

"""Unknown parameter names: which are unknown, and the closest real name."""

from i3dmgx2_driver.ros.parameters import SPECS
from i3dmgx2_driver.ros.unknown_parameters import message, unknown_names

KNOWN = [spec.name for spec in SPECS] + ['use_sim_time', 'start_type_description_service']


def test_typos_get_the_closest_real_name():
    given = ['adress', 'data_rat', 'prot', 'wirless', 'frame', 'port', 'use_sim_time']
    assert unknown_names(given, KNOWN) == [
        ('adress', 'address'), ('data_rat', 'data_rate'), ('frame', 'frame_id'),
        ('prot', 'port'), ('wirless', 'wireless')]


def test_a_name_like_none_gets_no_suggestion():
    assert unknown_names(['qos_overrides./imu.publisher.depth', 'xyz'], KNOWN) == [
        ('qos_overrides./imu.publisher.depth', None), ('xyz', None)]


def test_declared_names_are_never_reported():
    assert unknown_names(KNOWN, KNOWN) == []


def test_the_message_names_both():
    assert message('data_rat', 'data_rate') == (
        "unknown parameter 'data_rat' (did you mean 'data_rate'?): ignored, the driver has "
        'no such parameter (ros2 param list shows those it has)')
    assert message('xyz', None).startswith("unknown parameter 'xyz': ignored")
