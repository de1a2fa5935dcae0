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
Keep the device streaming for the life of the driver, plain or managed.

:class:`DeviceSupervisor` is what the node holds: it builds the pieces of
the device side and offers them as the node needs them. The pieces, each in
a module of its own:

- ``dialogue.py``: :class:`~.dialogue.SensorDialogue`, what to say to the
  sensor (quiet, identity, rate, continuous mode, resume; each phase in a
  module of its own); no thread.
- ``connection.py``: :class:`~.connection.Connection`, the one open link,
  opened and closed safely from any thread, counted across reconnects.
- ``startup.py``: :class:`~.startup.StartUp`, the steps from an open port
  to a stream, shared by the thread and the phases.
- ``recovery.py``: :class:`~.recovery.RecoveryLoop`, the supervisor thread
  (stalls, unplugs, back-off), with its policies in ``watchdog.py``.
- ``exclusive.py``: :class:`~.exclusive.ExclusiveAccess`, the sensor lent
  to a service with the stream stopped.
- ``report.py``: :class:`~.report.DeviceReport`, the state and counters,
  changed in one place each; :meth:`DeviceSupervisor.status` makes the one
  immutable snapshot (``status.py``) that diagnostics and services read.

The plain node's :meth:`~DeviceSupervisor.start` runs the whole bring-up in
the thread, retrying forever instead of failing. A managed (lifecycle) node
must know at each step whether it worked, so the same steps are offered as
phases: :meth:`~DeviceSupervisor.connect` (port, quiet, identity, rate; no
stream), :meth:`~DeviceSupervisor.start_streaming` (the stream, then the
thread that keeps it going), :meth:`~DeviceSupervisor.stop_streaming` (0xFA,
the port stays open) and :meth:`~DeviceSupervisor.stop` (the port closed).

