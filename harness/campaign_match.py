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
Each published message matched to the record it came from, by its exact values.

Here are the checks on what was published: nothing unknown, corrupted or
foreign, nothing twice, nothing the node read left out, in order, with the
orientation exact. A record is found by the values the node publishes for
it (campaign_truth.py); whether the node had to publish it comes from
when it was written (read_windows.py).
"""

import bisect
import collections
import dataclasses
import itertools

from harness.campaign_data import RunData
from harness.campaign_result import Check, verdict
from harness.campaign_truth import Sent
from harness.read_windows import Windows


@dataclasses.dataclass
class Matching:
    """The published messages against the truth."""

    #: (record, message row) of every message that matched a record, in arrival order.
    matched: list[tuple[Sent, tuple]]
    #: How often each record was published.
    seen: collections.Counter
    #: Records published more than once, and how often.
    duplicates: dict[int, int]
    #: Messages that match no record of the truth.
    unknown: int
    #: Matched records that were not valid packets from the node's address.
    invalid: int
    #: A few of the unknown and invalid ones, for the report.
    invalid_examples: list[str]


def match(truth: list[Sent], messages: list[tuple], address: int) -> Matching:
    """Match every message, by its exact values, to the first record that has them."""
    by_key: dict[bytes, Sent] = {}
    bad_keys: dict[bytes, Sent] = {}
    for sent in truth:
        if sent.key is not None:
            by_key.setdefault(sent.key, sent)
        if sent.bad_key is not None:
            bad_keys.setdefault(sent.bad_key, sent)
    seen: collections.Counter = collections.Counter()
    matched: list[tuple[Sent, tuple]] = []
    unknown = invalid = 0
    invalid_examples: list[str] = []
    for row in messages:
        sent = by_key.get(row[0])
        if sent is None:
            unknown += 1
            bad = bad_keys.get(row[0])
            if bad is not None and len(invalid_examples) < 5:
                invalid_examples.append(f'corrupted packet #{bad.index} ({bad.fault})')
            continue
        seen[sent.index] += 1
        matched.append((sent, row))
        if not (sent.valid and sent.address == address):
            invalid += 1
            if len(invalid_examples) < 5:
                invalid_examples.append(f'#{sent.index} ({sent.fault}, address '
                                        f'{sent.address}, {sent.source})')
    duplicates = {i: n for i, n in seen.items() if n > 1}
    return Matching(matched, seen, duplicates, unknown, invalid, invalid_examples)


@dataclasses.dataclass
class Coverage:
    """Which of our records the node had to publish, and which it only may have."""

    #: Written while the node read, not claimed by a polled request: published once each.
    must: list[Sent]
    #: Written when the node may not have read, or claimed: published at most once each.
    may: list[Sent]
    #: Those of ``must`` never published.
    missing: list[Sent]
    #: Those of ``may`` published.
    may_published: int
    #: Our records written at all.
    sent: int
    #: The command byte of the stream's records: ours.
    code: int


def is_ours(sent: Sent, address: int, code: int) -> bool:
    """
    Whether the node publishes this record when it reads it.

    Records of another stream (a sensor power-cycled into its EEPROM
    auto-start) are the node's to count, not to publish.
    """
    return sent.key is not None and sent.valid and sent.address == address \
        and sent.code in (None, code)


def claimed_by_polls(ours: list[Sent], host_log: list, code: int) -> set[int]:
    """
    Return the indices of the records taken as replies to polled requests.

    A polled request of the stream's own record (the start-up's two polled
    requests) takes the first such record after it as its reply, whether the
    sensor answered it or was streaming already (a stall ate the stop): that
    record is claimed, not lost.
    """
    polled = sorted(h.time for h in host_log
                    if h.command is not None and h.command.code == code)
    ours_sorted = sorted((s.write_time, s.index) for s in ours if s.write_time is not None)
    claimed = set()
    for p in polled:
        i = bisect.bisect_right(ours_sorted, (p, float('inf')))
        if i < len(ours_sorted):
            claimed.add(ours_sorted[i][1])
    return claimed


def coverage(data: RunData, windows: Windows, seen: collections.Counter,
             code: int) -> Coverage:
    """Sort our records into must and may be published, and find the missing ones."""
    ours = [s for s in data.truth if is_ours(s, data.cfg.address, code)]
    claimed = claimed_by_polls(ours, data.host_log, code)
    must = [s for s in ours if windows.read(s.write_time) and s.index not in claimed]
    may = [s for s in ours if s.write_time is not None
           and (not windows.read(s.write_time) or s.index in claimed)]
    missing = [s for s in must if s.index not in seen]
    may_published = sum(1 for s in may if s.index in seen)
    sent = sum(1 for s in ours if s.write_time is not None)
    return Coverage(must, may, missing, may_published, sent, code)


def missing_examples(data: RunData, missing: list[Sent]) -> str:
    """Describe the first missing records with what may explain them."""
    position = {sent.index: i for i, sent in enumerate(data.truth)}

    def before(sent: Sent) -> str:
        # What the line carried just before a missing record: the faults that may explain it.
        i = position.get(sent.index, 0)
        return ', '.join(f'#{p.index} {p.source}/{p.fault or "ok"}/{p.address}'
                         for p in data.truth[max(0, i - 3):i])

    port_events = (data.node_stats or {}).get('port_events', [])

    def around(sent: Sent) -> str:
        # The node's port events near a missing record: a flush or close may explain it.
        return ', '.join(f'{kind} {t - sent.write_time:+.3f}' for kind, t, _ in port_events
                         if abs(t - sent.write_time) < 1.0)

    return '; '.join(f'#{s.index} written {s.write_time - data.started:.3f} s after '
                     f'[{before(s)}], port events [{around(s)}]' for s in missing[:5])


def published_checks(data: RunData, matching: Matching, cover: Coverage) -> list[Check]:
    """Judge what was published: every message once, each a valid record we had to send."""
    address = data.cfg.address
    published = (data.node_stats or {}).get('stats', {}).get('published')
    unknown, invalid = matching.unknown, matching.invalid
    examples, duplicates = matching.invalid_examples, matching.duplicates
    must, missing = cover.must, cover.missing
    return [
        verdict('every message reached the subscriber', published == len(data.messages),
                f'node published {published}, subscriber received {len(data.messages)}'),
        verdict('every message is a record the sensor sent', unknown == 0,
                f'{unknown} messages match no record of the truth'
                + (f' ({"; ".join(examples)})' if examples else '')),
        verdict('no corrupted, foreign or unwritten record published', invalid == 0,
                f'{invalid} published records were not valid packets from address {address}'
                + (f': {"; ".join(examples)}' if examples else '')),
        verdict('no record published twice', not duplicates,
                f'{len(duplicates)} records published more than once'
                + (f', e.g. {sorted(duplicates.items())[:5]}' if duplicates else '')),
        verdict('every valid record read by the node published', not missing,
                f'{len(must)} valid records written while the node was reading: '
                f'{len(must) - len(missing)} published, {len(missing)} missing'
                + (f' ({missing_examples(data, missing)})' if missing else '')),
        *order_checks(matching.matched)]


def order_checks(matched: list[tuple[Sent, tuple]]) -> list[Check]:
    """Judge the order the records arrived in, and their orientations."""
    order = [sent.index for sent, _ in matched]
    out_of_order = sum(1 for a, b in itertools.pairwise(order) if b <= a)
    wrong_quat = sum(1 for sent, row in matched if row[2] != sent.quat)
    return [
        verdict('published in the order sent', out_of_order == 0,
                f'{out_of_order} messages arrived before one sent earlier'),
        verdict('orientation exact', wrong_quat == 0,
                f'{wrong_quat} of {len(matched)} orientations differ from the Shepperd '
                f'quaternion the codec computes from the record matrix (ENU)')]
