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
The soak and fault campaign of benchmarks/soak.py, short: about 40 s in CI.

Same code (harness/campaign.py), same checks: the real node process on a
simulated base station that injects every fault at random, a real rclpy
subscriber, every message matched to the ground truth, counters reconciled.
Shorter, slower (200 Hz) and with faults closer together than the ten-minute
run. The analysis itself is checked first, on synthetic runs with known bugs.
"""

import struct

from harness.campaign import VALUES
from harness.campaign_verdict import analyse, CampaignConfig, RunData, Sent
from harness.long_soak import run_campaign
import pytest


@pytest.mark.slow
@pytest.mark.alone
def test_soak_short():
    cfg = CampaignConfig(minutes=0.3, rate_hz=200.0, seed=5, event_gap=(0.3, 1.0),
                         warmup_min=6.0, quiet=4.0, log=None)
    result = run_campaign(cfg)
    assert result.ok, result.report


def _synthetic_run(published_indices: list[int], extra: list[bytes] = ()) -> RunData:
    """Build a clean 100-record run on one connection that publishes the records named."""
    rate = 100.0
    truth = []
    for i in range(100):
        t = 10.0 + i / rate
        key = VALUES.pack(0.001 * i, 0.0, -1.0, 0.0, 0.002 * i, 0.0)
        truth.append(Sent(i, t + 0.002, True, None, 95, 'stream', key, None,
                          struct.pack('<4d', 0.0, 0.0, 0.0, 1.0), 196608 * i, t, 1, 88))
    messages = [(truth[i].key, round(truth[i].sample_time * 1e9), truth[i].quat, 0.0)
                for i in published_indices]
    messages += [(key, 0, b'', 0.0) for key in extra]
    parser = {'acks': 0, 'nacks': 0, 'bytes_in': 8800, 'bytes_skipped': 0,
              'checksum_failures': 0, 'length_failures': 0, 'foreign_frames': 0,
              'good_frames': 100}
    node = {'final': True, 'parser': parser,
            'stats': {'published': len(messages), 'lost': 0, 'device_resets': 0,
                      'unpublished': 0},
            'supervisor': {'connections': 1},
            'port_events': [('open', 9.0, 1), ('flush', 9.1, 1), ('flush', 9.2, 1),
                            ('anchor', 9.2, 1), ('close', 12.0, 1)]}
    return RunData(
        cfg=CampaignConfig(log=None), truth=truth, truth_missed=0, messages=messages,
        events=[], node_stats=node, sim_stats={'bytes_written': 8800, 'nacks': 0},
        host_log=[], rss=[(t, 1000) for t in range(30)], warmup_end=0.0, fault_end=11.0,
        alive_at_end=True, exit_code=0, exit_seconds=0.1, recovered=1,
        unsafe_garbage_bytes=0, unsafe_garbage_bursts=0, divider=512, power_ups=[],
        node_output='', started=9.0)


def _failed(data: RunData) -> set[str]:
    return {check.name for check in analyse(data).failures()}


def test_campaign_analysis_passes_a_clean_run():
    assert _failed(_synthetic_run(list(range(100)))) == set()


def test_campaign_analysis_catches_a_record_published_twice():
    assert 'no record published twice' in _failed(_synthetic_run([*range(100), 42]))


def test_campaign_analysis_catches_a_record_lost():
    published = [i for i in range(100) if i != 42]
    assert 'every valid record read by the node published' in _failed(
        _synthetic_run(published))


def test_campaign_analysis_catches_a_record_never_sent():
    bogus = VALUES.pack(1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    assert 'every message is a record the sensor sent' in _failed(
        _synthetic_run(list(range(100)), [bogus]))


def test_campaign_analysis_catches_reordering():
    published = [*range(50), 51, 50, *range(52, 100)]
    assert 'published in the order sent' in _failed(_synthetic_run(published))


def test_campaign_analysis_catches_a_corrupted_record_published():
    data = _synthetic_run(list(range(100)))
    data.truth[42] = data.truth[42]._replace(valid=False, fault='checksum')
    assert 'no corrupted, foreign or unwritten record published' in _failed(data)


def test_campaign_analysis_catches_stamps_that_run_slow_after_a_fault():
    """The issue #23 symptom: stamps 8 % slow from record 50 on, 40 ms behind at the end."""
    data = _synthetic_run(list(range(100)))
    data.messages[:] = [(key, stamp - round(max(0, i - 50) * 0.0008 * 1e9), quat, t)
                        for i, (key, stamp, quat, t) in enumerate(data.messages)]
    assert _failed(data) == {'stamps true through every fault'}
