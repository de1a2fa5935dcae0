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
Whether the node came through the run whole: alive, a clean exit, data back, memory flat.

The RSS baseline is taken at the end of the warm-up (the run's
``warmup_end``), not at the start: the node's first seconds fill its
buffers and caches, and only growth after that means a leak.
"""

import statistics

from harness.campaign_data import RunData
from harness.campaign_result import Check, verdict


def health_checks(data: RunData) -> list[Check]:
    """Judge the node's life through the run, its memory, and the truth's completeness."""
    cfg = data.cfg
    return [
        verdict('node alive at the end', data.alive_at_end,
                'the node process ran through every fault' if data.alive_at_end
                else 'the node process died:\n' + data.node_output[-3000:]),
        verdict('clean exit on SIGINT', data.exit_code == 0,
                f'exit code {data.exit_code} after {data.exit_seconds:.2f} s'),
        verdict('stream recovered after the faults', data.recovered > 0,
                f'{data.recovered} messages in the {cfg.quiet:g} s quiet phase'),
        rss_check(data.rss, data.warmup_end, cfg.rss_limit),
        verdict('ground truth complete', data.truth_missed == 0,
                f'{len(data.truth)} truth entries, {data.truth_missed} missed by the collector')]


def rss_check(rss: list[tuple[float, int]], warmup_end: float, limit: float) -> Check:
    """Compare the median RSS of the 10 s after warm-up with that of the last 10 samples."""
    base = [kib for t, kib in rss if warmup_end <= t <= warmup_end + 10.0]
    tail = [kib for _, kib in rss[-10:]]
    if not (base and tail):
        return verdict('RSS growth after warm-up', False, 'not enough RSS samples')
    b, e = statistics.median(base), statistics.median(tail)
    growth = e / b - 1.0
    peak = max(kib for _, kib in rss)
    return verdict('RSS growth after warm-up', growth <= limit,
                   f'{b / 1024:.1f} MiB after warm-up -> {e / 1024:.1f} MiB at the end '
                   f'({growth * 100:+.1f} %, limit {limit * 100:.0f} %); peak '
                   f'{peak / 1024:.1f} MiB; {len(rss)} samples')
