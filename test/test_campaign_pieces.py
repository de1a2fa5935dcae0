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

"""The campaign's analysis pieces on their own: read windows, polled replies, RSS, bounds."""

from types import SimpleNamespace

from harness.campaign_verdict import bounds, claimed_by_polls, expected_gaps, rss_check, Sent, \
    Windows
from i3dmgx2_driver.codec.data_rate import ticks_per_cycle


def _windows() -> Windows:
    events = [('open', 1.0, 1), ('flush', 1.5, 1), ('anchor', 2.0, 1), ('close', 10.0, 1),
              ('open', 11.0, 2), ('anchor', 11.2, 2)]
    return Windows(events, unplugs=[6.0], end=20.0, margin=0.5)


def test_windows_read_from_the_last_anchor_plus_settle_to_the_close_less_the_margin():
    windows = _windows()
    assert not windows.read(None)
    assert not windows.read(0.5)
    assert not windows.read(2.01)
    assert windows.read(3.0)
    assert not windows.read(9.6)
    assert windows.read(12.0)
    assert windows.read(19.5)
    assert not windows.read(19.6)


def test_windows_read_nothing_from_just_before_an_unplug_to_the_next_anchor():
    windows = _windows()
    assert windows.read(5.4)
    assert not windows.read(5.6)
    assert not windows.read(7.0)


def test_windows_near_flush_counts_opens_and_flushes():
    windows = _windows()
    assert windows.near_flush(1.05)
    assert windows.near_flush(1.55)
    assert not windows.near_flush(1.3)
    assert not windows.near_flush(None)


def _sent(index: int, write_time: float | None) -> Sent:
    return Sent(index, write_time, True, None, 95, 'stream', b'k', None, None, 0, 0.0, 0, 10)


def _record(index: int, write_time: float, timer: int) -> Sent:
    return _sent(index, write_time)._replace(timer=timer, sample_time=write_time)


def test_losses_are_counted_within_one_anchor_span_and_say_where():
    step = ticks_per_cycle(10)  # one record's ticks at divider 10
    published = [_record(0, 3.0, 0), _record(1, 3.1, step), _record(2, 3.5, 5 * step),
                 _record(3, 12.0, 100 * step), _record(4, 12.1, 103 * step)]
    lost, resets, steps = expected_gaps(published, _windows(), 10, power_ups=[])
    # 3 lost before the record at 3.5 s and 2 before the one at 12.1 s; none across the
    # anchor at 11.2 s (a new connection: the node forgets its last record there).
    assert (lost, resets, steps) == (5, 0, [(3.5, 3), (12.1, 2)])
    # A power-up between two records is a reset, not a loss.
    lost, resets, steps = expected_gaps(published, _windows(), 10, power_ups=[3.3])
    assert (lost, resets, steps) == (2, 1, [(12.1, 2)])


def test_a_record_written_between_a_reconnects_flush_and_its_anchor_starts_the_new_span():
    # Reconnect 2 flushes at 11.1 s and anchors at 11.2 s: the record written at 11.15 s
    # waited in the port's queue and was read after the anchor, where the node forgets the
    # record before. The gap across the outage is no loss (leg 20 of the hour run of
    # 2026-11-26 counted 387 such records of a reconnect against the node).
    events = [('open', 1.0, 1), ('flush', 1.5, 1), ('anchor', 2.0, 1), ('close', 10.0, 1),
              ('open', 11.0, 2), ('flush', 11.1, 2), ('anchor', 11.2, 2)]
    windows = Windows(events, unplugs=[6.0], end=20.0, margin=0.5)
    assert windows.fresh_starts == [1.5, 11.1]
    step = ticks_per_cycle(10)
    published = [_record(0, 3.0, 0), _record(1, 3.1, step), _record(2, 11.15, 300 * step),
                 _record(3, 11.3, 302 * step)]
    assert expected_gaps(published, windows, 10, power_ups=[]) == (1, 0, [(11.3, 1)])
    # An anchor with no flush since the one before starts the span at the anchor itself.
    events += [('anchor', 15.0, 2)]
    assert Windows(events, unplugs=[], end=20.0, margin=0.5).fresh_starts == [1.5, 11.1, 15.0]


def test_a_polled_request_claims_the_first_record_written_after_it():
    ours = [_sent(0, 0.9), _sent(1, 1.1), _sent(2, 1.2), _sent(3, None), _sent(4, 5.0)]
    log = [SimpleNamespace(time=1.0, command=SimpleNamespace(code=0xCC)),
           SimpleNamespace(time=2.0, command=SimpleNamespace(code=0xC2)),
           SimpleNamespace(time=3.0, command=None),
           SimpleNamespace(time=9.0, command=SimpleNamespace(code=0xCC))]
    assert claimed_by_polls(ours, log, 0xCC) == {1}


def test_rss_growth_is_judged_from_the_end_of_warm_up_to_the_last_samples():
    flat = [(float(t), 1000) for t in range(40)]
    assert rss_check(flat, warmup_end=10.0, limit=0.1).ok
    grown = [(float(t), 1000 if t < 30 else 1200) for t in range(40)]
    check = rss_check(grown, warmup_end=10.0, limit=0.1)
    assert not check.ok
    assert '+20.0 %' in check.detail
    assert rss_check(flat, warmup_end=50.0, limit=0.1).detail == 'not enough RSS samples'


def test_a_counter_missing_is_out_of_its_bounds():
    assert bounds('acks', 3, 3, 3, 'exact').ok
    assert not bounds('acks', 4, 3, 3, 'exact').ok
    assert not bounds('acks', None, 0, 10, 'any').ok
