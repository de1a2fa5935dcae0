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
The dialogue with one sensor over an open link: what to say, in which order.

Quiet any stream, ping, make a couple of polled requests, read the identity,
set the data rate (the one EEPROM write the driver makes), start continuous
mode until records actually arrive, resume a known sensor after a reconnect
with one serial-number read, and lend the sensor to a service for an
exclusive operation. Each request is retried a few times because the radio
loses commands both ways; that is part of speaking to this device. What to
do when the dialogue fails (reopen, back off, give up) is not: the
recovery loop (recovery.py) and the lifecycle phases (supervisor.py) decide
that, and drive this object through the start-up steps (startup.py). It has
no thread and starts none; it can be tested with a link and a simulator alone.

What it learns (identity, divider, whether the ping was answered, the line's
use) it keeps as attributes for the supervisor's status snapshot. Each phase
lives in a module of its own: who answers and what it is
(``identification.py``), the data rate and its EEPROM write
(``rate_setting.py``), continuous mode and the resume (``continuous.py``);
this class says in which order, and is what the callers hold.
"""

from collections.abc import Callable
import threading
import time
from typing import Any

from .continuous import ContinuousMode
from .dialogue_parts import DialogueParts, Warn
from .identification import Identification
from .identity import DeviceInfo
from .link import DeviceLink
from .rate_setting import RateSetting
from .settings import DeviceConfig
from ..forwarding import Forwarded


class SensorDialogue:
    """
    Speak to the sensor at ``config.address`` through whatever link is open.

    ``log`` has ``debug/info/warning/error``; ``warn`` says a problem once
    per key and period; ``cancel`` set makes the waits give up (the driver
    is stopping or pausing the stream).
    """

    def __init__(self, config: DeviceConfig, log: Any, warn: Warn,
                 cancel: threading.Event) -> None:
        self.config = config
        parts = DialogueParts(config, log, warn, cancel)
        #: Who answers and what it is (ping, polled requests, identity).
        self.identification = Identification(parts)
        #: The data-rate divider, its EEPROM write, the line's use.
        self.rate = RateSetting(parts)
        #: Starting and resuming the stream.
        self.continuous = ContinuousMode(parts, self.identification, self.rate)

    # -- what it learned (the supervisor's status snapshot) ------------------------------

    info: 'DeviceInfo | None' = Forwarded('identification', "The device's identity, once read.")

    ping_ok: 'bool | None' = Forwarded(
        'identification',
        "Whether the base station's ping was answered (None: wired, or not asked).")

    divider: 'int | None' = Forwarded('rate', 'The data-rate divider, once known.')

    eeprom_writes: 'int' = Forwarded(
        'rate', "The EEPROM write commands sent (the divider's cell; each may wear it).")

    line_use: 'str' = Forwarded(
        'rate', "The stream's use of the line at the device's rate ('' while unknown).")

    line_warning: 'str' = Forwarded(
        'rate', "What to do when the stream does not fit the line ('' when it fits).")

    expected_rate_hz: 'float | None' = Forwarded('rate', 'The rate the divider gives, once known.')

    period: 'float' = Forwarded(
        'rate', 'The time between samples (s), or 10 ms while the rate is unknown.')

    # -- quiet --------------------------------------------------------------------------

    def quiet(self, link: DeviceLink) -> None:
        """Stop the device's stream and drop what is in flight (raises PortError)."""
        if not link.running.is_set():
            link.flush_input()
        link.stop_streaming()
        link.streamed = None  # a polled record is a reply only now
        time.sleep(0.05)
        link.flush_input()

    # -- bring-up -----------------------------------------------------------------------

    def initialise(self, link: DeviceLink, require_answer: bool = False,
                   observed: Callable[[], str] = str) -> None:
        """
        Learn what the (quiet, read) device is; set the rate if asked; no stream.

        ``require_answer``: raise DeviceTimeout at once if the device answered
        neither the ping nor the polled requests, rather than going on to
        time out on every later request (a configure transition must fail
        soon, with the reason; the plain node just retries). ``observed()``
        says what the line carried meanwhile, for that message.
        """
        self.identification.introduce(link, require_answer, observed)
        self.rate.configure(link)
        self.rate.check_line()

    # -- streaming (continuous.py) ------------------------------------------------------

    def start_continuous(self, link: DeviceLink) -> bool:
        """Ask for continuous mode until records arrive (:meth:`.ContinuousMode.start`)."""
        return self.continuous.start(link)

    def announce_streaming(self) -> None:
        """Say that records flow: called only once one has arrived on this link."""
        self.continuous.announce()

    def resume(self, link: DeviceLink) -> bool:
        """Confirm the known sensor is back; keep it streaming (:meth:`.ContinuousMode.resume`)."""
        return self.continuous.resume(link)

    def expect_stream(self, link: DeviceLink) -> None:
        """Drop what is in flight; count records of the stream as samples from the first."""
        self.continuous.expect_stream(link)

    def can_resume(self) -> bool:
        """Whether a reconnect may try :meth:`resume` (a known sensor, and allowed to)."""
        return self.continuous.can_resume()

    # -- exclusive operations -----------------------------------------------------------

    def run_exclusive(self, link: DeviceLink, operation: Callable[[DeviceLink], Any]) -> Any:
        """
        Stop the stream and run ``operation(link)``; the caller starts the stream again.

        For services that need the device's full attention (gyro bias
        capture, built-in test). Raises PortError or DeviceTimeout.
        """
        link.stop_streaming()
        # Paused, a polled record of the streamed code (a self test's 0xC2, with
        # the built-in test skewing it) is a reply only, never a sample.
        link.streamed = None
        time.sleep(0.05)
        return operation(link)
