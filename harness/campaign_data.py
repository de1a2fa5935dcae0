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
Everything a run produced: what the checks judge.

The campaign and the long soak's legs each fill one in their own way; the
analysis (``campaign_analysis.py``) reads only this.
"""

import dataclasses

from harness.campaign_config import CampaignConfig
from harness.campaign_truth import Sent
from harness.fault_driver import FaultEvent


@dataclasses.dataclass
class RunData:
    """Everything a run produced, for the analysis."""

    cfg: CampaignConfig
    truth: list[Sent]
    truth_missed: int
    messages: list[tuple[bytes, int, bytes, float]]
    events: list[FaultEvent]
    node_stats: dict
    sim_stats: dict
    host_log: list
    rss: list[tuple[float, int]]
    warmup_end: float
    fault_end: float
    alive_at_end: bool
    exit_code: int | None
    exit_seconds: float
    recovered: int
    unsafe_garbage_bytes: int
    unsafe_garbage_bursts: int
    divider: int
    power_ups: list[float]
    node_output: str
    started: float
    #: When the node stopped reading for good, if known (a managed node's deactivate);
    #: None: its last port event, or the end of the faults.
    end: float | None = None
