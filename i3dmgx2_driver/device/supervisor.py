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

:class:`DeviceSupervisor` is what the node holds, and it is the one place
that decides about the connection: it holds the one open link, takes the
start-up steps on it, runs the thread that keeps the stream going and lends
the sensor to a service. What it builds on, each read and tested alone:

- ``dialogue.py``: :class:`~.dialogue.SensorDialogue`, what to say to the
  sensor (quiet, identity, rate, continuous mode, resume); no thread.
- ``link.py``: :class:`~.link.DeviceLink`, one open port and its reader.
- ``watchdog.py``: when a stream has stalled and when to try the port again
  (the reconnect back-off), decided on a clock passed in.
- ``status.py``: :class:`~.status.DeviceReport`, the state and counters,
  changed in one place each; :meth:`DeviceSupervisor.status` makes the one
  immutable :class:`~.status.DeviceStatus` that diagnostics and services read.

**The link.** The supervisor thread opens links; a lifecycle phase or
:meth:`~DeviceSupervisor.stop` on another thread may close the current one
at any moment, even while a new one is being opened. A lock decides who owns
the link, and a link opened after the driver was told to stop is closed at
once. Every link is made the same way (its line observer, the cancel event,
the reader thread's scheduling); what outlives a link is kept here: how many
were opened, the parser counters and the records that were not the
stream's (each link's ``other_records``) summed over all of them, what the port
granted of low-latency mode and the reader of its scheduling (each logged
when it changes, not at every reconnect).

