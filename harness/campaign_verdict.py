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
The fault campaign's verdict: what a run produced, every check on it, and the report.

Each leg of a run (processes, threads, the simulator: ``long_soak.py``, on
the pieces of ``campaign.py``; the campaign is one such leg) fills in a
:class:`RunData`; all that is judged is read from it here, so the rules can be checked on
synthetic runs with known bugs, without a node or a simulator
(``test/test_soak_short.py``, ``test/test_campaign_pieces.py``).

What is judged, in the report's order:

* the node's health: alive, a clean exit, data back after the faults, RSS
  flat after the warm-up (the baseline is taken at the end of the warm-up,
  not at the start: the node's first seconds fill its buffers and caches);
* what was published against the truth: every message matched, by its
  exact values, to the record it came from; nothing unknown, corrupted or
  foreign, nothing twice, nothing the node read left out, in order, with
  the orientation exact;
* the stamps: true to the sample time through every fault (issue #23);
* the node's own counters, each within bounds computed from the truth: at
  least what the node surely read, at most what it could have read, widened
  only by the stray bytes that can legitimately fake an event.

Whether the node had to read a record comes from when it was written
against the node's own port events (:class:`Windows`). The rules are stated
in the report itself, beside the bounds they give, so that a reader of a
failed run need not open the code.
"""

import bisect
import collections
from collections.abc import Callable
import dataclasses
import itertools
import statistics
from typing import Any, NamedTuple

from harness.fault_driver import FaultEvent
from i3dmgx2_driver.codec.data_rate import ticks_per_cycle
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.streams import parse as parse_stream
from i3dmgx2_driver.codec.timer import TIMER_MODULUS


# -- what a run is given and what it produced --------------------------------------------------

# What every run on a simulated sensor shares (the campaign and the long soak here, the node
# fuzz in benchmarks/fuzz_node.py) is declared once: a default changes for all or for none.

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


def rate_text(cfg: CampaignConfig) -> str:
    """Say what the simulator streams and how fast, for the logs and the report."""
    if cfg.rate_hz is None:
        return (f'stream {cfg.stream!r} at data_rate {cfg.data_rate:g} Hz (the divider the '
                f'node writes; the line rate honoured)')
    return f'stream {cfg.stream!r} at {cfg.rate_hz:g} Hz (simulator rate override)'


class Sent(NamedTuple):
    """What the campaign keeps of one truth entry (compact: a run has 10^5 of them)."""

    index: int
    write_time: float | None
    valid: bool
    fault: str | None
    address: int
    source: str
    #: Exact published values (accel ENU m/s^2, rate ENU rad/s) of a record, packed.
    key: bytes | None
    #: The values a corrupted packet would publish if a parser accepted it.
    bad_key: bytes | None
    quat: bytes | None
    timer: int | None
    sample_time: float
    #: 0xAA and 0x21 bytes in the packet (each can become a spurious parser event).
    marks: int
    size: int
    #: Command byte of the record (None: not a streamable record).
    code: int | None = None


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


class Check(NamedTuple):
    """One pass/fail verdict with its evidence."""

    name: str
    ok: bool
    detail: str


def verdict(name: str, ok: object, detail: str) -> Check:
    """Return a check, its ``ok`` a bool whatever the test gave (a count, a list, None)."""
    return Check(name, bool(ok), detail)


@dataclasses.dataclass
class CampaignResult:
    """The verdicts and the report of one run: a campaign, a leg, or the whole long soak."""

    checks: list[Check]
    report: str
    #: The run's figures by name (sent, published, received, missing, ...), for a summary.
    figures: dict = dataclasses.field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Whether there were checks and every one passed."""
        return bool(self.checks) and all(check.ok for check in self.checks)

    def failures(self) -> list[Check]:
        """Return the checks that failed."""
        return [check for check in self.checks if not check.ok]


# -- when the node was surely reading the port -------------------------------------------------

class Windows:
    """
    When the node was reading the port, from its own port events.

    A record written outside these windows (unplugged, flushed at a (re)open,
    still unread at a close) may be lost legitimately; one written inside
    must be published.
    """

    def __init__(self, port_events: list, unplugs: list[float], end: float,
                 margin: float, settle: float = 0.05) -> None:
        by_conn: dict[int, dict] = collections.defaultdict(
            lambda: {'flush': [], 'anchor': [], 'close': None, 'open': None})
        for kind, t, conn in port_events:
            entry = by_conn[conn]
            if kind in ('flush', 'anchor'):
                entry[kind].append(t)
            else:
                entry[kind] = t
        self.flushes = sorted(t for e in by_conn.values() for t in e['flush'])
        self.opens = sorted(e['open'] for e in by_conn.values() if e['open'] is not None)
        #: Where the node's loss counting starts afresh (it re-anchored: its reader publishes
        #: from then on), by the write time of the records (see :func:`_fresh_from`).
        self.fresh_starts = sorted(t for e in by_conn.values() for t in _fresh_from(e))
        self.spans: list[tuple[float, float]] = []
        for entry in by_conn.values():
            if entry['anchor']:
                close = entry['close'] if entry['close'] is not None else end
                self.spans.append((entry['anchor'][-1], close))
        self.spans.sort()
        self.starts = [s for s, _ in self.spans]
        self.unplugs = sorted(unplugs)
        self.margin = margin
        self.settle = settle

    def read(self, t: float | None) -> bool:
        """Whether bytes written at ``t`` were surely read by the node (see the rules)."""
        if t is None:
            return False
        i = bisect.bisect_right(self.starts, t) - 1
        if i < 0:
            return False
        start, close = self.spans[i]
        if not start + self.settle <= t <= close - self.margin:
            return False
        j = bisect.bisect_left(self.unplugs, start)
        return not (j < len(self.unplugs) and self.unplugs[j] <= t + self.margin)

    def near_flush(self, t: float | None, width: float = 0.1) -> bool:
        """Whether ``t`` is within ``width`` of a flush or open of the port."""
        if t is None:
            return False
        for times in (self.flushes, self.opens):
            i = bisect.bisect_left(times, t - width)
            if i < len(times) and times[i] <= t + width:
                return True
        return False


def _fresh_from(entry: dict) -> list[float]:
    """
    Return, for each anchor of one connection, the write time from which records follow it.

    The node forgets its last record at an anchor, and its reader starts
    there; the bytes of a record written after the flush just before the
    anchor (a reconnect's ``expect_stream``, a start-up's quiet) wait in the
    port's queue and are read, and counted, after it, though written
    before. So a record belongs to the anchor's span from that flush on, or
    from the anchor itself when no flush came between it and the one before.
    (When a resume falls back to the full dialogue, its reader still runs
    through the quiet's flush; the stream was stopped 50 ms before it, so no
    record should come between that flush and the anchor.)
    """
    starts = []
    previous = entry['open'] if entry['open'] is not None else float('-inf')
    for anchor in sorted(entry['anchor']):
        flushes = [t for t in entry['flush'] if previous < t <= anchor]
        starts.append(max(flushes) if flushes else anchor)
        previous = anchor
    return starts


# -- the node's health -------------------------------------------------------------------------

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


# -- what was published against the truth ------------------------------------------------------

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
    #: Those of ``must`` never published.
    missing: list[Sent]
    #: Our records written at all.
    sent: int
    #: The command byte of the stream's records: ours.
    code: int


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
    # Records of another stream (a sensor power-cycled into its EEPROM auto-start) are
    # the node's to count, not to publish.
    ours = [s for s in data.truth if s.key is not None and s.valid
            and s.address == data.cfg.address and s.code in (None, code)]
    claimed = claimed_by_polls(ours, data.host_log, code)
    must = [s for s in ours if windows.read(s.write_time) and s.index not in claimed]
    missing = [s for s in must if s.index not in seen]
    sent = sum(1 for s in ours if s.write_time is not None)
    return Coverage(must, missing, sent, code)


def published_checks(data: RunData, matching: Matching, cover: Coverage) -> list[Check]:
    """Judge what was published: every message once, in order, each a record we had to send."""
    address = data.cfg.address
    published = (data.node_stats or {}).get('stats', {}).get('published')
    unknown, invalid = matching.unknown, matching.invalid
    examples, duplicates = matching.invalid_examples, matching.duplicates
    must, missing = cover.must, cover.missing
    matched = matching.matched
    order = [sent.index for sent, _ in matched]
    out_of_order = sum(1 for a, b in itertools.pairwise(order) if b <= a)
    wrong_quat = sum(1 for sent, row in matched if row[2] != sent.quat)
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
                + (f', e.g. #{", #".join(str(s.index) for s in missing[:5])}'
                   if missing else '')),
        verdict('published in the order sent', out_of_order == 0,
                f'{out_of_order} messages arrived before one sent earlier'),
        verdict('orientation exact', wrong_quat == 0,
                f'{wrong_quat} of {len(matched)} orientations differ from the Shepperd '
                f'quaternion the codec computes from the record matrix (ENU)')]


