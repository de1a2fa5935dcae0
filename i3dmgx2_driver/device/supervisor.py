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
that decides about the connection: when a link is wanted, what is done when
one fails, and when the sensor is lent to a service. What it decides with,
each read and tested alone:

- ``dialogue.py``: :class:`~.dialogue.SensorDialogue`, what to say to the
  sensor (quiet, identity, rate, continuous mode, resume); no thread.
- ``current_link.py``: :class:`~.current_link.CurrentLink`, the one open
  link (who owns it, under a lock) and what outlives each link.
- ``watchdog.py``: when a stream has stalled and when to try the port again
  (the reconnect back-off), decided on a clock passed in.
- ``status.py``: :class:`~.status.DeviceReport`, the state and counters,
  changed in one place each; :meth:`DeviceSupervisor.status` makes the one
  immutable :class:`~.status.DeviceStatus` that diagnostics and services read.

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
from .current_link import CurrentLink
from .dialogue import SensorDialogue
from .link import BytesCallback, DeviceError, DeviceLink, RecordCallback, RequestCancelled
from .port import PortDisconnected, PortError, PortUnusable
from .realtime import PolicyOutcome
from .settings import DeviceConfig
from .shared_port import PortOpener, SharedPort
from .status import DeviceReport, DeviceStatus, State
from .throttle import EVENT_PERIOD
from .watchdog import ReopenWait, StallWatch
from ..codec.data_rate import ticks_per_cycle


class DeviceUnavailable(DeviceError):
    """The supervisor cannot take the request now: still stopping, or the stream not running."""


