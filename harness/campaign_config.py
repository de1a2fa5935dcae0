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
The campaign's settings: how long, how fast and how rough.

Apart from the run and the checks, since both read them (and the fault
driver, and the long soak's legs, which build one for their faults).
"""

import dataclasses

from harness.run_config import FaultedNodeConfig


@dataclasses.dataclass
class CampaignConfig(FaultedNodeConfig):
    """
    How long, how fast and how rough the campaign is.

    The seed, address, node timeouts, fault pacing and log: ``FaultedNodeConfig``.
    """

    #: Length of the fault phase (min); a quiet phase follows.
    minutes: float = 10.0
    #: Calculation rate the simulator streams at (its rate_hz override: beyond the device);
    #: None: the rate the node sets with ``data_rate`` (EEPROM divider), at most what the
    #: line carries (the simulator skips a record the line is still busy for, as the device).
    rate_hz: float | None = 500.0
    #: The stream the node asks for, and its data_rate parameter (0: leave the device's).
    stream: str = 'full'
    data_rate: float = 0.0
    #: Warm-up (s) before the RSS baseline: this share of the run, at least ``warmup_min``.
    warmup_fraction: float = 0.15
    warmup_min: float = 10.0
    #: Most RSS growth allowed from the end of warm-up to the end of the run.
    rss_limit: float = 0.10
    #: How long before a close or an unplug a record may still be legitimately unread (s).
    unread_margin: float = 0.5
    #: How far (s) a stamp may be from the steady offset (the median of stamp - true
    #: sample time): within ``stamp_grace`` s of the stream's start or return (a gap,
    #: or the sensor's timer restarted), ``stamp_early_tolerance``; after it,
    #: ``stamp_tolerance`` (issue #23: time stays true through every fault).
    stamp_tolerance: float = 0.001
    stamp_early_tolerance: float = 0.005
    stamp_grace: float = 0.5
    #: Include long stalls (longer than the node's stall recovery: it reopens the port).
    long_stalls: bool = True


def rate_text(cfg: CampaignConfig) -> str:
    """Say what the simulator streams and how fast, for the logs and the report."""
    if cfg.rate_hz is None:
        return (f'stream {cfg.stream!r} at data_rate {cfg.data_rate:g} Hz (the divider the '
                f'node writes; the line rate honoured)')
    return f'stream {cfg.stream!r} at {cfg.rate_hz:g} Hz (simulator rate override)'