# -- the stamps --------------------------------------------------------------------------------

def stamp_verdict(matched: list[tuple[Sent, tuple]], cfg: CampaignConfig) -> tuple[bool, str]:
    """
    Judge the stamp errors as a series: steady after every start and return.

    A return is a published record sampled more than 0.1 s after the one
    before it, or whose timer does not follow from that one's (the sensor
    restarted): the stamps may start afresh there, within
    ``stamp_early_tolerance`` for ``stamp_grace`` s.

    The first record of a start or return is stamped at its read time (the
    fresh fit has nothing else): its error is how late the node's reader got
    to it, which a loaded host (a thread waiting for the interpreter's lock,
    up to its 5-ms switch interval) makes late at the node's start. Only for
    that record, how much later than usual it reached the subscriber is
    allowed on top; every later record of the grace has the strict limit.
    """
    if not matched:
        return True, 'no stamps to judge'
    series = [(sent.sample_time, row[1] * 1e-9 - sent.sample_time, sent.timer)
              for sent, row in matched]
    # How late each record left the simulator after its sample time (the line's queue).
    delays = [(sent.write_time or sent.sample_time) - sent.sample_time for sent, _ in matched]
    # How late each reached the subscriber after its sample time (the node's reader among it).
    arrivals = [row[3] - sent.sample_time for sent, row in matched]
    steady = statistics.median(e for _, e, _ in series)
    usual = statistics.median(delays)
    usual_arrival = statistics.median(arrivals)
    grace_from = series[0][0]
    # In a grace the stamps start from the first records' arrival: one the simulator wrote
    # late (its thread descheduled on a loaded machine) moves them by as much, and no
    # receiver could know better then. That lateness is allowed on top, in that grace.
    grace_late = max(0.0, delays[0] - usual)
    returns = 0
    worst = worst_early = 0.0
    bad = []
    previous = None
    for (t, e, timer), delay, arrival in zip(series, delays, arrivals, strict=True):
        first = previous is None
        if previous is not None:
            dt = t - previous[0]
            steps = ((timer - previous[2]) % TIMER_MODULUS / TICKS_PER_SECOND
                     if timer is not None and previous[2] is not None else dt)
            if dt > 0.1 or abs(steps - dt) > 0.05:
                grace_from = t
                grace_late = max(0.0, delay - usual)
                returns += 1
                first = True
        previous = (t, e, timer)
        off = abs(e - steady)
        early = t - grace_from < cfg.stamp_grace
        if early:
            worst_early = max(worst_early, off)
        else:
            worst = max(worst, off)
        read_late = max(0.0, arrival - usual_arrival) if first else 0.0
        limit = (cfg.stamp_early_tolerance + max(grace_late, read_late) if early
                 else cfg.stamp_tolerance)
        if off > limit:
            bad.append(f'{off * 1e3:.2f} ms at {t - series[0][0]:.2f} s'
                       + (' (in a grace)' if early else '')
                       + f' written {delay * 1e3:.1f} ms after its sample time'
                       + (f', received {arrival * 1e3:.1f} ms after it' if first else ''))
    detail = (f'stamp - true sample time: steady {steady * 1e3:+.3f} ms; worst off it '
              f'{worst * 1e3:.3f} ms after the {cfg.stamp_grace:g}-s graces (limit '
              f'{cfg.stamp_tolerance * 1e3:g}), {worst_early * 1e3:.2f} ms in them (limit '
              f'{cfg.stamp_early_tolerance * 1e3:g}, plus how much later than usual the '
              f"simulator wrote the grace's first record, and for that record, how much "
              f'later than usual it was received); {returns} returns; '
              f'{len(bad)} stamps over' + (f', e.g. {"; ".join(bad[:5])}' if bad else ''))
    return not bad, detail


