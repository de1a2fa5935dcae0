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

Same code (benchmarks/campaign.py), same checks: the real node process on a
simulated base station that injects every fault at random, a real rclpy
subscriber, every message matched to the ground truth, counters reconciled.
Shorter, slower (200 Hz) and with faults closer together than the ten-minute
run.
"""

from benchmarks.campaign import CampaignConfig, run_campaign
import pytest


@pytest.mark.slow
def test_soak_short():
    cfg = CampaignConfig(minutes=0.4, rate_hz=200.0, seed=5, event_gap=(0.5, 2.0),
                         warmup_min=6.0, quiet=4.0, log=None)
    result = run_campaign(cfg)
    assert result.ok, result.report
