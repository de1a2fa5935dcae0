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
The node's own counters reconciled with what the simulator wrote.

Each counter must lie within bounds computed from the truth: at least what
the node surely read, at most what it could have read, widened only by the
stray bytes that can legitimately fake an event (each rule is printed in
the report beside its bounds). Whether the node read a record comes from
``read_windows.py``.
"""

import bisect
from collections.abc import Callable
from typing import NamedTuple

from harness.campaign_data import RunData
from harness.campaign_match import Matching
from harness.campaign_result import Check, verdict
from harness.campaign_truth import Sent
from harness.read_windows import Windows
from i3dmgx2_driver.codec.data_rate import ticks_per_cycle
from i3dmgx2_driver.codec.timer import TIMER_MODULUS


class CounterRow(NamedTuple):
    """One counter, its bounds, whether it lies within them, and the rule they come from."""

    name: str
    value: int | None
    low: int
    high: int
    ok: bool
    rule: str


def bounds(name: str, value: int | None, low: int, high: int, rule: str) -> CounterRow:
    """Put a counter against its bounds."""
    ok = value is not None and low <= value <= high
    return CounterRow(name, value, low, high, ok, rule)


class Tally:
    """Count truth records over those the node surely read, or over all it could have."""

    def __init__(self, truth: list[Sent], windows: Windows, started: float) -> None:
        self.truth = truth
        self.windows = windows
        #: Just before the node first opened the port: nothing written earlier can count.
        self.first_open = windows.opens[0] - 0.1 if windows.opens else started

    def written(self, s: Sent) -> bool:
        """Whether the record was written after the node first opened the port."""
        return s.write_time is not None and s.write_time >= self.first_open

    def count(self, pred: Callable[[Sent], bool], only_read: bool) -> int:
        """Count the records pred takes, read by the node, or written at all."""
        return sum(1 for s in self.truth if pred(s)
                   and (self.windows.read(s.write_time) if only_read else self.written(s)))


def fault_is(name: str) -> Callable[[Sent], bool]:
    """Return a predicate taking the records of one fault."""
    return lambda s: s.fault == name


def counter_rows(data: RunData, windows: Windows, matching: Matching) -> list[CounterRow]:
    """Reconcile every counter the node keeps with the truth, in the report's order."""
    tally = Tally(data.truth, windows, data.started)
    parser = (data.node_stats or {}).get('parser', {})
    corrupted = [s for s in data.truth
                 if s.fault in ('checksum', 'length') and tally.written(s)]
    marks_corrupt = sum(s.marks - 1 for s in corrupted)
    tail_marks = sum(s.marks for s in data.truth
                     if s.write_time is not None and windows.near_flush(s.write_time))
    # Bytes that may start a spurious ACK/NACK (the parser reports no answers from
    # inside a packet that failed its checksum or length): 0xAA/0x21 garbage, and
    # the tail of a packet cut by a flush, whose start is gone.
    stray = data.unsafe_garbage_bytes + tail_marks
    return [*frame_rows(parser, tally, data.cfg.address, stray + marks_corrupt),
            *line_rows(data, tally, stray),
            *node_rows(data, windows, matching)]


def frame_rows(parser: dict, tally: Tally, address: int, stray_marks: int) -> list[CounterRow]:
    """Reconcile the parser's frame counters; stray_marks may each fake a length failure."""
    count = tally.count
    c_read = count(fault_is('checksum'), True)
    return [
        bounds('checksum_failures', parser.get('checksum_failures'), c_read,
               count(fault_is('checksum'), False),
               'each checksum-corrupted packet the node read is one failure, no other'),
        bounds('length_failures', parser.get('length_failures'),
               count(fault_is('length'), True),
               count(fault_is('length'), False) + stray_marks,
               'each length-corrupted packet read is one; any other 0xAA byte (in 0xAA garbage, '
               'inside a corrupted packet, in a packet cut by a flush) may add one'),
        bounds('foreign_frames', parser.get('foreign_frames'), count(fault_is('foreign'), True),
               count(fault_is('foreign'), False),
               'each foreign packet read is one, no other'),
        bounds('good_frames', parser.get('good_frames'),
               count(lambda s: s.valid and s.address == address, True),
               count(lambda s: s.valid and s.address == address, False),
               'each valid packet from our address read (stream and replies) is one, no other')]


