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
The campaign's verdict on a run: every check, in the report's order, and the report.

This only puts the pieces together, each in its own room: the node's health
(``campaign_health.py``), what was published against the truth
(``campaign_match.py``), the stamps (``campaign_stamps.py``), the counters
(``campaign_counters.py``) and the report (``campaign_report.py``), all
judged against when the node could read the port (``read_windows.py``).
"""

from harness.campaign_counters import counter_checks, counter_rows
from harness.campaign_data import RunData
from harness.campaign_health import health_checks
from harness.campaign_match import coverage, match, published_checks
from harness.campaign_report import report
from harness.campaign_result import CampaignResult, verdict
from harness.campaign_stamps import stamp_verdict
from harness.read_windows import Windows
from i3dmgx2_driver.codec.streams import parse as parse_stream


def windows_of(data: RunData) -> Windows:
    """Return when the node read the port, until its deactivate, last port event or faults' end."""
    node = data.node_stats or {}
    end = data.end if data.end is not None else max(
        [e[1] for e in node.get('port_events', [])] + [data.fault_end])
    unplugs = [e.start for e in data.events if e.kind == 'unplug']
    return Windows(node.get('port_events', []), unplugs, end, data.cfg.unread_margin)


def analyse(data: RunData, exempt: tuple[str, ...] = ()) -> CampaignResult:
    """
    Match what was published with the truth; reconcile the counters; judge.

    ``exempt`` names checks that do not apply to this run (a managed node's
    leg: the node lives on, and counts what it reads while inactive as
    unpublished): they are left out of the checks and of the report.
    """
    cfg = data.cfg
    nstats = (data.node_stats or {}).get('stats', {})
    windows = windows_of(data)
    matching = match(data.truth, data.messages, cfg.address)
    cover = coverage(data, windows, matching.seen, parse_stream(cfg.stream).code)
    rows = counter_rows(data, windows, matching)
    checks = [*health_checks(data),
              *published_checks(data, matching, cover),
              verdict('stamps true through every fault', *stamp_verdict(matching.matched, cfg)),
              *counter_checks(rows, nstats)]
    checks = [c for c in checks if c.name not in exempt]
    figures = {
        'sent': cover.sent,
        'must': len(cover.must), 'published': nstats.get('published'),
        'received': len(data.messages), 'missing': len(cover.missing),
        'duplicated': len(matching.duplicates),
        'corrupted': matching.invalid + matching.unknown,
        'lost_counted': nstats.get('lost'), 'events': len(data.events)}
    return CampaignResult(checks, report(data, cover, windows, rows, checks), figures)
