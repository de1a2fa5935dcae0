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
What a test may ask of a running simulation: the ground truth, copied, and waits on it.

``TruthQueries`` is the read side of ``GroundTruth``: every answer is a
copy taken under the simulator's lock, so a caller can keep it while the
simulation runs on, and every wait wakes on each new entry.
"""

import collections.abc
import threading
import time

from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.commands import Command

from .ground_truth import GroundTruth, HostCommand, SentRecord, SimulatorStats


class TruthQueries:
    """
    The ground truth as copies, and waits until it shows something; thread-safe.

    The simulator's observation surface: its users are the tests, the harness and
    the benchmarks (the package itself reads only ``stats``, for the command
    line), so that they all ask the ground truth one way and none reads it
    unlocked. ``changed`` is a condition on the simulator's lock, notified on
    every new entry.
    """

    def __init__(self, record: GroundTruth, changed: threading.Condition) -> None:
        self._record = record
        self._changed = changed

    @property
    def truth(self) -> list[SentRecord]:
        """Every data packet produced so far, in order (a copy)."""
        with self._changed:
            truth = self._record.truth
            return list(truth) if truth is not None else []

    @property
    def commands(self) -> list[tuple[float, Command]]:
        """(time, command) of every command the sensor received (a copy)."""
        with self._changed:
            return list(self._record.commands)

    @property
    def host_log(self) -> list[HostCommand]:
        """Everything the host sent, with what became of it (a copy)."""
        with self._changed:
            return list(self._record.host_log)

    @property
    def stats(self) -> SimulatorStats:
        """Return a snapshot of the counters."""
        with self._changed:
            return self._record.stats.copy()

    @property
    def stream_changes(self) -> list[tuple[float, int]]:
        """
        (time, command byte or 0) each time the sensor's stream changed (a copy).

        The first entry is the power-up state. A start, stop or change of
        stream (0xC4, 0xFA, power cycle, unplugging a wired sensor) adds one;
        asking for the record already streamed adds none. A test proves that
        an interrupted stream was restarted by finding a 0 followed by a code.
        """
        with self._changed:
            return list(self._record.stream_changes)

    def commands_of(self, *codes: int) -> list[tuple[float, Command]]:
        """(time, command) of the commands with these command bytes the sensor received."""
        with self._changed:
            return [entry for entry in self._record.commands if entry[1].code in codes]

    def eeprom_writes(self) -> list[tuple[float, Command]]:
        """
        Every EEPROM write (0xE4) the sensor received, whether or not it stored it.

        Empty proves that nothing was written to the EEPROM. (A write the radio
        lost never reached the sensor; ``host_log`` still shows it was sent.)
        """
        return self.commands_of(lay.WRITE_EEPROM)

    def wait_until(self, condition: collections.abc.Callable[[], bool],
                   timeout: float = 5.0) -> bool:
        """Wait until ``condition()`` is true (checked on every change); return it."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                if condition():
                    return True
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._changed.wait(min(remaining, 0.05))