# -- the node's counters against the truth -----------------------------------------------------

def bounds(name: str, value: int | None, low: int, high: int, rule: str) -> Check:
    """Put a counter against its bounds; a counter missing is out of them."""
    return verdict(f'counter {name} reconciles', value is not None and low <= value <= high,
                   f'{value} in [{low}, {high}]: {rule}')


def fault_is(name: str) -> Callable[[Sent], bool]:
    """Return a predicate taking the records of one fault."""
    return lambda s: s.fault == name


def counter_rows(data: RunData, windows: Windows, matching: Matching) -> list[Check]:
    """Reconcile every counter the node keeps with the truth, in the report's order."""
    address, sim = data.cfg.address, data.sim_stats
    # Just before the node first opened the port: nothing written earlier can count.
    first_open = windows.opens[0] - 0.1 if windows.opens else data.started

    def written(s: Sent) -> bool:
        return s.write_time is not None and s.write_time >= first_open

    def count(pred: Callable[[Sent], bool], only_read: bool) -> int:
        # The records pred takes, surely read by the node, or written at all.
        return sum(1 for s in data.truth
                   if pred(s) and (windows.read(s.write_time) if only_read else written(s)))

    parser = (data.node_stats or {}).get('parser', {})
    nstats = (data.node_stats or {}).get('stats', {})
    corrupted = [s for s in data.truth
                 if s.fault in ('checksum', 'length') and written(s)]
    tail_marks = sum(s.marks for s in data.truth
                     if s.write_time is not None and windows.near_flush(s.write_time))
    # Bytes that may start a spurious ACK/NACK (the parser reports no answers from
    # inside a packet that failed its checksum or length): 0xAA/0x21 garbage, and
    # the tail of a packet cut by a flush, whose start is gone. Inside a corrupted
    # packet, each may still fake a length failure.
    stray = data.unsafe_garbage_bytes + tail_marks
    stray_marks = stray + sum(s.marks - 1 for s in corrupted)
    pings_failed = sum(1 for h in data.host_log if h.outcome == 'ping failed')
    acks_sent = [h for h in data.host_log if h.kind == 'packet']
    acks_read = sum(1 for h in acks_sent if windows.read(h.time))
    acks_all = sum(1 for h in acks_sent if h.time >= first_open)
    bytes_read = sum(s.size for s in data.truth if windows.read(s.write_time))
    skipped_low = sum(s.size - s.marks for s in data.truth
                      if s.fault in ('checksum', 'length') and windows.read(s.write_time))
    published_sorted = sorted((s for s, _ in matching.matched
                               if s.index not in matching.duplicates),
                              key=lambda s: s.index)
    lost, resets, _ = expected_gaps(published_sorted, windows, data.divider, data.power_ups)
    return [
        bounds('checksum_failures', parser.get('checksum_failures'),
               count(fault_is('checksum'), True), count(fault_is('checksum'), False),
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
               'each valid packet from our address read (stream and replies) is one, no other'),
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
               'at least the bytes of the corrupted packets read, less their 0xAA/0x21 bytes'),
        bounds('lost', nstats.get('lost'), lost, lost,
               f'timer steps between published records of one connection and one power-up, '
               f'as cycles of the divider ({data.divider}) less one: exact'),
        bounds('device_resets', nstats.get('device_resets'), resets, resets,
               'published records of one connection on either side of a sensor power-up: exact')]


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


