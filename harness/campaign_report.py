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
The campaign's printable report: what ran, what the node counted, the rules, the verdicts.

The reconciliation rules are stated in the report itself, beside the bounds
they give, so that a reader of a failed run need not open the code.
"""

import collections

from harness.campaign_config import rate_text
from harness.campaign_counters import CounterRow
from harness.campaign_data import RunData
from harness.campaign_match import Coverage
from harness.campaign_result import Check
from harness.read_windows import Windows


def report(data: RunData, cover: Coverage, windows: Windows, rows: list[CounterRow],
           checks: list[Check]) -> str:
    """Return the whole report, ending in its RESULT line."""
    lines = run_lines(data, cover)
    lines.append('')
    lines += rule_lines(data, windows, rows)
    lines.append('')
    lines += check_lines(checks)
    return '\n'.join(lines)


def run_lines(data: RunData, cover: Coverage) -> list[str]:
    """Say what ran, the faults, and what the node, its parser and the simulator counted."""
    cfg = data.cfg
    node = data.node_stats or {}
    nstats = node.get('stats', {})
    sup = node.get('supervisor', {})
    kinds = collections.Counter(e.kind for e in data.events)
    lines = ['== i3dmgx2 soak and fault campaign ==']
    lines.append(f'fault phase {cfg.minutes:g} min at {rate_text(cfg)}, seed {cfg.seed}, '
                 f'node read_timeout {cfg.read_timeout:g} s, reconnect_interval '
                 f'{cfg.reconnect_interval:g} s, temperature_period '
                 f'{cfg.temperature_period:g} s, then {cfg.quiet:g} s quiet')
    lines.append('fault events: ' + ', '.join(f'{k} {n}' for k, n in sorted(kinds.items())))
    for event in data.events:
        if 'power' in event.detail or event.kind == 'power_cycle':
            lines.append(f'  {event.start - data.started:7.2f} s {event.kind}: {event.detail}')
    lines.append(f'node: {sup.get("connections")} connections ({sup.get("reconnects")} '
                 f'reconnects), {sup.get("stalls")} stalls, published {nstats.get("published")}, '
                 f'lost {nstats.get("lost")}, device resets {nstats.get("device_resets")}, '
                 f'other records {nstats.get("other_records")}')
    parser = node.get('parser', {})
    lines.append('parser: ' + ', '.join(f'{k} {v}' for k, v in sorted(parser.items())))
    sim = data.sim_stats
    lines.append('simulator: ' + ', '.join(f'{k} {v}' for k, v in sorted(sim.items()) if v))
    lines.append(f'unsafe garbage (with 0xAA/0x21/0x02/0x07): {data.unsafe_garbage_bursts} '
                 f'bursts, {data.unsafe_garbage_bytes} bytes')
    lines.append(f'valid 0x{cover.code:02X} records from address {cfg.address}: '
                 f'{len(cover.must)} written '
                 f'while the node read (must be published once), {len(cover.may)} written when '
                 f'it may not have (unplugged, flushed at a (re)open, just before a close: '
                 f'{cover.may_published} of them published, at most once each)')
    return lines


def rule_lines(data: RunData, windows: Windows, rows: list[CounterRow]) -> list[str]:
    """State what "read" and "written" mean, then each counter against its bounds and rule."""
    lines = ['Reconciliation rules. "Read" means written whole at least '
             f'{windows.settle * 1e3:.0f} ms after the node last started its reader afresh '
             f'on a connection (after the stop-and-flush of the full start-up, or the '
             f'flush of a reconnect to the known sensor) and at least '
             f'{data.cfg.unread_margin:g} s before the close of that connection or the next '
             f'unplug; "written" means written whole after the node '
             f'first opened the port. A record written at any other time may be lost '
             f'legitimately (unplugged, flushed by the stop-and-flush at a (re)open, '
             f'unread at a close); stalls and drops are never written.']
    for name, value, low, high, ok, rule in rows:
        lines.append(f'  {"ok  " if ok else "FAIL"} {name:18s} {value!s:>9s} in '
                     f'[{low}, {high}]  -- {rule}')
    return lines


def check_lines(checks: list[Check]) -> list[str]:
    """List the checks (the counters' are in the rules already) and the result."""
    lines = ['Checks:']
    for item in checks:
        if not item.name.startswith('counter '):
            lines.append(f'  {"PASS" if item.ok else "FAIL"} {item.name}: {item.detail}')
    failed = [c for c in checks if not c.ok]
    lines.append('')
    lines.append('RESULT: ' + ('PASS' if not failed else
                               f'FAIL ({len(failed)} checks: '
                               + ', '.join(c.name for c in failed) + ')'))
    return lines
