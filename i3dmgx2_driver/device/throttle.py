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
Say a persisting condition once, then remind at most every so often.

A missing port or a silent sensor would otherwise fill the log at the retry
rate; what may come back is said once and reminded (``REMINDER_PERIOD``),
events that each mean something new (a stall) at most every ``EVENT_PERIOD``.
"""

import time

#: A condition that persists (a missing port, a silent sensor) is said once,
#: then reminded at most this often (s).
REMINDER_PERIOD = 60.0
#: Events that each mean something new (a stall) are logged at most this often (s).
EVENT_PERIOD = 10.0


class Throttle:
    """Let one message per key through every ``period`` seconds."""

    def __init__(self, period: float = REMINDER_PERIOD) -> None:
        self.period = period
        self._last: dict[str, float] = {}

    def allow(self, key: str, period: float | None = None) -> bool:
        """Tell whether a message of this key may be logged now (``period``: override)."""
        now = time.monotonic()
        if now - self._last.get(key, -1e9) >= (self.period if period is None else period):
            self._last[key] = now
            return True
        return False
