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
When a stream has stalled, and when to try a port again: two small policies.

Both are decisions on the monotonic clock that the supervisor thread
(supervisor.py) acts on. They are apart from it so that each rule is read in
one place and tested with a fake clock, without a thread, a port or a wait:

- :class:`StallWatch`: the stream has stalled when no record came for the
  stall timeout, or three sample periods if those are longer (a slow rate
  is no stall). It says when to look next (the moment the stream would have
  stalled), so that the supervisor thread sleeps until then: while records
  flow, it wakes about once per stall timeout.
- :class:`ReopenWait`: the reconnect back-off. After a failure the port is
  tried again ``reconnect_interval`` later, or sooner: an unplugged
  adapter's device node goes and comes back when it is plugged in again, so
  a port seen missing is reopened once it is back (after a moment for udev
  to set its permissions), and a port closed for a stall is still there, so
  it is reopened at once. Looking for it costs a stat() every few tens of ms.
"""

from collections.abc import Callable
import os
import time

#: How often a missing port is looked for (s), so that it is reopened as soon as it is back.
PORT_WATCH_S = 0.02
#: How long after the stall deadline the watch looks (s), so that it is past when looked at.
LOOK_MARGIN_S = 0.005
#: Pause between a port reappearing and opening it (s): udev sets its permissions meanwhile.
PORT_SETTLE_S = 0.02


class StallWatch:
    """Tell from the last record's time whether the stream has stalled."""

    def __init__(self, stall_timeout: float, period: float,
                 clock: Callable[[], float] = time.monotonic) -> None:
        #: Silence (s) after which the stream has stalled.
        self.stall_after = max(stall_timeout, 3 * period)
        self._clock = clock

    def next_look(self, last_data: float) -> float:
        """Seconds until the stream has stalled if nothing comes after ``last_data``."""
        return max(last_data + self.stall_after - self._clock(), 0.0) + LOOK_MARGIN_S

    def stalled(self, last_data: float) -> bool:
        """Whether no record came for longer than ``stall_after`` (``last_data``: monotonic)."""
        return self._clock() - last_data > self.stall_after


class ReopenWait:
    """
    Wait before the port at ``path`` is tried again: ``interval`` s, or until it is back.

    ``wait(seconds)`` waits and returns True when the driver stops meanwhile
    (an Event's ``wait``).
    """

    def __init__(self, path: str, interval: float, wait: Callable[[float], bool],
                 exists: Callable[[str], bool] = os.path.exists,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.path, self.interval = path, interval
        self._wait, self._exists, self._clock = wait, exists, clock

    @property
    def promise(self) -> str:
        """Say when the port is tried again, as a failed attempt's warning ends."""
        return f'retrying every {self.interval:g} s'

    def __call__(self, after_stall: bool = False) -> None:
        """
        Return when the port may be tried again, or the driver stops.

        ``after_stall``: the port was closed because its stream stalled, not
        lost; it is still there, and tried again at once.
        """
        if after_stall:
            return
        deadline = self._clock() + self.interval
        seen_missing = False
        while not self._wait(PORT_WATCH_S) and self._clock() < deadline:
            if not self._exists(self.path):
                seen_missing = True
            elif seen_missing:
                self._wait(PORT_SETTLE_S)
                return
