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
The sensor's power: off, on again from power-up, or a power cycle in between.

Power lost takes what the sensor had not yet sent with it; power back
starts it as from power-up (timer, EEPROM rate and auto-start). Each
change of stream is recorded in the ground truth.
"""

import collections.abc
import threading
import time

from i3dmgx2_driver.codec.timer import TIMER_MODULUS

from .faults import FaultState
from .ground_truth import GroundTruth
from .sensor import SimulatedSensor
from .transmitter import Transmitter

#: Runs an action on the simulator's reader thread after a delay (s).
Post = collections.abc.Callable[[float, collections.abc.Callable[[], None]], None]


class SensorPower:
    """
    Switches the sensor off and on; each method takes the simulator's lock.

    ``wake`` is a condition on that lock, notified when the sensor may stream
    again; ``post`` schedules the power-up after a power cycle's dark time.
    """

    def __init__(self, sensor: SimulatedSensor, tx: Transmitter, record: GroundTruth,
                 wake: threading.Condition, faults: FaultState, post: Post) -> None:
        self._sensor = sensor
        self._tx = tx
        self._record = record
        self._wake = wake
        self._faults = faults
        self._post = post

    def off(self) -> float:
        """Lose power now: the stream stops, the queue is forgotten; return the time."""
        with self._wake:
            self._tx.clear()
            self._sensor.power_off()
            now = time.time()
            self._record.note_streaming(now, self._sensor.streaming)
            return now

    def on(self, timer_start: int | None = None) -> None:
        """
        Power up now, the timer at ``timer_start`` (None: the sensor's own, kept from now).

        What was queued before is gone (a power cycle's old queue included).
        """
        with self._wake:
            self._tx.clear()
            self._sensor.power_up(time.time(), timer_start)
            self._record.note_streaming(time.time(), self._sensor.streaming)
            self._wake.notify_all()

    def cycle(self, off_seconds: float, timer_start: int | None) -> None:
        """Go dark for ``off_seconds`` (silent both ways), then power up (see PtySimulator)."""
        if timer_start is not None and not 0 <= timer_start < TIMER_MODULUS:
            raise ValueError(f'timer_start must be a uint32, got {timer_start!r}')
        if off_seconds < 0:
            raise ValueError(f'off_seconds must not be negative, got {off_seconds!r}')
        if off_seconds == 0:
            self.on(timer_start)
            return
        with self._wake:
            now = self.off()
            self._faults.stall(now, off_seconds)
        self._post(off_seconds, lambda: self.on(timer_start))