# -- the report --------------------------------------------------------------------------------

def run_lines(data: RunData, cover: Coverage) -> list[str]:
    """Say what ran, the faults, and how many of our records the node had to publish."""
    cfg = data.cfg
    kinds = collections.Counter(e.kind for e in data.events)
    return ['== i3dmgx2 soak and fault campaign ==',
            f'fault phase {cfg.minutes:g} min at {rate_text(cfg)}, seed {cfg.seed}, '
            f'node read_timeout {cfg.read_timeout:g} s, reconnect_interval '
            f'{cfg.reconnect_interval:g} s, temperature_period '
            f'{cfg.temperature_period:g} s, then {cfg.quiet:g} s quiet',
            'fault events: ' + ', '.join(f'{k} {n}' for k, n in sorted(kinds.items())),
            f'valid 0x{cover.code:02X} records from address {cfg.address}: '
            f'{cover.sent} written, {len(cover.must)} of them while the node read (must be '
            f'published once; the others may be lost: unplugged, flushed at a (re)open, '
            f'just before a close)']


def rule_lines(data: RunData, windows: Windows, checks: list[Check]) -> list[str]:
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
    for c in checks:
        if c.name.startswith('counter '):
            name = c.name.removeprefix('counter ').removesuffix(' reconciles')
            lines.append(f'  {"ok  " if c.ok else "FAIL"} {name}: {c.detail}')
    return lines


