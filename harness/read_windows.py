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
        #: Every time the node started afresh (re-anchored: its reader publishes from then on).
        self.anchors = sorted(t for e in by_conn.values() for t in e['anchor'])
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