class DeviceSupervisor:
    """
    Own the connection to one device for the life of the driver.

    The callbacks: ``on_record`` (reader thread, every record of the
    stream), ``on_connect`` (before a new link's first record: the node
    re-anchors its clock), ``on_fatal`` (once, the port can never work;
    default: logged), ``on_bytes`` (reader thread, every read: a raw
    capture), ``on_gyro_bias`` (the kept bias written and echoed),
    ``on_stream_known`` (the tick step and the bias flag, :meth:`_hand_on`). ``log``
    has ``debug/info/warning/error``. ``shared``: the port this sensor
    shares behind one base station (shared_port.py), which opens and closes
    it; no line observer watches it.
    """

    def __init__(self, config: DeviceConfig, on_record: RecordCallback, log: Any = None,
                 on_connect: Callable[[], None] | None = None,
                 on_fatal: Callable[[PortError], None] | None = None,
                 on_bytes: BytesCallback | None = None, shared: SharedPort | None = None,
                 on_gyro_bias: Callable[[], None] | None = None,
                 on_stream_known: Callable[[int | None, bool], None] | None = None) -> None:
        self.config, self._shared = config, shared
        self._log = log = log or logging.getLogger('i3dmgx2_driver')
        #: Set means "no stream wanted now": the thread ends, and every request on the
        #: link gives up within a few tens of milliseconds (the link's ``cancel`` event),
        #: and a link opened meanwhile is closed at once. Only this class sets or clears
        #: it; whoever set it decides what becomes of the port: stop() closes it,
        #: stop_streaming() keeps it.
        self._cancel = threading.Event()
        #: ``_paused`` is set while a service's operation has the sensor: the stream is
        #: quiet on purpose. ``_attention``, when the watch must look before its stall
        #: deadline: a cancel, a lost port, the end of a pause. Between them it sleeps
        #: (idle costs nothing, docs/cpu.md).
        self._paused, self._attention = threading.Event(), threading.Event()
        self._report = DeviceReport(log)
        #: What to say to the sensor; it keeps what it learns (identity, divider).
        self.dialogue = SensorDialogue(config, log, self._report.warn, self._cancel, on_gyro_bias)
        #: Its firmware, as the dialogue reads it: what a service may ask of the sensor.
        self.firmware = self.dialogue.firmware
        self._on_fatal = on_fatal or (lambda error: log.error(str(error)))
        #: The one open link, and what outlives each.
        self._current = CurrentLink(config, PortOpener(config, log, on_bytes), on_record,
                                    self._cancel, self._attention.set, self._report.finding,
                                    shared)
        self._on_connect = on_connect or (lambda: None)
        self._on_stream_known = on_stream_known or (lambda ticks, bias_kept: None)
        #: The reader thread's scheduling as last logged (logged again when it changes).
        self._policy_logged = PolicyOutcome()
        self._reopen_wait = ReopenWait(config.port, config.reconnect_interval, self._cancel.wait)
        self._thread: threading.Thread | None = None

    # -- what others read ---------------------------------------------------------------

    def status(self) -> DeviceStatus:
        """Return the device side as one snapshot (from any thread)."""
        dialogue, cfg = self.dialogue, self.config
        line_warning = dialogue.line_warning
        if self._shared is not None and dialogue.divider and not line_warning:
            line_warning = self._shared.line_warning(cfg.address, cfg.stream,
                                                     dialogue.expected_rate_hz)
        learned = ('ping_ok', 'info', 'divider', 'expected_rate_hz', 'eeprom_writes', 'line_use')
        return DeviceStatus(**self._report.fields(), **self._current.totals(),
                            **{name: getattr(dialogue, name) for name in learned}, port=cfg.port,
                            address=cfg.address, wireless=cfg.wireless, line_warning=line_warning)

    @property
    def link(self) -> DeviceLink | None:
        """Return the current link, or None while disconnected."""
        return self._current.link

    def streaming_link(self) -> DeviceLink | None:
        """Return the link while the device streams (a poll may share it), else None."""
        return self._current.link if self._report.state is State.STREAMING else None

    # -- the plain node: one thread for everything ----------------------------------------

    def start(self) -> None:
        """Start the supervisor thread: open, initialise, stream, recover, forever."""
        self._cancel.clear()
        self._start_thread(self._current.link)

    def stop(self, timeout: float = timeouts.SUPERVISOR_STOP_WAIT_S) -> None:
        """Stop streaming (0xFA), stop the threads, close the port."""
        self._cancel.set()
        self._attention.set()  # the watch sees it at once
        link = self._current.link
        if link is not None:
            link.abort()  # its reader and any waiting request give up
        self.join(timeout)
        self._current.release(send_stop=True)
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
        link = self._current.open_link()
        try:
            self._initialise(link, require_answer=True)
        except BaseException:
            self._current.release()
            self._report.enter(State.STOPPED)
            raise
        self._report.enter(State.READY)
        self._current.observe(False)

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
            raise DeviceUnavailable('the supervisor is still stopping: try again')
        self._cancel.clear()
        self._current.observe(True)
        link = self._current.link
        try:
            if link is None or link.disconnected.is_set():
                self._current.release()
                link = self._current.open_link()
                self._initialise(link)
            self._begin_stream(link)
        except PortError:
            self._current.release()
            self._report.enter(State.DISCONNECTED)
            raise
        except DeviceError:
            current = self._current.link
            if current is not None:
                self._quiet(current)
            raise
        if self._cancel.is_set():
            # stop() came while the stream was starting: it has the port; no thread.
            raise RequestCancelled('the driver stopped while the stream was starting')
        self._start_thread(link)

    def start_retrying(self) -> None:
        """
        Let go of any link and keep trying in the supervisor thread, as :meth:`start` does.

        For a managed node with several sensors: one that did not answer at
        configure or activate is retried in the background (it may be
        switched on later) while the others stream.
        """
        self._current.release()
        self._report.enter(State.DISCONNECTED)
        self.start()

    def stop_streaming(self, timeout: float = timeouts.SUPERVISOR_STOP_WAIT_S) -> None:
        """
        Stop the stream (0xFA) and the supervisor thread; keep the port open.

        The deactivate phase of a managed node. If the port was lost while
        streaming it stays closed (DISCONNECTED) until the next start.
        """
        self._cancel.set()
        self._attention.set()  # the watch sees it at once
        self.join(timeout)
        link = self._current.link
        if link is not None and not link.disconnected.is_set():
            self._quiet(link)

    # -- for services: the sensor lent for an operation -----------------------------------

    def run_paused(self, operation: Callable[[DeviceLink], Any]) -> Any:
        """
        Stop the stream, run ``operation(link)``, then restart the stream.

        Used by services that need the device's full attention (gyro bias
        capture, built-in test), one at a time. Raises DeviceUnavailable at once
        unless the device streams (or has stalled); PortError or
        DeviceError from the operation or the restart.
        """
        link, state = self._current.link, self._report.state
        if link is None or state not in (State.STREAMING, State.STALLED):
            raise DeviceUnavailable(f'device not streaming (state: {state.value})')
        self._paused.set()
        self._report.enter(State.PAUSED)
        self._current.observe(False)  # a long operation (a 30 s bias capture) is quiet
        try:
            # Stopped, a polled record of the streamed code (a self test's 0xC2, with the
            # built-in test skewing it) is a reply only, never a sample.
            self.dialogue.stop(link)
            return operation(link)
        finally:
            try:
                self._current.observe(True)
                if not self._cancel.is_set():
                    self._restart_stream(link)
            finally:
                self._paused.clear()
                self._attention.set()

    # -- the steps from an open port to a stream, each moving the report's state ------------
    #
    # The thread and the phases take the same steps in different orders and with
    # different answers to failure (the thread retries forever, a phase fails with the
    # reason), so that they cannot tell a different story about the same step.

    def _initialise(self, link: DeviceLink, require_answer: bool = False) -> None:
        """Quiet the device, start reading, and have the dialogue learn what it is."""
        self._report.enter(State.INITIALISING)
        self.dialogue.quiet(link)
        if link.running.is_set():
            # The reader runs already (a resume that was not confirmed): anchor afresh.
            self._on_connect()
        else:
            self._start_reader(link)
        self.dialogue.initialise(link, require_answer, self._current.observed)
        self._hand_on()

    def _resume(self, link: DeviceLink) -> bool:
        """
        Resume a known sensor after a reconnect, or return False for the full dialogue.

        Returns False, with nothing done or the reader running, when the
        driver knows no sensor yet (or must not resume), or when the sensor
        does not answer or another serial number does. A resume cut short by
        the cancel is not announced.
        """
        dialogue = self.dialogue
        if not dialogue.can_resume():
            return False
        self._report.enter(State.INITIALISING)
        dialogue.expect_stream(link)
        self._hand_on()
        self._start_reader(link)
        if (resumed := dialogue.resume(link)) and not self._cancel.is_set():
            self._report.streaming('resumed')
        return resumed

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
        self._hand_on()  # a capture in the pause may have given a bias to keep
        if started := self.dialogue.start_continuous(link):
            self._report.streaming()
        return started

    def _quiet(self, link: DeviceLink) -> None:
        """Stop the device's stream and drop what is in flight: READY, or DISCONNECTED."""
        try:
            self.dialogue.quiet(link)
            self._report.enter(State.READY)
            self._current.observe(False)
        except PortError as exc:
            self._report.warn(type(exc).__name__, str(exc))
            self._current.release()
            self._report.enter(State.DISCONNECTED)

    def _hand_on(self) -> None:
        """
        Hand the record path what it needs of what the dialogue learned, before records come.

        ``on_stream_known`` gets the timer ticks between two records (None
        while the divider is unknown) and whether a gyro bias is kept and
        written back after a power cycle.
        """
        divider = self.dialogue.divider
        self._on_stream_known(ticks_per_cycle(divider) if divider else None,
                              self.dialogue.gyro_bias is not None)

    def _start_reader(self, link: DeviceLink) -> None:
        """Anchor the consumer, start the reader thread; log its scheduling when it changes."""
        self._on_connect()  # before the first record of a new link reaches it
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
        while not self._cancel.is_set():
            stalled = False
            try:
                if link is None:
                    self._report.enter(State.CONNECTING)
                    link = self._current.open_link()
                    if not self._resume(link):
                        self._initialise(link)
                        self._begin_stream(link)
                self._watch(link)
                stalled = True
            except PortUnusable as exc:
                self._fail(exc)
            except (PortError, DeviceError) as exc:
                if not self._cancel.is_set():  # else: cut short on purpose
                    self._say(exc)
            if self._cancel.is_set():
                break  # whoever stopped us decides about the port
            self._current.release()
            link = None
            self._report.enter(State.DISCONNECTED)
            self._reopen_wait(after_stall=stalled)

    def _say(self, exc: PortError | DeviceError) -> None:
        """Say why this attempt failed, and that the loop goes on."""
        if isinstance(exc, DeviceError):
            self._report.warn('timeout', f'device not answering: {exc} (wrong port or address? '
                                         f'ros2 run i3dmgx2_driver discover finds sensors)')
            return
        # An unplug is an event; a port that stays missing is a condition.
        period = EVENT_PERIOD if isinstance(exc, PortDisconnected) else None
        self._report.warn(type(exc).__name__, f'{exc} ({self._reopen_wait.promise})', period)

    def _fail(self, exc: PortUnusable) -> None:
        """Give up for good: keep why, stop, and let the entry point say it and exit."""
        self._report.failed(exc)
        self._cancel.set()
        self._attention.set()  # the watch sees it at once
        self._on_fatal(exc)

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
            link.check_port()
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
            except DeviceError:
                report.warn('stall', 'stream did not resume: reopening the port', EVENT_PERIOD)
                return
            if resumed:
                report.log.info('stream resumed')
