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
The data rate as the records show it, and how far it may stray from the configured one.

Diagnostics measures it every period and the self test once after the
stream resumed, both from the records' read times with :class:`RateMeter`,
and both judge it against the configured rate within :data:`RATE_TOLERANCE`.
"""

#: How far the measured rate may stray from the configured one (beyond: WARN, a failed step).
RATE_TOLERANCE = 0.05


class RateMeter:
    """
    Measure the record rate between two moments from the records' read times.

    The rate is (records since the last update) over the time between the
    last record of each, so neither timer jitter nor the caller's own phase
    affects it. It restarts whenever the stream was not running at both
    updates (a pause or reconnect would otherwise show as a low rate).
    """

    def __init__(self) -> None:
        self._count: int | None = None
        self._time = 0.0

    def update(self, count: int, last_time: float, running: bool) -> float | None:
        """Take the record count and the last record's read time; return the rate or None."""
        rate = None
        if running and self._count is not None and last_time > self._time \
                and count > self._count:
            rate = (count - self._count) / (last_time - self._time)
        self._count, self._time = (count, last_time) if running else (None, 0.0)
        return rate
