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
How long the data took to come back after each fault of a long-soak leg, and its limit.

The limit is not one number: every command or reply lost meanwhile costs the
dialogue one more try by design, so it grows by :data:`TRY_COST` for each;
the reasoning lives here, apart from the running of the leg.
"""

import bisect
from collections.abc import Callable

from harness.fault_driver import FaultEvent
from i3dmgx2_driver.device.timeouts import REQUEST_TIMEOUT

#: What one more try costs the dialogue when a command or its answer is lost: the
#: request's timeout, then the shortest wait for the first record
#: (``SensorDialogue.start_continuous``).
TRY_COST = REQUEST_TIMEOUT + 0.3


def recoveries(events: list[FaultEvent], rows: list, truth: list, host_log: list,
               recovery_limit: float, log: Callable[[str], None]
               ) -> list[tuple[str, float | None, float]]:
    """
    For each fault that ends: (kind, seconds to the next message received, the limit).

    The limit is ``recovery_limit``, plus :data:`TRY_COST` for every
    command the radio lost, stalled or the sensor ignored, and every reply
    the radio dropped, from one try before the fault ended to the
    message: each costs the dialogue one more try, by design. A fault
    followed by the next one before the data came back is left out (the
    recovery was cut short, not slow). Each slow one is explained to ``log``.
    """
    times = sorted(row[3] for row in rows)
    misses = sorted([h.time for h in host_log
                     if h.outcome in ('lost', 'ignored', 'stalled', 'ping failed')
                     or h.outcome.startswith('rejected')]
                    + [s.sample_time for s in truth
                       if s.source == 'reply' and s.fault is not None])
    starts = sorted(e.start for e in events)
    out = []
    for event in events:
        if event.kind in {'noise', 'quirks'}:
            continue  # they change the line's odds until the next change; all_off ends them
        i = bisect.bisect_right(times, event.end)
        back = times[i] if i < len(times) else None
        j = bisect.bisect_right(starts, event.end)
        if j < len(starts) and (back is None or starts[j] < back):
            continue  # the next fault began before the data came back: not a recovery
        retries = (bisect.bisect_right(misses, back)
                   - bisect.bisect_left(misses, event.end - TRY_COST)
                   if back is not None else 0)
        limit = recovery_limit + retries * TRY_COST
        gap = back - event.end if back is not None else None
        out.append((event.kind, gap, limit))
        if gap is None or gap > limit:
            explain(event, back, host_log, log)
    return out


def explain(event: FaultEvent, back: float | None, host_log: list,
            log: Callable[[str], None]) -> None:
    """Log what the host sent and the sensor made of it while the data did not come."""
    stop = back if back is not None else event.end + 10.0
    log(f'  slow recovery after {event.kind} ({event.detail}) at {event.end:.3f}:')
    for h in host_log:
        if event.start - 1.0 <= h.time <= stop:
            code = f'0x{h.raw[0]:02X}' if h.raw else '-'
            log(f'    {h.time - event.end:+.3f} s host {h.kind} {code} {h.outcome}')