A reconnect to a sensor already identified is short: what the driver knows
(identity, data-rate divider) is not asked again. One serial-number read
confirms it is the same sensor (the wireless sensor keeps streaming while
the base station is unplugged, so its records usually flow already; if not,
continuous mode is requested). Records are published from the moment they
arrive. Another serial number, or no answer, gets the full dialogue.
Streaming is announced when the first record has arrived, never before.
"""

from collections.abc import Callable
import logging
import threading
from typing import Any

from .connection import Connection
from .dialogue import SensorDialogue
from .exclusive import ExclusiveAccess
from .identity import DeviceInfo
from .link import DeviceLink, DeviceTimeout, RecordCallback
from .port import PortError
from .port_opener import PortParts
from .recovery import RecoveryLoop
from .report import DeviceReport
from .settings import DeviceConfig
from .shared_port import SharedPort
from .startup import StartUp
from .status import DeviceStatus, State
from ..forwarding import Forwarded


class DeviceSupervisor:
    """
    Own the connection to one device for the life of the driver.

    ``on_record`` runs in the reader thread for every streamed record;
    ``on_connect`` runs in the supervisor thread each time a link is made
    (the node checks its clock there). ``log`` is any object with
    ``debug/info/warning/error`` methods (a ``logging.Logger`` by default;
    the node passes its rclpy logger). ``on_fatal`` runs in the supervisor
    thread, once, when the port can never work (``fatal_error`` then holds
    the error; without it the error is logged); the supervisor has stopped
    by then. ``port`` says how the port is opened and whom its reader tells
    (port_opener.py): its
    ``port_factory`` opens the port (SerialPort; a subclass to observe it);
    its ``on_bytes`` runs in the reader thread with every read's raw bytes
    and read time (a raw capture); its ``timings``, if given, is told every
    port open and every link up (right after ``on_connect``) and handed to
    every link, which tells it the read and the parse of each sample
    (hot_path.py). ``shared``, if given, is the port this sensor shares
    with others behind the same base station (shared_port.py): it opens and
    closes the port, and this supervisor keeps only its sensor streaming (a
    supervisor per sensor, each with its own thread).
    """

    def __init__(self, config: DeviceConfig, on_record: RecordCallback,
                 log: Any = None, on_connect: Callable[[], None] | None = None,
                 on_fatal: Callable[[PortError], None] | None = None,
                 port: PortParts | None = None,
                 shared: SharedPort | None = None) -> None:
        self.config = config
        self._shared = shared
        port = port if port is not None else PortParts()
        log = log or logging.getLogger('i3dmgx2_driver')
        #: Set means "no stream wanted now": the thread ends, and every request on the
        #: link gives up within a few tens of milliseconds (the link's ``cancel`` event).
        #: Whoever set it decides what becomes of the port: stop() closes it,
        #: stop_streaming() keeps it.
        self._stop = threading.Event()
        self.report = DeviceReport(log)
        self.connection = Connection(config, log, port, on_record, self.report.finding,
                                     self._stop, shared)
        #: What to say to the sensor; it keeps what it learns (identity, divider).
        self.dialogue = SensorDialogue(config, log, self.report.warn, self._stop)
        timings = port.timings
        self._startup = StartUp(self.connection, self.dialogue, self.report, self._stop,
                                _then(on_connect, timings.connected if timings else None))
        self._exclusive = ExclusiveAccess(self.connection, self.dialogue, self._startup,
                                          self.report, self._stop)
        self.recovery = RecoveryLoop(
            config, self.connection, self._startup, self.report, self._stop,
            self._exclusive.paused, on_fatal or (lambda error: log.error(str(error))))

    # -- what others read ---------------------------------------------------------------

    def status(self) -> DeviceStatus:
        """Return the device side as one snapshot (from any thread)."""
        dialogue, connection = self.dialogue, self.connection
        link = connection.link
        line_warning = dialogue.line_warning
        if self._shared is not None and dialogue.divider and not line_warning:
            line_warning = self._shared.line_warning(self.config.address, self.config.stream,
                                                     dialogue.expected_rate_hz)
        return DeviceStatus(
            **self.report.fields(), connections=connection.connections,
            reconnects=connection.reconnects, low_latency_state=connection.low_latency_state,
            parser=connection.parser_stats(), radio=link.radio if link is not None else None,
            connected=link is not None, ping_ok=dialogue.ping_ok, info=dialogue.info,
            divider=dialogue.divider, expected_rate_hz=dialogue.expected_rate_hz,
            eeprom_writes=dialogue.eeprom_writes, line_use=dialogue.line_use,
            line_warning=line_warning, strays=connection.strays())

    state: 'State' = Forwarded('report', 'What the supervisor is doing now.')

    fatal_error: 'PortError | None' = Forwarded(
        'report', 'Why the port can never work, once found (None otherwise).')

    link: 'DeviceLink | None' = Forwarded(
        'connection', 'The current link, or None while disconnected.')

    def streaming_link(self) -> DeviceLink | None:
        """Return the link while the device streams (a poll may share it), else None."""
        link = self.connection.link
        return link if link is not None and self.report.state is State.STREAMING else None

    info: 'DeviceInfo | None' = Forwarded('dialogue', "The device's identity, once read.")

    divider: 'int | None' = Forwarded('dialogue', 'The data-rate divider, once known.')

    expected_rate_hz: 'float | None' = Forwarded(
        'dialogue', 'The rate the divider gives, once known.')

    # -- the plain node: one thread for everything ----------------------------------------

    def start(self) -> None:
        """Start the supervisor thread: open, initialise, stream, recover, forever."""
        self._stop.clear()
        self.recovery.start(self.connection.link)

    def stop(self, timeout: float = 1.5) -> None:
        """Stop streaming (0xFA), stop the threads, close the port."""
        self._stop.set()
        self.connection.abort()
        self.recovery.join(timeout)
        self.connection.release(send_stop=True)
        self.report.enter(State.STOPPED)

    # -- the managed node: one phase per transition ----------------------------------------

    def connect(self) -> None:
        """
        Open the port and bring the device to a known state, without streaming.

        The configure phase of a managed node: open the port exclusively,
        quiet any stream, ping, make the polled requests, read the identity
        and set the data rate if asked. Raises PortError (missing, busy,
        denied: the port is not open) or DeviceTimeout (the device is silent
        or refused the rate: the port is closed again) with a message that
        says why. Bounded: a silent device is given up after the ping and
        the polled requests (about 3 s), a talking one answers in well under
        a second.
        """
        self._stop.clear()
        link = self.connection.open_link()
        try:
            self._startup.initialise(link, require_answer=True)
        except BaseException:
            self.connection.release()
            self.report.enter(State.STOPPED)
            raise
        self.report.enter(State.READY)
        self.connection.observe(False)

    def start_streaming(self) -> None:
        """
        Start the stream now, then keep it going in the supervisor thread.

        The activate phase of a managed node: returns once records arrive,
        raises DeviceTimeout or PortError if they do not (the port stays
        open unless it is gone). A link lost since :meth:`connect` is reopened
        and initialised first. From then on stalls and unplugs are recovered
        as :meth:`start` recovers them.
        """
        if self.recovery.running:
            raise DeviceTimeout('the supervisor is still stopping: try again')
        self._stop.clear()
        self.connection.observe(True)
        link = self.connection.link
        try:
            if self.connection.lost():
                self.connection.release()
                link = self.connection.open_link()
                self._startup.initialise(link)
            self._startup.begin_stream(link)
        except PortError:
            self.connection.release()
            self.report.enter(State.DISCONNECTED)
            raise
        except DeviceTimeout:
            if self.connection.link is not None:
                self._startup.quiet(self.connection.link)
            raise
        if self._stop.is_set():
            # stop() came while the stream was starting: it has the port; no thread.
            raise DeviceTimeout('the driver stopped while the stream was starting')
        self.recovery.start(link)

    def start_retrying(self) -> None:
        """
        Let go of any link and keep trying in the supervisor thread, as :meth:`start` does.

        For a managed node with several sensors: one that did not answer at
        configure or activate is retried in the background (it may be
        switched on later) while the others stream.
        """
        self.connection.release()
        self.report.enter(State.DISCONNECTED)
        self.start()

    def stop_streaming(self, timeout: float = 1.5) -> None:
        """
        Stop the stream (0xFA) and the supervisor thread; keep the port open.

        The deactivate phase of a managed node. If the port was lost while
        streaming it stays closed (DISCONNECTED) until the next start.
        """
        self._stop.set()
        self.recovery.join(timeout)
        link = self.connection.link
        if link is not None and not link.disconnected.is_set():
            self._startup.quiet(link)

    # -- for services ---------------------------------------------------------------------

    def run_paused(self, operation: Callable[[DeviceLink], Any]) -> Any:
        """
        Stop the stream, run ``operation(link)``, then restart the stream.

        Used by services that need the device's full attention (gyro bias
        capture, built-in test). Raises PortError or DeviceTimeout.
        """
        return self._exclusive.run(operation)


def _then(first: Callable[[], None] | None,
          second: Callable[[], None] | None) -> Callable[[], None] | None:
    """Return a callable that calls ``first`` then ``second`` (either may be None)."""
    if first is None or second is None:
        return first or second

    def both() -> None:
        first()
        second()
    return both
