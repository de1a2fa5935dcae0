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
The radio's link quality as the sensor's packets report it.

Every wireless data packet carries the base station's LQI and RSSI; what
diagnostics shows (latest, lowest, mean) is kept here, apart from the stream
bookkeeping that feeds it, so that changing what is summed changes one
small class.
"""

from typing import NamedTuple


class RadioStats(NamedTuple):
    """Latest, lowest and mean LQI and RSSI of the packets received."""

    lqi: int
    rssi: int
    lqi_min: int
    rssi_min: int
    lqi_mean: float
    rssi_mean: float


class RadioQuality:
    """Sum the LQI and RSSI of each packet in the reader thread; summarise on demand."""

    def __init__(self) -> None:
        #: Latest LQI and RSSI, their lowest, their sums and the packets counted.
        self._radio: list[int] = [0, 0, 255, 255, 0, 0, 0]

    def note(self, lqi: int, rssi: int) -> None:
        """Count one packet's link quality (reader thread: no lock, no allocation)."""
        radio = self._radio
        radio[0], radio[1] = lqi, rssi
        radio[2] = min(radio[2], lqi)
        radio[3] = min(radio[3], rssi)
        radio[4] += lqi
        radio[5] += rssi
        radio[6] += 1

    @property
    def stats(self) -> RadioStats | None:
        """Radio link quality so far, or None before the first packet."""
        r = self._radio
        if not r[6]:
            return None
        return RadioStats(r[0], r[1], r[2], r[3], r[4] / r[6], r[5] / r[6])
