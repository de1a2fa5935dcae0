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
The check every stamp test makes of a stamp-error series (issue #23's terms).

A series is (true sample time, stamp - true sample time) in stamping order.
The steady offset is its median between the start's grace and the event
(the radio latency less the wire time: no host-side estimate can see it).
From ``GRACE`` after the start and after the stream's return (the first
record sampled after the event) every stamp is within ``TOLERANCE`` of it;
within the graces, within ``EARLY_TOLERANCE``; and after the last grace the
error has no trend (a rate error would show as one).
"""

import statistics

#: Stamps within this of the steady offset, but in the grace after a start or return.
TOLERANCE = 0.001
GRACE = 0.5
EARLY_TOLERANCE = 0.005
#: The error may trend by at most this (ppm) after the grace: a rate error shows here.
MAX_TREND_PPM = 100.0


def check_series(series: list[tuple[float, float]], event_time: float | None,
                 context: object = '') -> dict:
    """Assert the series keeps the bounds; return the worst error after a grace and more."""
    start = series[0][0]
    event = event_time if event_time is not None else float('inf')
    steady = statistics.median(e for t, e in series if start + GRACE <= t < event)
    back = next((t for t, _ in series if t > event), None)
    graces = [start] + ([back] if back is not None else [])
    worst = 0.0
    settled = []
    for t, e in series:
        since = min(t - g for g in graces if t >= g)
        off = abs(e - steady)
        if since < GRACE:
            assert off <= EARLY_TOLERANCE, (f'{t - start:.3f} s in, {since:.3f} s after a '
                                            f'start: {off * 1e3:.3f} ms off', context)
            continue
        settled.append((t, e))
        worst = max(worst, off)
        assert off <= TOLERANCE, (f'{t - start:.3f} s in, {since:.3f} s after the last '
                                  f'start: {off * 1e3:.3f} ms off the steady offset', context)
    after = [(t, e) for t, e in settled if back is None or t >= back + GRACE]
    trend = 0.0
    if len(after) > 50:
        trend = statistics.linear_regression([t for t, _ in after],
                                             [e for _, e in after]).slope
        assert abs(trend) * 1e6 < MAX_TREND_PPM, (f'stamps trend {trend * 1e6:.1f} ppm',
                                                  context)
    return {'worst': worst, 'steady': steady, 'back': back, 'trend_ppm': trend * 1e6}
