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
Lend the streaming sensor to a service for an operation that needs it alone.

A gyro bias capture or a built-in test runs in a service's executor thread
while the recovery thread watches the stream. For their duration the stream
is stopped on purpose, so three others must know: the watch must not take
the silence for a stall (it skips its look while :attr:`ExclusiveAccess.paused`
is set), the line observer must not report it (it is paused), and diagnostics
say PAUSED. Afterwards the stream is asked for again, whatever the operation
did. Which bytes stop the stream is the dialogue's; this is only the lending.
"""

from collections.abc import Callable
import threading
from typing import Any

from .connection import Connection
from .dialogue import SensorDialogue
from .link import DeviceLink, DeviceTimeout
from .report import DeviceReport
from .startup import StartUp
from .status import State


class ExclusiveAccess:
    """Run one operation at a time on the link with the stream stopped."""

    def __init__(self, connection: Connection, dialogue: SensorDialogue, startup: StartUp,
                 report: DeviceReport, cancel: threading.Event) -> None:
        self._connection = connection
        self._dialogue = dialogue
        self._startup = startup
        self._report = report
        self._cancel = cancel
        #: Set while an operation has the sensor: the stream is quiet on purpose.
        self.paused = threading.Event()

    def run(self, operation: Callable[[DeviceLink], Any]) -> Any:
        """
        Stop the stream, run ``operation(link)``, then restart the stream.

        Raises DeviceTimeout at once unless the device streams (or has
        stalled); PortError or DeviceTimeout from the operation or the restart.
        """
        link = self._connection.link
        state = self._report.state
        if link is None or state not in (State.STREAMING, State.STALLED):
            raise DeviceTimeout(f'device not streaming (state: {state.value})')
        self.paused.set()
        self._report.enter(State.PAUSED)
        self._connection.observe(False)  # a long operation (a 30 s bias capture) is quiet
        try:
            return self._dialogue.run_exclusive(link, operation)
        finally:
            try:
                self._connection.observe(True)
                if not self._cancel.is_set():
                    self._startup.restart_stream(link)
            finally:
                self.paused.clear()