def line_rows(data: RunData, tally: Tally, stray: int) -> list[CounterRow]:
    """Reconcile the parser's answer and byte counters with what the line carried."""
    parser = (data.node_stats or {}).get('parser', {})
    sim = data.sim_stats
    windows = tally.windows
    pings_failed = sum(1 for h in data.host_log if h.outcome == 'ping failed')
    acks_sent = [h for h in data.host_log if h.kind == 'packet']
    acks_read = sum(1 for h in acks_sent if windows.read(h.time))
    acks_all = sum(1 for h in acks_sent if h.time >= tally.first_open)
    bytes_read = sum(s.size for s in data.truth if windows.read(s.write_time))
    skipped_low = sum(s.size - s.marks for s in data.truth
                      if s.fault in ('checksum', 'length') and windows.read(s.write_time))
    return [
        bounds('acks', parser.get('acks'), max(0, acks_read - data.unsafe_garbage_bursts),
               acks_all + stray,
               'each ACK the base station wrote while the node read is one (less one per 0xAA-'
               'garbage burst, whose 0x07 may follow it); each 0xAA of 0xAA-garbage or of a '
               'packet cut by a flush may add one, none inside a corrupted packet'),
        bounds('nacks', parser.get('nacks'), 0,
               sim.get('nacks', 0) + pings_failed + stray,
               'NACKs written, failed-ping answers arriving late, and 0x21 bytes of 0xAA-garbage '
               'or of a packet cut by a flush are the only ones (none inside a corrupted packet)'),
        bounds('bytes_in', parser.get('bytes_in'), bytes_read, sim.get('bytes_written', 0),
               'at least every packet written while the node read, at most all bytes written'),
        bounds('bytes_skipped', parser.get('bytes_skipped'), skipped_low,
               parser.get('bytes_in', 0),
               'at least the bytes of the corrupted packets read, less their 0xAA/0x21 bytes')]


def node_rows(data: RunData, windows: Windows, matching: Matching) -> list[CounterRow]:
    """Reconcile the node's lost records and device resets with the published records."""
    nstats = (data.node_stats or {}).get('stats', {})
    published_sorted = sorted((s for s, _ in matching.matched
                               if s.index not in matching.duplicates),
                              key=lambda s: s.index)
    lost, resets, gaps = expected_gaps(published_sorted, windows, data.divider, data.power_ups)
    rule = (f'timer steps between published records of one connection and one power-up, '
            f'as cycles of the divider ({data.divider}) less one: exact')
    if nstats.get('lost') != lost:
        # Where to look: the largest steps counted here, by the write time of the record after.
        largest = sorted(gaps, key=lambda gap: -gap[1])[:5]
        rule += '; largest steps counted here: ' + ', '.join(
            f'{count} before the record written at {t - data.started:.2f} s'
            for t, count in largest)
    return [
        bounds('lost', nstats.get('lost'), lost, lost, rule),
        bounds('device_resets', nstats.get('device_resets'), resets, resets,
               'published records of one connection on either side of a sensor power-up: exact')]


def counter_checks(rows: list[CounterRow], nstats: dict) -> list[Check]:
    """Turn the rows into checks, and check that no record was dropped by a failed publish."""
    return [*(verdict(f'counter {r.name} reconciles', r.ok,
                      f'{r.value} in [{r.low}, {r.high}]: {r.rule}') for r in rows),
            verdict('nothing left unpublished', nstats.get('unpublished', 0) == 0,
                    f'{nstats.get("unpublished")} records dropped by a failed publish')]


def expected_gaps(published: list[Sent], windows: Windows, divider: int,
                  power_ups: list[float]) -> tuple[int, int, list[tuple[float, int]]]:
    """
    Return the (lost, device resets, steps) the node should count over the published records.

    ``steps`` are the (write time, records lost) of each record after a loss.

    Two consecutive published records straddle a power-up of the sensor or
    do not. If they do, the node counts a device reset, whether or not it
    reconnected in between: its clock checks the first record of every new
    link against the fit (device/sample_clock.py). If they do not, and both
    lie between the same two anchors of the node (it forgets the last record
    at each: every connection, and again when a reconnect to a known sensor
    fell back to the full dialogue; a record written after the flush just
    before an anchor is read after it: ``Windows.fresh_starts``), it counts
    ``round(step / ticks_per_cycle(divider)) - 1`` lost records when that is
    positive, ``step`` being the timer step in ticks (its own formula, for
    the rate the divider gives).
    """
    expected = ticks_per_cycle(divider)
    ups = sorted(power_ups)
    lost = resets = 0
    steps: list[tuple[float, int]] = []
    last = None
    span = None
    for sent in published:
        i = bisect.bisect_right(windows.fresh_starts, sent.write_time) - 1
        if last is not None:
            j = bisect.bisect_right(ups, last.sample_time)
            if j < len(ups) and ups[j] <= sent.sample_time:
                resets += 1
            elif i == span:
                gap = round(((sent.timer - last.timer) % TIMER_MODULUS) / expected) - 1
                if gap > 0:
                    lost += gap
                    steps.append((sent.write_time, gap))
        span, last = i, sent
    return lost, resets, steps
