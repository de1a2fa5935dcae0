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
The judgements behind the services and the raw capture's failure handling, no node.

Whether a gyro bias capture is trusted, whether gravity and the rate pass
the self test, and that a raw capture that cannot write turns itself off
with one log line instead of taking the driver down.
"""

import os

from i3dmgx2_driver.capture import read_capture
from i3dmgx2_driver.ros.raw_capture import RawCapture
from i3dmgx2_driver.ros.services import (
    format_report, gravity_step, judge_capture, MAX_GYRO_BIAS, rate_step, Step,
)
import pytest

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


class Log:
    """Collects log lines the way the node's logger would print them."""

    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(('info', text))

    def error(self, text):
        self.lines.append(('error', text))


def test_raw_capture_writes_reads_as_read(tmp_path):
    path = tmp_path / 'raw.gx2'
    log = Log()
    capture = RawCapture(str(path), log, port='/dev/ttyUSB0', address=95, baud=115200,
                         wireless=True)
    assert capture.active
    capture.on_bytes(b'\xaa\x07\x00', 100.0)
    capture.on_bytes(b'\x00\x5f', 100.5)
    assert '2 reads, 5 bytes' in capture.describe()
    capture.close()
    header, chunks = read_capture(path)
    assert (header['port'], header['address'], header['baud'], header['wireless']) == \
        ('/dev/ttyUSB0', 95, 115200, True)
    assert header['driver_version'] and header['start_time'] > 0
    assert list(chunks) == [(100.0, b'\xaa\x07\x00'), (100.5, b'\x00\x5f')]
    assert not any(level == 'error' for level, _ in log.lines)


def test_raw_capture_that_cannot_open_is_off_and_said_once(tmp_path):
    log = Log()
    capture = RawCapture(str(tmp_path / 'no' / 'such' / 'dir.gx2'), log)
    assert not capture.active
    capture.on_bytes(b'abc', 1.0)
    capture.close()
    errors = [text for level, text in log.lines if level == 'error']
    assert len(errors) == 1 and 'keeps running' in errors[0]
    assert capture.describe().startswith('stopped:')


@pytest.mark.skipif(not os.path.exists('/dev/full'), reason='needs /dev/full')
def test_raw_capture_on_a_full_disk_is_off_and_said_once():
    log = Log()
    capture = RawCapture('/dev/full', log)
    for _ in range(3):
        capture.on_bytes(b'x' * 100_000, 1.0)
    capture.close()
    errors = [text for level, text in log.lines if level == 'error']
    assert len(errors) == 1, log.lines
    assert 'No space left' in errors[0]


def test_raw_capture_failing_mid_stream_stops_once(tmp_path):
    log = Log()
    capture = RawCapture(str(tmp_path / 'raw.gx2'), log)
    capture.on_bytes(b'good', 1.0)
    capture._writer.error = OSError(27, 'File too large')  # as the flusher thread keeps it
    for _ in range(5):
        capture.on_bytes(b'more', 2.0)
    capture.close()
    errors = [text for level, text in log.lines if level == 'error']
    assert len(errors) == 1 and 'File too large' in errors[0]
    assert not capture.active
