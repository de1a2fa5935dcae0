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
The long soak's report: the per-leg and per-stream tables, and every check in one list.

Kept apart from the run so that the report's form (what docs/soak.md quotes)
changes here and nowhere else.
"""

import collections
import dataclasses

from harness.campaign_result import Check
from harness.soak_leg import LegResult
from harness.soak_plan import LongSoakConfig
from i3dmgx2_driver.codec.data_rate import divider_for_rate
from i3dmgx2_driver.codec.streams import STREAMS
from i3dmgx2_driver.simulator.eeprom import FACTORY_DIVIDER


@dataclasses.dataclass
class SoakRecord:
    """What the run gathered for the report: the legs run and the end's checks."""

    #: How many legs were planned.
    planned: int
    results: list[LegResult] = dataclasses.field(default_factory=list)
    #: Writes of the rate divider the simulated sensor received (None: the run broke off).
    eeprom_writes: int | None = None
    end_checks: list[Check] = dataclasses.field(default_factory=list)
    end_lines: list[str] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class LongSoakResult:
    """The verdicts and the report of one long run."""

    checks: list[Check]
    report: str

    @property
    def ok(self) -> bool:
        """Whether every check passed."""
        return bool(self.checks) and all(check.ok for check in self.checks)


def report(cfg: LongSoakConfig, run: SoakRecord, minutes: float, slope_checks: list[Check],
           slope_lines: list[str]) -> LongSoakResult:
    """Build the per-stream and overall tables and the list of checks."""
    lines = ['== i3dmgx2 long soak: every stream, every fault, both node kinds ==',
             f'{minutes:.1f} min, {len(run.results)} legs of {cfg.leg_minutes:g} min of faults '
             f'+ {cfg.quiet:g} s quiet, seed {cfg.seed}, 115200 baud, wireless; the simulator '
             f'honours the line rate']
    head = ('| leg | node | stream | rate (Hz) | sent | published | received | missing | '
            'duplicated | corrupted | faults | longest recovery (s) | node CPU (%) | result |')
    lines += ['', head, '|' + '---|' * 14]
    checks: list[Check] = []
    per_stream: dict[str, dict] = {}
    for r in run.results:
        f = r.figures
        worst = max((g for _, g, _ in r.recoveries if g is not None), default=0.0)
        ok = all(c.ok for c in r.checks)
        lines.append(f'| {r.leg.number} | {r.leg.kind} | {r.leg.stream} | {r.leg.rate_hz:g} | '
                     f'{f.get("sent")} | {f.get("published")} | {f.get("received")} | '
                     f'{f.get("missing")} | {f.get("duplicated")} | {f.get("corrupted")} | '
                     f'{f.get("events")} | {worst:.3f} | {r.cpu_percent:.1f} | '
                     f'{"PASS" if ok else "FAIL"} |')
        for c in r.checks:
            checks.append(Check(f'leg {r.leg.number} ({r.leg.kind} {r.leg.stream}): {c.name}',
                                c.ok, c.detail))
        s = per_stream.setdefault(r.leg.stream, collections_counter())
        for name in ('sent', 'published', 'received', 'missing', 'duplicated', 'corrupted',
                     'events'):
            s[name] += f.get(name) or 0
        s['legs'] += 1
        s['seconds'] += r.seconds
        s['cpu'] += r.cpu_percent * r.seconds
        s['worst'] = max(s['worst'], worst)
        recovery_kinds = s.setdefault('by_kind', {})
        for kind, gap, _ in r.recoveries:
            if gap is not None:
                recovery_kinds[kind] = max(recovery_kinds.get(kind, 0.0), gap)
    lines += ['', '| stream | legs | sent | published | received | missing | duplicated | '
              'corrupted | faults | longest recovery (s) | node CPU (%) |', '|' + '---|' * 11]
    total = collections_counter()
    for stream in STREAMS:
        s = per_stream.get(stream.name)
        if s is None:
            continue
        cpu = s['cpu'] / s['seconds'] if s['seconds'] else 0.0
        lines.append(f'| {stream.name} | {s["legs"]} | {s["sent"]} | {s["published"]} | '
                     f'{s["received"]} | {s["missing"]} | {s["duplicated"]} | '
                     f'{s["corrupted"]} | {s["events"]} | {s["worst"]:.3f} | {cpu:.1f} |')
        for name in ('legs', 'sent', 'published', 'received', 'missing', 'duplicated',
                     'corrupted', 'events'):
            total[name] += s[name]
        total['worst'] = max(total['worst'], s['worst'])
    lines.append(f'| **all** | {total["legs"]} | {total["sent"]} | {total["published"]} | '
                 f'{total["received"]} | {total["missing"]} | {total["duplicated"]} | '
                 f'{total["corrupted"]} | {total["events"]} | {total["worst"]:.3f} | |')
    kinds: dict[str, float] = {}
    for s in per_stream.values():
        for kind, gap in s.get('by_kind', {}).items():
            kinds[kind] = max(kinds.get(kind, 0.0), gap)
    lines.append('')
    lines.append('longest wait for data after the end of each kind of fault: '
                 + ', '.join(f'{k} {v:.3f} s' for k, v in sorted(kinds.items())))
    expected = eeprom_changes(run.results)
    lines.append(f'EEPROM writes the simulated sensor received: {run.eeprom_writes} (one per '
                 f'change of the divider between legs: {expected})')
    if run.eeprom_writes is not None:
        checks.append(Check('EEPROM written once per change of setting, never otherwise',
                            run.eeprom_writes == expected,
                            f'{run.eeprom_writes} writes of 0xFCA2 received, {expected} changes '
                            f'of data_rate from leg to leg (factory divider {FACTORY_DIVIDER})'))
    lines += ['', *slope_lines, *run.end_lines]
    checks += slope_checks + run.end_checks
    legs_planned = run.planned
    checks.append(Check('every leg ran', len(run.results) == legs_planned,
                        f'{len(run.results)} of {legs_planned} legs'))
    failed = [c for c in checks if not c.ok]
    lines.append('')
    lines.append('Checks failed:' if failed else f'All {len(checks)} checks passed.')
    for c in failed:
        lines.append(f'  FAIL {c.name}: {c.detail}')
    lines.append('')
    lines.append('RESULT: ' + ('PASS' if not failed else f'FAIL ({len(failed)} checks)'))
    return LongSoakResult(checks, '\n'.join(lines))


def eeprom_changes(results: list[LegResult]) -> int:
    """Return how many legs asked for another divider than the sensor had."""
    changes, divider = 0, FACTORY_DIVIDER
    for r in results:
        wanted = divider_for_rate(r.leg.rate_hz)
        changes += wanted != divider
        divider = wanted
    return changes


def collections_counter() -> dict:
    """Return a per-stream accumulator."""
    return collections.defaultdict(int)
