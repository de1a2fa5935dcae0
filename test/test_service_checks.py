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
The judgements behind the services, no node.

Whether a gyro bias capture is trusted, and whether gravity and the rate
pass the self test.
"""

from i3dmgx2_driver.device.gyro_bias import judge_capture, MAX_GYRO_BIAS
from i3dmgx2_driver.device.self_test import format_report, gravity_step, rate_step, Step

BIAS = (-0.0033, -0.0217, -0.0052)
DOWN = (0.0, 0.0, -1.0)


def test_still_capture_is_accepted():
    assert judge_capture(BIAS, DOWN, (0.0005, -0.0003, -1.0002), (0.001, -0.0008, 0.0)) == []


def test_each_sign_of_motion_refuses_on_its_own():
    big = judge_capture((0.12, 0.0, 0.05), DOWN, DOWN, (0.0, 0.0, 0.0))
    assert len(big) == 1 and 'captured bias' in big[0]
    tilted = judge_capture(BIAS, DOWN, (0.1, 0.0, -0.995), (0.0, 0.0, 0.0))
    assert len(tilted) == 1 and 'gravity vector changed' in tilted[0]
    turning = judge_capture(BIAS, DOWN, DOWN, (0.05, 0.0, 0.0))
    assert len(turning) == 1 and 'angular rate after' in turning[0]
    nan = judge_capture((float('nan'), 0.0, 0.0), DOWN, DOWN, (0.0, 0.0, 0.0))
    assert len(nan) == 1
    assert max(abs(b) for b in BIAS) * 2 < MAX_GYRO_BIAS  # real biases pass comfortably


def test_gravity_step():
    assert gravity_step((0.0, 0.0, -1.0)).passed
    assert gravity_step((0.6, 0.0, -0.8)).passed          # tilted, still 1 g
    assert not gravity_step((0.0, 0.0, -1.2)).passed
    assert not gravity_step((0.0, 0.0, 0.0)).passed
    assert '1.0000 g' in gravity_step((0.0, 0.0, -1.0)).detail


def test_rate_step():
    assert rate_step(99.0, 100.0).passed
    assert not rate_step(80.0, 100.0).passed
    assert not rate_step(None, 100.0).passed
    assert not rate_step(100.0, None).passed
    assert '80.00 Hz measured' in rate_step(80.0, 100.0).detail


def test_report_has_one_line_per_step_and_a_summary():
    report = format_report([Step('a', True, 'fine'), Step('b', False, 'broken')])
    assert report.splitlines() == ['PASS a: fine', 'FAIL b: broken',
                                   'self test FAILED: 1/2 steps passed']
    assert format_report([Step('a', True, 'x')]).endswith('self test passed: 1/1 steps passed')
