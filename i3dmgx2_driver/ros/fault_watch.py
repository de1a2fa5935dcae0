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
What went wrong with one sensor since the last look: the fault capture's triggers.

The fault capture (:class:`~..capture.fault_capture.FaultCapture`) writes the
last seconds of the port when a fault is seen. The faults are those the
driver already counts where it detects them: the supervisor's stalls and
reconnects and its state (device/status.py), the parser's corrupted packets
and NACKs (codec/parser.py ``ParserStats``, summed over links), the device
resets the stamping clock found (``StreamStats.device_resets``: a power
cycle, a clock reset). :class:`FaultWatch` compares one snapshot of those
counters with the one before, in the fault capture's own thread a few
times a second, rather than having each place that counts call out: the
reader thread's path and the device layer stay exactly as they were, and
the delay (at most one poll) is far inside the seconds kept after a fault.
"""

from collections import deque
from collections.abc import Callable

from .diagnostic_statuses import PARSER_FAILURES
from ..device.status import DeviceStatus, State

#: Corrupted packets (checksum or length failures) within CORRUPT_WINDOW s that make a
#: burst: one now and then is the radio's normal life, not a fault worth a file.
CORRUPT_BURST = 3
CORRUPT_WINDOW = 2.0
#: States in which the stream was up: leaving them for DISCONNECTED is a disconnect.
_RUNNING = (State.STREAMING, State.STALLED, State.PAUSED)
#: States in which a NACK refused a command the driver needed (not one of the bring-up's
#: tries, which a sensor that is still waking up may refuse).
_SERVING = (State.STREAMING, State.PAUSED)


class FaultWatch:
    """
    Tell the faults of one sensor since the last :meth:`look`.

    ``status`` returns the supervisor's snapshot, ``resets`` the device
    resets counted so far; ``prefix`` goes before each cause (a sensor's
    name, with several). The first look only takes the counters as they are.
    """

    def __init__(self, status: Callable[[], DeviceStatus], resets: Callable[[], int],
                 prefix: str = '') -> None:
        self._status = status
        self._resets = resets
        self._prefix = prefix
        self._last: tuple[DeviceStatus, int] | None = None
        #: (monotonic time, corrupted so far) of the looks within CORRUPT_WINDOW.
        self._corrupt: deque[tuple[float, int]] = deque()

    def look(self, now: float) -> list[str]:
        """Return the causes seen since the one before, ``now`` in monotonic seconds."""
        device, resets = self._status(), self._resets()
        bad = sum(device.parser.get(key, 0) for key in PARSER_FAILURES)  # corrupted packets
        self._corrupt.append((now, bad))
        while now - self._corrupt[0][0] > CORRUPT_WINDOW:
            self._corrupt.popleft()
        last, self._last = self._last, (device, resets)
        if last is None:
            return []
        before, resets_before = last
        burst = bad - self._corrupt[0][1] >= CORRUPT_BURST
        if burst:
            self._corrupt.clear()  # the burst is told; the next one counts afresh
            self._corrupt.append((now, bad))
        seen = {'stall': device.stalls > before.stalls,
                'disconnect': device.reconnects > before.reconnects or (
                    device.state is State.DISCONNECTED and before.state in _RUNNING),
                'device_reset': resets > resets_before,
                'corrupt': burst,
                'refused': device.parser.get('nacks', 0) > before.parser.get('nacks', 0)
                and before.state in _SERVING}
        return [self._prefix + cause for cause, happened in seen.items() if happened]