**The start-up steps.** The thread and the lifecycle phases take the same
steps in different orders and with different answers to failure: the thread
retries forever, a phase fails with the reason. Each step (initialise,
resume, begin the stream, take it up again, quiet it) has the dialogue say
what to say, starts the reader when needed (letting the consumer re-anchor
before a new link's first record) and moves the report's state, so that the
thread and the phases cannot tell a different story about the same step.

**The thread.** The plain node's :meth:`~DeviceSupervisor.start` runs the
whole bring-up in the ``gx2-supervisor`` thread, retrying forever instead of
failing, then watches the stream. A stall re-requests continuous mode and
then reopens the port; an unplug reopens it after the back-off, forever.
What goes wrong is said once and reminded; a port that can never work ends
the thread, and ``on_fatal`` is told, once. The thread decides only when to
try again: it knows no command byte and touches no sample (the link's
reader thread publishes).

A managed (lifecycle) node must know at each step whether it worked, so the
same steps are offered as phases: :meth:`~DeviceSupervisor.connect` (port,
quiet, identity, rate; no stream), :meth:`~DeviceSupervisor.start_streaming`
(the stream, then the thread that keeps it going),
:meth:`~DeviceSupervisor.stop_streaming` (0xFA, the port stays open) and
:meth:`~DeviceSupervisor.stop` (the port closed).

A reconnect to a sensor already identified is short: what the driver knows
(identity, data-rate divider) is not asked again. One serial-number read
confirms it is the same sensor (the wireless sensor keeps streaming while
the base station is unplugged, so its records usually flow already; if not,
continuous mode is requested). Records are published from the moment they
arrive. Another serial number, or no answer, gets the full dialogue.
Streaming is announced when the first record has arrived, never before.

**Exclusive use.** A gyro bias capture or a built-in test runs in a
service's executor thread while the supervisor thread watches the stream.
For their duration the stream is stopped on purpose, so three others must
know: the watch must not take the silence for a stall (it skips its look
while ``_paused`` is set), the line observer must not report it (it is
paused), and diagnostics say PAUSED. Afterwards the stream is asked for
again, whatever the operation did. Which bytes stop the stream is the
dialogue's; this is only the lending.

**Cancelling** is this class's alone: its ``_cancel`` event, set by
:meth:`~DeviceSupervisor.stop`, :meth:`~DeviceSupervisor.stop_streaming` or
a port that can never work, and cleared when a stream is wanted again. The
dialogue, every link and the back-off's wait are handed it to read.
"""

from collections.abc import Callable
import logging
import threading
from typing import Any

from . import timeouts
from .dialogue import SensorDialogue
from .link import BytesCallback, DeviceLink, DeviceTimeout, RecordCallback
from .observer import LineObserver
from .port import PortDisconnected, PortError, PortUnusable
from .port_opener import PortOpener
from .realtime import PolicyOutcome
from .settings import DeviceConfig
from .shared_port import SharedPort
from .status import DeviceReport, DeviceStatus, State
from .throttle import EVENT_PERIOD
from .watchdog import ReopenWait, StallWatch


class DeviceSupervisor:
    """
    Own the connection to one device for the life of the driver.

    The callbacks: ``on_record`` (reader thread, every record of the
    stream), ``on_connect`` (before a new link's first record: the node
    re-anchors its clock), ``on_fatal`` (once, the port can never work;
    default: logged), ``on_bytes`` (reader thread, every read: a raw
    capture), ``on_gyro_bias`` (the kept bias written and echoed). ``log``
    has ``debug/info/warning/error``. ``shared``: the port this sensor
    shares behind one base station (shared_port.py), which opens and closes
    it; no line observer watches it.
    """

    def __init__(self, config: DeviceConfig, on_record: RecordCallback,
                 log: Any = None, on_connect: Callable[[], None] | None = None,
                 on_fatal: Callable[[PortError], None] | None = None,
                 on_bytes: BytesCallback | None = None,
                 shared: SharedPort | None = None,
                 on_gyro_bias: Callable[[], None] | None = None) -> None:
        self.config = config
        self._shared = shared
        log = log or logging.getLogger('i3dmgx2_driver')
        self._log = log
        #: Set means "no stream wanted now": the thread ends, and every request on the
        #: link gives up within a few tens of milliseconds (the link's ``cancel`` event),
        #: and a link opened meanwhile is closed at once. Only this class sets or clears
        #: it; whoever set it decides what becomes of the port: stop() closes it,
        #: stop_streaming() keeps it.
        self._cancel = threading.Event()
        #: Set while a service's operation has the sensor: the stream is quiet on purpose.
        self._paused = threading.Event()
        #: Set when the watch must look before its stall deadline: a cancel, a lost port,
        #: the end of a pause. Between them it sleeps (idle costs nothing, docs/cpu.md).
        self._attention = threading.Event()
        self._report = DeviceReport(log)
        #: What to say to the sensor; it keeps what it learns (identity, divider).
        self.dialogue = SensorDialogue(config, log, self._report.warn, self._cancel,
                                       on_gyro_bias)
        self._on_record = on_record
        self._on_connect = on_connect
        self._on_fatal = on_fatal or (lambda error: log.error(str(error)))
        self._opener = PortOpener(config, log, on_bytes)
        self._reopen_wait = ReopenWait(config.port, config.reconnect_interval, self._cancel.wait)
        self._thread: threading.Thread | None = None
        self._link: DeviceLink | None = None
        #: Guards who owns ``_link``: the thread opening one, or a caller releasing it.
        self._lock = threading.Lock()
        self._observer: LineObserver | None = None
        self._policy_logged = PolicyOutcome()
        #: Links opened so far, and how many of them were reconnections.
        self._connections = 0
        self._reconnects = 0
        self._low_latency_state = ''
        self._parser_totals: dict[str, int] = {}
        #: Records of closed links that were neither a reply nor of the stream.
        self._other_records = 0

    # -- what others read ---------------------------------------------------------------

    def status(self) -> DeviceStatus:
        """Return the device side as one snapshot (from any thread)."""
        dialogue, cfg, link = self.dialogue, self.config, self._link
        line_warning = dialogue.line_warning
        if self._shared is not None and dialogue.divider and not line_warning:
            line_warning = self._shared.line_warning(cfg.address, cfg.stream,
                                                     dialogue.expected_rate_hz)
        return DeviceStatus(
            **self._report.fields(), port=cfg.port, address=cfg.address,
            wireless=cfg.wireless, connections=self._connections,
            reconnects=self._reconnects, low_latency_state=self._low_latency_state,
            parser=self._parser_stats(), radio=link.radio if link is not None else None,
            connected=link is not None, ping_ok=dialogue.ping_ok, info=dialogue.info,
            divider=dialogue.divider, expected_rate_hz=dialogue.expected_rate_hz,
            eeprom_writes=dialogue.eeprom_writes, line_use=dialogue.line_use,
            line_warning=line_warning, strays=self._strays(),
            other_records=self._other_records + (link.other_records if link is not None else 0))

    @property
    def link(self) -> DeviceLink | None:
        """Return the current link, or None while disconnected."""
        return self._link

    def streaming_link(self) -> DeviceLink | None:
        """Return the link while the device streams (a poll may share it), else None."""
        link = self._link
        return link if link is not None and self._report.state is State.STREAMING else None

    # -- the plain node: one thread for everything ----------------------------------------

    def start(self) -> None:
        """Start the supervisor thread: open, initialise, stream, recover, forever."""
        self._cancel.clear()
        self._start_thread(self._link)

    def stop(self, timeout: float = 1.5) -> None:
        """Stop streaming (0xFA), stop the threads, close the port."""
        self._cancel_now()
        link = self._link
        if link is not None:
            link.abort()  # its reader and any waiting request give up
        self.join(timeout)
        self._release(send_stop=True)
        self._report.enter(State.STOPPED)

    def join(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the supervisor thread to end; True once it has."""
        thread = self._thread
        # Not yet started (a transition is starting it as a signal stops us): nothing to
        # wait for, and it ends at once, the cancel set. Thread.join() would raise.
        if thread is not None and thread.is_alive():
            thread.join(timeout)
        return not self._running()

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
        self._cancel.clear()
        link = self._open_link()
        try:
            self._initialise(link, require_answer=True)
        except BaseException:
            self._release()
            self._report.enter(State.STOPPED)
            raise
        self._report.enter(State.READY)
        self._observe(False)

    def start_streaming(self) -> None:
        """
        Start the stream now, then keep it going in the supervisor thread.

        The activate phase of a managed node: returns once records arrive,
        raises DeviceTimeout or PortError if they do not (the port stays
        open unless it is gone). A link lost since :meth:`connect` is reopened
        and initialised first. From then on stalls and unplugs are recovered
        as :meth:`start` recovers them.
        """
        if self._running():
            raise DeviceTimeout('the supervisor is still stopping: try again')
        self._cancel.clear()
        self._observe(True)
        link = self._link
        try:
            if link is None or link.disconnected.is_set():
                self._release()
                link = self._open_link()
                self._initialise(link)
            self._begin_stream(link)
        except PortError:
            self._release()
            self._report.enter(State.DISCONNECTED)
            raise
        except DeviceTimeout:
            if self._link is not None:
                self._quiet(self._link)
            raise
        if self._cancel.is_set():
            # stop() came while the stream was starting: it has the port; no thread.
            raise DeviceTimeout('the driver stopped while the stream was starting')
        self._start_thread(link)

    def start_retrying(self) -> None:
        """
        Let go of any link and keep trying in the supervisor thread, as :meth:`start` does.

        For a managed node with several sensors: one that did not answer at
        configure or activate is retried in the background (it may be
        switched on later) while the others stream.
        """
        self._release()
        self._report.enter(State.DISCONNECTED)
        self.start()

    def stop_streaming(self, timeout: float = 1.5) -> None:
        """
        Stop the stream (0xFA) and the supervisor thread; keep the port open.

        The deactivate phase of a managed node. If the port was lost while
        streaming it stays closed (DISCONNECTED) until the next start.
        """
        self._cancel_now()
        self.join(timeout)
        link = self._link
        if link is not None and not link.disconnected.is_set():
            self._quiet(link)

    # -- for services: the sensor lent for an operation -----------------------------------

    def run_paused(self, operation: Callable[[DeviceLink], Any]) -> Any:
        """
        Stop the stream, run ``operation(link)``, then restart the stream.

        Used by services that need the device's full attention (gyro bias
        capture, built-in test), one at a time. Raises DeviceTimeout at once
        unless the device streams (or has stalled); PortError or
        DeviceTimeout from the operation or the restart.
        """
        link = self._link
        state = self._report.state
        if link is None or state not in (State.STREAMING, State.STALLED):
            raise DeviceTimeout(f'device not streaming (state: {state.value})')
        self._paused.set()
        self._report.enter(State.PAUSED)
        self._observe(False)  # a long operation (a 30 s bias capture) is quiet
        try:
            return self.dialogue.run_exclusive(link, operation)
        finally:
            try:
                self._observe(True)
                if not self._cancel.is_set():
                    self._restart_stream(link)
            finally:
                self._paused.clear()
                self._attention.set()

    # -- the supervisor thread: stream and recover ---------------------------------------

    def _start_thread(self, link: DeviceLink | None) -> None:
        """Start the thread on ``link``, one already streaming, or None: it opens one."""
        self._thread = threading.Thread(target=self._run, args=(link,),
                                        name='gx2-supervisor', daemon=True)
        self._thread.start()

    def _running(self) -> bool:
        """Whether the supervisor thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def _run(self, link: DeviceLink | None) -> None:
        """Stream and recover until cancelled."""
        report = self._report
        while not self._cancel.is_set():
            stalled = False
            try:
                if link is None:
                    report.enter(State.CONNECTING)
                    link = self._open_link()
                    if not self._resume(link):
                        self._initialise(link)
                        self._begin_stream(link)
                self._watch(link)
                stalled = True
            except PortUnusable as exc:
                self._fail(exc)
            except (PortError, DeviceTimeout) as exc:
                if not self._cancel.is_set():  # else: cut short on purpose
                    self._say(exc)
            if self._cancel.is_set():
                break  # whoever stopped us decides about the port
            self._release()
            link = None
            report.enter(State.DISCONNECTED)
            self._reopen_wait(after_stall=stalled)

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
        self._cancel_now()
        self._on_fatal(exc)

    def _cancel_now(self) -> None:
        """Set the cancel, and wake the watch to see it."""
        self._cancel.set()
        self._attention.set()

    def _watch(self, link: DeviceLink) -> None:
        """Return when the link is lost or cannot be revived; recover stalls."""
        report = self._report
        watch = StallWatch(self.config.stall_timeout, self.dialogue.period)
        while True:
            # Asleep until the stream would have stalled, or until told (a paused
            # stream is quiet on purpose: until the pause ends).
            self._attention.wait(None if self._paused.is_set()
                                 else watch.next_look(link.last_data_mono))
            self._attention.clear()  # what set it is looked at below
            if self._cancel.is_set():
                return
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
                # A sensor power-cycled meanwhile (a battery swap) lost the biases
                # in its RAM: the kept ones go back before its stream does.
                self.dialogue.write_biases(link)
                resumed = self._restart_stream(link)
            except DeviceTimeout:
                report.warn('stall', 'stream did not resume: reopening the port', EVENT_PERIOD)
                return
            if resumed:
                report.log.info('stream resumed')

    # -- the steps from an open port to a stream ----------------------------------------

    def _initialise(self, link: DeviceLink, require_answer: bool = False) -> None:
        """Quiet the device, start reading, and have the dialogue learn what it is."""
        self._report.enter(State.INITIALISING)
        self.dialogue.quiet(link)
        if link.running.is_set():
            # The reader runs already (a resume that was not confirmed): anchor afresh.
            self._anchor()
        else:
            self._start_reader(link)
        self.dialogue.initialise(link, require_answer, self._observed)

    def _resume(self, link: DeviceLink) -> bool:
        """
        Resume a known sensor after a reconnect, or return False for the full dialogue.

        Returns False, with nothing done or the reader running, when the
        driver knows no sensor yet (or must not resume), or when the sensor
        does not answer or another serial number does.
        """
        dialogue = self.dialogue
        if not dialogue.can_resume():
            return False
        self._report.enter(State.INITIALISING)
        dialogue.expect_stream(link)
        self._start_reader(link)
        if not dialogue.resume(link):
            return False
        if not self._cancel.is_set():
            self._report.streaming('resumed')
        return True

    def _begin_stream(self, link: DeviceLink) -> None:
        """Start continuous mode on an initialised link; announce it once records arrive."""
        if self.dialogue.start_continuous(link):
            self._report.streaming('full')
            self.dialogue.announce_streaming()

    def _restart_stream(self, link: DeviceLink) -> bool:
        """
        Ask for the stream again on the same link (after a stall or a pause).

        True once records arrive again, False if cancelled first; raises
        DeviceTimeout when none comes, PortDisconnected if the port goes.
        """
        if not self.dialogue.start_continuous(link):
            return False
        self._report.streaming()
        return True

    def _quiet(self, link: DeviceLink) -> None:
        """Stop the device's stream and drop what is in flight: READY, or DISCONNECTED."""
        try:
            self.dialogue.quiet(link)
            self._report.enter(State.READY)
            self._observe(False)
        except PortError as exc:
            self._report.warn(type(exc).__name__, str(exc))
            self._release()
            self._report.enter(State.DISCONNECTED)

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

    # -- the one open link ---------------------------------------------------------------

    def _open_link(self) -> DeviceLink:
        """Open the port and make it the current link (reader not started); raise PortError."""
        cfg = self.config
        if self._shared is not None:
            link = self._shared.attach(cfg.address, self._on_record, self._cancel, cfg.stream,
                                       self._attention.set)
            self._low_latency_state = self._shared.low_latency_state
            return self._own(link)
        port = self._opener.open_port()
        self._low_latency_state = self._opener.low_latency_state
        observer = self._observer = LineObserver(cfg.port, cfg.address, cfg.wireless,
                                                 cfg.baud, self._report.finding)
        link = DeviceLink(port, cfg.address, self._on_record,
                          self._opener.reader_options(observer, self._cancel, cfg.stream,
                                                      self._attention.set))
        return self._own(link)

    def _own(self, link: DeviceLink) -> DeviceLink:
        """Make ``link`` the current one, unless the driver was told to stop meanwhile."""
        cfg = self.config
        with self._lock:
            if self._cancel.is_set():
                # Stopped while opening: the caller has released the link already.
                self._close(link)
                raise PortDisconnected(f'{cfg.port}: closed, the driver is stopping')
            self._link = link
        self._connections += 1
        if self._connections > 1:
            self._reconnects += 1
        return link

    def _release(self, send_stop: bool = False) -> None:
        """Close the current link, if any (once, whichever thread gets here first)."""
        with self._lock:
            link, self._link = self._link, None
        if link is None:
            return
        link.stop()
        if send_stop:
            try:
                link.stop_streaming(timeouts.STOP_REPEATS_AT_EXIT, timeouts.STOP_GAP_AT_EXIT_S)
            except PortError:
                pass
        self._close(link)
        self._other_records += link.other_records
        if self._shared is None:
            for key, value in link.parser.stats.as_dict().items():
                self._parser_totals[key] = self._parser_totals.get(key, 0) + value

    def _close(self, link: DeviceLink) -> None:
        """Close the link's port, or hand the link back to the shared one."""
        if self._shared is not None:
            self._shared.detach(link)
        else:
            link.port.close()

    def _parser_stats(self) -> dict[str, int]:
        """Parser counters summed over every connection so far (shared: the open port's)."""
        if self._shared is not None:
            return self._shared.parser_stats()
        totals = dict(self._parser_totals)
        link = self._link
        if link is not None:
            for key, value in link.parser.stats.as_dict().items():
                totals[key] = totals.get(key, 0) + value
        return totals

    def _strays(self) -> dict[int, int]:
        """Packets of addresses no sensor on a shared port has, by address (else empty)."""
        return self._shared.strays() if self._shared is not None else {}

    def _observe(self, on: bool) -> None:
        """Resume or pause the line observer: silence is a symptom only while we ask."""
        observer = self._observer
        if observer is not None:
            if on:
                observer.resume()
            else:
                observer.pause()

    def _observed(self) -> str:
        """Say what the line observer last found on this link ('' if nothing)."""
        seen = self._observer.last_finding if self._observer is not None else None
        return seen.message if seen is not None else ''
