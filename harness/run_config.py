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
The settings every run on a simulated sensor shares, in one place.

The fault campaign (``campaign_verdict.py``), the long soak (``long_soak.py``) and
the node fuzz (``benchmarks/fuzz_node.py``) each have a config of their own; what they
share (the seed, the sensor's address, the node's timeouts, the fault
pacing, where progress goes) is declared here once, so that a default
changes for all of them or for none.
"""

import dataclasses
from typing import Any


@dataclasses.dataclass
class RunConfig:
    """What any run on a simulated sensor is given."""

    #: Seed of the simulator and of the fault schedule.
    seed: int = 1
    #: Node address of the sensor.
    address: int = 95
    #: Where progress lines go (None: nowhere).
    log: Any = print


@dataclasses.dataclass
class FaultedNodeConfig(RunConfig):
    """What a run that faults the node's line is given: the node's timeouts, the pacing."""

    #: The node's read_timeout (stall detection) and reconnect_interval (s).
    read_timeout: float = 0.3
    reconnect_interval: float = 0.2
    #: The node's temperature_period: 0xD1 polls interleaved with the stream (0: none).
    temperature_period: float = 1.0
    #: Seconds between fault events, drawn uniformly from this range.
    event_gap: tuple[float, float] = (1.0, 4.0)
    #: Seconds without faults at the end, in which the stream must come back.
    quiet: float = 4.0
