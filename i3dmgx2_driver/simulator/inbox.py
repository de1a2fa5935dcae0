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
The sensor's inbox: a command that reached it, through the firmware's quirks, to the model.

Before ``SimulatedSensor.handle`` sees a command, the firmware's quirks may
swallow it (``FaultConfig.ignore_first_continuous``, ``needs_polled_first``);
after, its replies are queued on the transmitter and a change of stream is
recorded.
"""

import threading

from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.commands import Command

from .faults import FaultState
from .ground_truth import GroundTruth
from .sensor import SimulatedSensor
from .transmitter import Transmitter


class SensorInbox:
    """
    Hands each command that reached the sensor to it; call with the simulator's lock held.

    ``wake`` (a condition on that lock) is notified when the sensor has
    something new to send.
    """

    def __init__(self, sensor: SimulatedSensor, record: GroundTruth, tx: Transmitter,
                 wake: threading.Condition, faults: FaultState) -> None:
        self._sensor = sensor
        self._record = record
        self._tx = tx
        self._wake = wake
        self._faults = faults
        #: Whether a polled request came since the host opened the port.
        self._polled_since_open = False
        #: Whether the next request to stream is ignored (a quirk, armed by the faults).
        self.ignore_next_continuous = faults.config.ignore_first_continuous

    def port_opened(self) -> None:
        """Note that the host opened the port (or flushed its input)."""
        self._polled_since_open = False

    def deliver(self, command: Command | None, raw: bytes, now: float) -> str:
        """Hand a command to the sensor; return the outcome ('delivered' or 'ignored')."""
        sensor = self._sensor
        if command is None:
            sensor.handle(raw, now)
            return 'ignored'
        self._record.commands.append((now, command))
        if command.code == lay.SET_CONTINUOUS and command.args[0] != 0:
            if self.ignore_next_continuous:
                self.ignore_next_continuous = False
                return 'ignored'
            if self._faults.config.needs_polled_first and not self._polled_since_open:
                return 'ignored'
        elif command.code not in (lay.SET_CONTINUOUS, lay.STOP_CONTINUOUS):
            self._polled_since_open = True
        ignored_before = sensor.ignored
        for reply in sensor.handle(command, now):
            self._tx.enqueue(reply, 'reply', sensor.address)
        self._record.note_streaming(now, sensor.streaming)
        self._wake.notify_all()
        return 'ignored' if sensor.ignored != ignored_before else 'delivered'
