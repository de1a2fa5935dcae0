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
The supervisor thread: keep the stream going through stalls and unplugs.

:class:`RecoveryLoop` owns the one thread that opens the port, has the
start-up steps (startup.py) bring the sensor to streaming, and then watches
the stream. A stall re-requests continuous mode and then reopens the port;
an unplug reopens it every ``reconnect_interval``, forever, and at once when
the port reappears (watchdog.py says when). What goes wrong is said once and
reminded (report.py); a port that can never work ends the loop, and
``on_fatal`` is told, once. The loop decides only when to try again: it knows
no command byte and touches no sample (the link's reader thread publishes).
"""

from collections.abc import Callable
import threading

from .connection import Connection
from .link import DeviceLink, DeviceTimeout
from .port import PortDisconnected, PortError, PortUnusable
from .report import DeviceReport
from .settings import DeviceConfig
from .startup import StartUp
from .status import State
from .throttle import EVENT_PERIOD
from .watchdog import ReopenWait, StallWatch


class RecoveryLoop:
    """
    Run, in a thread of its own, the loop that keeps the device streaming.

    ``cancel`` set ends it (whoever sets it decides what becomes of the
    port); ``paused`` set means the stream is quiet on purpose (an
    exclusive operation); ``on_fatal(error)`` runs in the thread, once, when
    the port can never work.
    """

    def __init__(self, config: DeviceConfig, connection: Connection, startup: StartUp,
                 report: DeviceReport, cancel: threading.Event, paused: threading.Event,
                 on_fatal: Callable[[PortError], None]) -> None:
        self.config = config
        self._connection = connection
        self._startup = startup
        self._report = report
        self._cancel = cancel
        self._paused = paused
        self._on_fatal = on_fatal
        self._reopen_wait = ReopenWait(config.port, config.reconnect_interval,
                                       config.prompt_reopen, cancel.wait)
        self._thread: threading.Thread | None = None

    def start(self, link: DeviceLink | None) -> None:
        """Start the thread on ``link``, one already streaming, or None: it opens one."""
        self._thread = threading.Thread(target=self._run, args=(link,),
                                        name='gx2-supervisor', daemon=True)
        self._thread.start()

    @property
    def running(self) -> bool:
        """Whether the thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def join(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the thread to end; True once it has (or never ran)."""
        if self._thread is not None:
            self._thread.join(timeout)
        return not self.running

    def _run(self, link: DeviceLink | None) -> None:
        """Stream and recover until cancelled."""
        report = self._report
        while not self._cancel.is_set():
            stalled = False
            try:
                if link is None:
                    report.enter(State.CONNECTING)
                    link = self._connection.open_link()
                    if not self._startup.resume(link):
                        self._startup.initialise(link)
                        self._startup.begin_stream(link)
                self._watch(link)
                stalled = True
            except PortUnusable as exc:
                self._fail(exc)
            except (PortError, DeviceTimeout) as exc:
                if not self._cancel.is_set():  # else: cut short on purpose
                    self._say(exc)
            if self._cancel.is_set():
                break  # whoever stopped us decides about the port
            self._connection.release()
            link = None
            report.enter(State.DISCONNECTED)
            if not (stalled and self.config.prompt_reopen):
                self._reopen_wait()  # a port closed for a stall is still there

    def _say(self, exc: PortError | DeviceTimeout) -> None:
        """Say why this attempt failed, and that the loop goes on."""
        if isinstance(exc, DeviceTimeout):
            self._report.warn('timeout', f'device not answering: {exc} (wrong port or '
                                         f'address? ros2 run i3dmgx2_driver discover '
                                         f'finds sensors)')
            return
        # An unplug is an event; a port that stays missing is a condition.
        period = EVENT_PERIOD if isinstance(exc, PortDisconnected) else None
        self._report.warn(type(exc).__name__, f'{exc} (retrying every '
                                              f'{self.config.reconnect_interval:g} s)', period)

    def _fail(self, exc: PortUnusable) -> None:
        """Give up for good: keep why, stop, and let the entry point say it and exit."""
        self._report.failed(exc)
        self._cancel.set()
        self._on_fatal(exc)

    def _watch(self, link: DeviceLink) -> None:
        """Return when the link is lost or cannot be revived; recover stalls."""
        report = self._report
        watch = StallWatch(self.config.stall_timeout, self._startup.period)
        while not self._cancel.wait(watch.tick):
            if link.disconnected.is_set():
                raise PortDisconnected(link.error or 'device disconnected')
            if self._paused.is_set():
                continue
            if not watch.stalled(link.last_data_mono):
                report.records_flow()  # what was observed is past
                continue
            report.stalled()
            report.warn('stall', f'no data for {watch.stall_after:.1f} s: re-requesting '
                                 f'continuous mode', EVENT_PERIOD)
            try:
                resumed = self._startup.restart_stream(link)
            except DeviceTimeout:
                report.warn('stall', 'stream did not resume: reopening the port', EVENT_PERIOD)
                return
            if resumed:
                report.log.info('stream resumed')