def check_lines(checks: list[Check], failed_only: bool = False) -> list[str]:
    """
    List the checks, then the result: every one but the counters' (in the rules already).

    ``failed_only``: the failed ones only (the long soak's run to hundreds).
    """
    failed = [c for c in checks if not c.ok]
    listed = failed if failed_only else [c for c in checks if not c.name.startswith('counter ')]
    return [f'Checks ({len(checks) - len(failed)} of {len(checks)} passed):',
            *(f'  {"PASS" if c.ok else "FAIL"} {c.name}: {c.detail}' for c in listed), '',
            'RESULT: ' + ('PASS' if not failed else f'FAIL ({len(failed)} checks)')]


# -- all of it ---------------------------------------------------------------------------------

def analyse(data: RunData, exempt: tuple[str, ...] = (),
            more: tuple[Check, ...] = ()) -> CampaignResult:
    """
    Match what was published with the truth; reconcile the counters; judge.

    ``exempt`` names checks that do not apply to this run (a managed node's
    leg: the node lives on, and counts what it reads while inactive as
    unpublished): they are left out of the checks and of the report.
    ``more``: checks the caller made (the data back after each fault), judged
    and reported with the others.
    """
    cfg = data.cfg
    node = data.node_stats or {}
    nstats = node.get('stats', {})
    # Until the node's deactivate, its last port event, or the end of the faults.
    end = data.end if data.end is not None else max(
        [e[1] for e in node.get('port_events', [])] + [data.fault_end])
    unplugs = [e.start for e in data.events if e.kind == 'unplug']
    windows = Windows(node.get('port_events', []), unplugs, end, cfg.unread_margin)
    matching = match(data.truth, data.messages, cfg.address)
    cover = coverage(data, windows, matching.seen, parse_stream(cfg.stream).code)
    checks = [*health_checks(data),
              *published_checks(data, matching, cover),
              verdict('stamps true through every fault', *stamp_verdict(matching.matched, cfg)),
              *counter_rows(data, windows, matching),
              verdict('nothing left unpublished', nstats.get('unpublished', 0) == 0,
                      f'{nstats.get("unpublished")} records dropped by a failed publish'),
              *more]
    checks = [c for c in checks if c.name not in exempt]
    figures = {
        'sent': cover.sent,
        'published': nstats.get('published'),
        'received': len(data.messages), 'missing': len(cover.missing),
        'duplicated': len(matching.duplicates),
        'corrupted': matching.invalid + matching.unknown, 'events': len(data.events)}
    report = [*run_lines(data, cover), '', *rule_lines(data, windows, checks), '',
              *check_lines(checks)]
    return CampaignResult(checks, '\n'.join(report), figures)
