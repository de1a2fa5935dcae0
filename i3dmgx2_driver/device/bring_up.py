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
The supervisor's steps from an open port to a stream, each moving the report's state.

The supervisor thread and the managed node's phases take the same steps in
different orders and with different answers to failure: the thread retries
forever, a phase fails with the reason. Each step (initialise, resume,
begin the stream, take it up again, quiet it) has the dialogue say what to
say, starts the reader when needed (letting the consumer re-anchor before a
new link's first record) and moves the report's state, so that the thread
and the phases cannot tell a different story about the same step.
"""

from collections.abc import Callable
import threading
from typing import Any

from . import timeouts
from .current_link import CurrentLink
from .dialogue import SensorDialogue
from .link import DeviceLink
from .port import PortError
from .realtime import PolicyOutcome
from .status import DeviceReport, State
from ..codec.data_rate import ticks_per_cycle


class BringUp:
    """
    Take one step on a link, saying what it is in the report.

    ``on_connect`` runs before a new link's first record reaches the
    consumer (the node re-anchors its clock there). ``on_stream_known`` is
    handed what the record path needs of what the dialogue learned, before
    the stream's records come: the timer ticks between two records (None
    while the divider is unknown) and whether a gyro bias is kept and
    written back after a power cycle. ``cancel`` is the supervisor's, read
    only: a resume cut short by it is not announced.
    """

    def __init__(self, dialogue: SensorDialogue, report: DeviceReport, current: CurrentLink,
                 cancel: threading.Event, on_connect: Callable[[], None] | None,
                 log: Any,
                 on_stream_known: Callable[[int | None, bool], None] | None = None) -> None:
        self._dialogue = dialogue
        self._report = report
        self._current = current
        self._cancel = cancel
        self._on_connect = on_connect
        self._on_stream_known = on_stream_known
        self._log = log
        self._policy_logged = PolicyOutcome()

    def initialise(self, link: DeviceLink, require_answer: bool = False) -> None:
        """Quiet the device, start reading, and have the dialogue learn what it is."""
        self._report.enter(State.INITIALISING)
        self._dialogue.quiet(link)
        if link.running.is_set():
            # The reader runs already (a resume that was not confirmed): anchor afresh.
            self._anchor()
        else:
            self._start_reader(link)
        self._dialogue.initialise(link, require_answer, self._current.observed)
        self._hand_on()

    def resume(self, link: DeviceLink) -> bool:
        """
        Resume a known sensor after a reconnect, or return False for the full dialogue.

        Returns False, with nothing done or the reader running, when the
        driver knows no sensor yet (or must not resume), or when the sensor
        does not answer or another serial number does.
        """
        dialogue = self._dialogue
        if not dialogue.can_resume():
            return False
        self._report.enter(State.INITIALISING)
        dialogue.expect_stream(link)
        self._hand_on()
        self._start_reader(link)
        if not dialogue.resume(link):
            return False
        if not self._cancel.is_set():
            self._report.streaming('resumed')
        return True

    def begin_stream(self, link: DeviceLink) -> None:
        """Start continuous mode on an initialised link; announce it once records arrive."""
        if self._dialogue.start_continuous(link):
            self._report.streaming('full')
            self._dialogue.announce_streaming()

    def restart_stream(self, link: DeviceLink) -> bool:
        """
        Ask for the stream again on the same link (after a stall or a pause).

        True once records arrive again, False if cancelled first; raises
        DeviceTimeout when none comes, PortDisconnected if the port goes.
        """
        self._hand_on()  # a capture in the pause may have given a bias to keep
        if not self._dialogue.start_continuous(link):
            return False
        self._report.streaming()
        return True

    def quiet(self, link: DeviceLink) -> None:
        """Stop the device's stream and drop what is in flight: READY, or DISCONNECTED."""
        try:
            self._dialogue.quiet(link)
            self._report.enter(State.READY)
            self._current.observe(False)
        except PortError as exc:
            self._report.warn(type(exc).__name__, str(exc))
            self._current.release()
            self._report.enter(State.DISCONNECTED)

    def _hand_on(self) -> None:
        """Hand the record path the tick step and the bias flag the dialogue knows now."""
        if self._on_stream_known is not None:
            divider = self._dialogue.divider
            self._on_stream_known(ticks_per_cycle(divider) if divider else None,
                                  self._dialogue.gyro_bias is not None)

    def _anchor(self) -> None:
        """Let the consumer re-anchor before the first record of a new link reaches it."""
        if self._on_connect is not None:
            self._on_connect()

    def _start_reader(self, link: DeviceLink) -> None:
        """Anchor the consumer, start the reader thread; log its scheduling when it changes."""
        self._anchor()
        link.start()
        if not link.running.wait(timeouts.READER_START_WAIT_S):
            return
        outcome = link.policy_outcome
        if outcome != self._policy_logged:
            self._policy_logged = outcome
            if outcome.applied:
                self._log.info(f'reader thread: {", ".join(outcome.applied)}')
            for refusal in outcome.refused:
                self._log.warning(refusal)
