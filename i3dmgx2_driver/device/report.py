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
What the supervisor is doing, said in the log and kept for the snapshot.

The recovery thread, the lifecycle phases, the reader thread (through the
line observer) and a service's exclusive operation all change what
diagnostics show: the state, the counters, the last problem said. Each such
change is one method of :class:`DeviceReport`, so that every rule about it
lives here: the device is declared streaming in one place only
(:meth:`~DeviceReport.streaming`), a problem is logged once per key and
period and kept as the last error (:meth:`~DeviceReport.warn`), and what
the observer found is forgotten once records flow. The supervisor makes
its :class:`~.status.DeviceStatus` from these fields, under the same lock.
"""

import threading
from typing import Any

from .observer import Finding
from .port import PortError
from .status import State
from .throttle import Throttle


class DeviceReport:
    """
    The device side's state and counters, and the one way to change each.

    ``log`` has ``debug/info/warning/error``. Any thread may call any
    method; :meth:`fields` returns them all at one moment.
    """

    def __init__(self, log: Any) -> None:
        self.log = log
        self._throttle = Throttle()
        self._lock = threading.Lock()
        self.state = State.CONNECTING
        self.stalls = 0
        #: The last problem said (a warning's text), '' if none yet.
        self.last_error = ''
        #: What the line observer last found while nothing of ours arrived ('' once
        #: records flow), for diagnostics.
        self.advice = ''
        #: The port can never work (a path that is no serial port): why.
        self.fatal_error: PortError | None = None
        #: How the last connection got streaming: 'full' (the whole dialogue) or 'resumed'.
        self.last_start = ''
        self.resumes = 0

    def enter(self, state: State) -> None:
        """Say what the supervisor does now (never STREAMING: see :meth:`streaming`)."""
        if state is State.STREAMING:
            raise ValueError('streaming is declared by streaming(), once a record arrived')
        self.state = state

    def streaming(self, start: str = '') -> None:
        """
        Declare the device streaming: call only once a record has arrived on this link.

        ``start`` says how a new connection got there ('full' or 'resumed');
        '' for a stream taken up again on the same link (after a stall or an
        exclusive operation). What the observer found is past.
        """
        with self._lock:
            self.state = State.STREAMING
            self.advice = ''
            if start:
                self.last_start = start
                if start == 'resumed':
                    self.resumes += 1

    def stalled(self) -> None:
        """Count a stall: no record for longer than the stall timeout."""
        with self._lock:
            self.stalls += 1
            self.state = State.STALLED

    def records_flow(self) -> None:
        """Forget what the observer found: records flow again."""
        if self.advice:
            self.advice = ''

    def warn(self, key: str, message: str, period: float | None = None) -> None:
        """Log ``message`` once, then again at most every ``period`` s (a reminder)."""
        self.last_error = message
        if self._throttle.allow(key, period):
            self.log.warning(message)

    def finding(self, finding: Finding) -> None:
        """Report what the line observer found (reader thread; never blocks long)."""
        self.advice = finding.message
        self.warn(f'observed {finding.kind}', finding.message)

    def failed(self, error: PortError) -> None:
        """Keep why the port can never work; the supervisor stops."""
        with self._lock:
            self.fatal_error = error
            self.last_error = str(error)
            self.state = State.STOPPED

    def fields(self) -> dict[str, Any]:
        """Return the report's fields at one moment, named as in DeviceStatus."""
        with self._lock:
            return {
                'state': self.state, 'stalls': self.stalls, 'last_error': self.last_error,
                'advice': self.advice, 'last_start': self.last_start, 'resumes': self.resumes,
                'fatal_error': str(self.fatal_error) if self.fatal_error is not None else ''}
