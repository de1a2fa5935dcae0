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
The cable between the port and the host: unplugged, the port is gone; plugged, it is back.

The pty closes (the host's reads and writes fail), the symlink goes, and a
new pty appears at the same path when it is plugged back in. A wireless
sensor keeps running meanwhile, behind its base station; a wired one is fed
by the cable: it goes dark with the port and starts from power-up when the
cable is back.
"""

import threading

from .ground_truth import GroundTruth
from .host_reader import HostReader
from .power import SensorPower
from .pty_port import PtyPort


class Cable:
    """
    Unplugs and replugs the port; its actions run on the reader thread (posted there).

    ``changed`` is a condition on the simulator's lock, notified when the
    port is back. ``power`` is the wired sensor's power, which the cable
    carries (None: wireless, the base station's cable feeds no sensor).
    """

    def __init__(self, port: PtyPort, reader: HostReader, record: GroundTruth,
                 changed: threading.Condition, power: SensorPower | None,
                 stop: threading.Event) -> None:
        self._port = port
        self._reader = reader
        self._record = record
        self._changed = changed
        self._power = power
        self._stop = stop

    def unplug(self, seconds: float | None) -> None:
        """Pull the cable now; plug it back in after ``seconds`` (None: never by itself)."""
        if self._port.master is None:
            return
        with self._changed:
            self._record.count(unplugs=1)
            if self._power is not None:
                # The cable feeds a wired sensor: it goes dark with the port
                # (first, so that whoever sees the port gone sees it off too).
                self._power.off()
        self._port.pull_out()
        if seconds is not None:
            self._reader.post(seconds, self.replug)

    def replug(self) -> None:
        """Plug the cable back in (if unplugged and still running)."""
        if self._port.master is None and not self._stop.is_set():
            if self._power is not None:
                self._power.on()
            self._reader.plug_in()
            with self._changed:
                self._changed.notify_all()
