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
When the node was surely reading the port, from the instrumented node's port events.

A record written outside these windows (unplugged, flushed at a (re)open,
still unread at a close) may be lost legitimately; one written inside must
be published. The report states the rule (``campaign_report.py``).
"""

import bisect
import collections


class Windows:
    """When the node was reading the port, from its own port events."""

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
