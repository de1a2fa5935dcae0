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
Keep the device streaming: the start-up dialogue, stalls, unplugs, shutdown.

The supervisor thread opens the port and has the sensor's dialogue
(dialogue.py: quiet, identity, data rate, continuous mode, each request
retried because commands get lost over the radio) bring it to streaming.
It then watches the stream: a stall re-requests continuous mode and
then reopens the port; an unplug reopens it every ``reconnect_interval``,
forever, and at once when the port reappears. The reader thread inside the
link does the publishing; this thread never touches a sample, and this
module knows no command byte: what to say is the dialogue's, when to say
it again is the supervisor's. What diagnostics and services read is one
immutable snapshot, :meth:`DeviceSupervisor.status`.

A reconnect to a sensor already identified is short: what the driver knows
(identity, data-rate divider) is not asked again. One serial-number read
confirms it is the same sensor (the wireless sensor keeps streaming while
the base station is unplugged, so its records usually flow already; if not,
continuous mode is requested). Records are published from the moment they
arrive. Another serial number, or no answer, gets the full dialogue.

What may come back (an unplugged adapter, a sensor switched off) is said
once and reminded at most every ``REMINDER_PERIOD``; what never can (a path
that is no serial port) is said once and ends the supervisor, with
``fatal_error`` set for the entry point to exit on. While nothing of ours
arrives, a ``LineObserver`` says what the line carries instead (another
address, the other framing, unreadable bytes, silence). Streaming is
announced when the first record has arrived, never before.

The same steps are offered as phases for a managed (lifecycle) node, which
brings the device up in order and must know at each step whether it
worked: :meth:`DeviceSupervisor.connect` (port, quiet, identity, rate; no
stream), :meth:`~DeviceSupervisor.start_streaming` (the stream, then the
thread that keeps it going), :meth:`~DeviceSupervisor.stop_streaming`
(0xFA, the port stays open) and :meth:`~DeviceSupervisor.stop` (the port
closed). The plain node's :meth:`~DeviceSupervisor.start` runs them all in
the thread, retrying forever instead of failing.
"""

from collections.abc import Callable
import logging
import os
import threading
import time
from typing import Any

from .dialogue import SensorDialogue
from .hot_path import HotPathObserver
from .identity import DeviceInfo
from .link import BytesCallback, DeviceLink, DeviceTimeout, RecordCallback
from .observer import Finding, LineObserver
from .port import PortDisconnected, PortError, PortUnusable, SerialPort
from .realtime import PolicyOutcome
from .settings import DeviceConfig
from .status import DeviceStatus, State
from .throttle import EVENT_PERIOD, Throttle

#: How often a missing port is looked for (s), so that it is reopened as soon as it is back.
PORT_WATCH_S = 0.02
#: Pause between a port reappearing and opening it (s): udev sets its permissions meanwhile.
PORT_SETTLE_S = 0.02


class DeviceSupervisor:
    """
    Own the connection to one device for the life of the driver.

    ``on_record`` runs in the reader thread for every streamed record;
    ``on_connect`` runs in the supervisor thread each time a link is made
    (the node checks its clock there). ``log`` is any object with
    ``debug/info/warning/error`` methods (a ``logging.Logger`` by default;
    the node passes its rclpy logger). ``on_bytes`` runs in the reader
    thread with every read's raw bytes and read time (a raw capture).
    ``on_fatal`` runs in the supervisor thread, once, when the port can
    never work (``fatal_error`` then holds the error); the supervisor has
    stopped by then. ``timings``, if given, is told every port open and
    every link up (right after ``on_connect``) and handed to every link,
    which tells it the read and the parse of each sample (hot_path.py).
    ``port_factory`` opens the port (SerialPort; a subclass to observe it).
    """

    def __init__(self, config: DeviceConfig, on_record: RecordCallback,
                 log: Any = None, on_connect: Callable[[], None] | None = None,
                 port_factory: Callable[..., SerialPort] = SerialPort,
                 on_bytes: BytesCallback | None = None,
                 on_fatal: Callable[[PortError], None] | None = None,
                 timings: HotPathObserver | None = None) -> None:
        self.config = config
        self._timings = timings
        self._on_fatal = on_fatal
        self._on_record = on_record
        self._on_bytes = on_bytes
        self._on_connect = on_connect
        self._log = log or logging.getLogger('i3dmgx2_driver')
        self._port_factory = port_factory
        self._throttle = Throttle()
        self._stop = threading.Event()
        self._paused = threading.Event()
        self._thread: threading.Thread | None = None
        self._link: DeviceLink | None = None
        #: Guards who owns ``_link``: the thread opening one, or a caller releasing it.
        self._link_lock = threading.Lock()
        #: What to say to the sensor; it keeps what it learns (identity, divider).
        self.dialogue = SensorDialogue(config, self._log, self._warn, self._stop)
        self.state = State.CONNECTING
        self.connections = 0
        self.reconnects = 0
        self.stalls = 0
        self.last_error = ''
        self.low_latency_state = ''
        self.parser_totals: dict[str, int] = {}
        #: The port can never work (a path that is no serial port): why.
        self.fatal_error: PortError | None = None
        #: What the line observer last found while nothing of ours arrived ('' once
        #: records flow), for diagnostics.
        self.advice = ''
        self._observer: LineObserver | None = None
        self._policy_logged = PolicyOutcome()
        #: How the last connection got streaming: 'full' (the whole dialogue) or 'resumed'.
        self.last_start = ''
        self.resumes = 0

    # -- what others read ---------------------------------------------------------------

    def status(self) -> DeviceStatus:
        """Return the device side as one snapshot (from any thread)."""
        dialogue = self.dialogue
        link = self._link
        return DeviceStatus(
            state=self.state, connections=self.connections, reconnects=self.reconnects,
            stalls=self.stalls, last_error=self.last_error,
            low_latency_state=self.low_latency_state, ping_ok=dialogue.ping_ok,
            advice=self.advice,
            fatal_error=str(self.fatal_error) if self.fatal_error is not None else '',
            info=dialogue.info, divider=dialogue.divider,
            expected_rate_hz=dialogue.expected_rate_hz, line_use=dialogue.line_use,
            line_warning=dialogue.line_warning, last_start=self.last_start,
            resumes=self.resumes, parser=self.parser_stats(),
            radio=link.radio if link is not None else None, connected=link is not None)

    @property
    def link(self) -> DeviceLink | None:
        """Return the current link, or None while disconnected."""
        return self._link

    def streaming_link(self) -> DeviceLink | None:
        """Return the link while the device streams (a poll may share it), else None."""
        link = self._link
        return link if link is not None and self.state is State.STREAMING else None

    @property
    def info(self) -> DeviceInfo | None:
        """Return the device's identity, once read."""
        return self.dialogue.info

    @property
    def divider(self) -> int | None:
        """Return the data-rate divider, once known."""
        return self.dialogue.divider

    @property
    def expected_rate_hz(self) -> float | None:
        """Return the rate the divider gives, once known."""
        return self.dialogue.expected_rate_hz

    def parser_stats(self) -> dict[str, int]:
        """Parser counters summed over every connection so far."""
        totals = dict(self.parser_totals)
        link = self._link
        if link is not None:
            for key, value in link.parser.stats.as_dict().items():
                totals[key] = totals.get(key, 0) + value
        return totals

    # -- life cycle ----------------------------------------------------------------------
    #
    # ``_stop`` set means "no stream wanted now": the thread ends, and every
    # request on the link gives up within a few tens of milliseconds (the
    # link is made with it as its ``cancel`` event). Whoever set it decides
    # what becomes of the port: stop() closes it, stop_streaming() keeps it.

    def start(self) -> None:
        """Start the supervisor thread: open, initialise, stream, recover, forever."""
        self._stop.clear()
        self._spawn()

    def _spawn(self) -> None:
        """Start the thread on the current link (None: it opens one)."""
        self._thread = threading.Thread(target=self._run, args=(self._link,),
                                        name='gx2-supervisor', daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 1.5) -> None:
        """Stop streaming (0xFA), stop the threads, close the port."""
        self._stop.set()
        link = self._link
        if link is not None:
            link.abort()
        if self._thread is not None:
            self._thread.join(timeout)
        self._release(send_stop=True)
        self.state = State.STOPPED

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
        link = self._open()
        try:
            self._initialise(link, require_answer=True)
        except BaseException:
            self._release(send_stop=False)
            self.state = State.STOPPED
            raise
        self.state = State.READY
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
        if self._thread is not None and self._thread.is_alive():
            raise DeviceTimeout('the supervisor is still stopping: try again')
        self._stop.clear()
        self._observe(True)
        link = self._link
        try:
            if link is None or link.disconnected.is_set():
                self._release(send_stop=False)
                link = self._open()
                self._initialise(link)
            self._begin_stream(link)
        except PortError:
            self._release(send_stop=False)
            self.state = State.DISCONNECTED
            raise
        except DeviceTimeout:
            if self._link is not None:
                self._quiet(self._link)
            raise
        if self._stop.is_set():
            # stop() came while the stream was starting: it has the port; no thread.
            raise DeviceTimeout('the driver stopped while the stream was starting')
        self._spawn()

    def stop_streaming(self, timeout: float = 1.5) -> None:
        """
        Stop the stream (0xFA) and the supervisor thread; keep the port open.

        The deactivate phase of a managed node. If the port was lost while
        streaming it stays closed (DISCONNECTED) until the next start.
        """
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        link = self._link
        if link is not None and not link.disconnected.is_set():
            self._quiet(link)

    def _quiet(self, link: DeviceLink) -> None:
        """Stop the device's stream and drop what is in flight; the state is READY."""
        try:
            self.dialogue.quiet(link)
            self.state = State.READY
            self._observe(False)
        except PortError as exc:
            self._warn(type(exc).__name__, str(exc))
            self._release(send_stop=False)
            self.state = State.DISCONNECTED

    def _observe(self, on: bool) -> None:
        """Resume or pause the line observer: silence is a symptom only while we ask."""
        observer = self._observer
        if observer is not None:
            if on:
                observer.resume()
            else:
                observer.pause()

    # -- the thread ----------------------------------------------------------------------

    def _warn(self, key: str, message: str, period: float | None = None) -> None:
        """Log ``message`` once, then again at most every ``period`` s (a reminder)."""
        self.last_error = message
        if self._throttle.allow(key, period):
            self._log.warning(message)

    def _on_finding(self, finding: Finding) -> None:
        """Report what the line observer found (reader thread; never blocks long)."""
        self.advice = finding.message
        self._warn(f'observed {finding.kind}', finding.message)

    def _run(self, link: DeviceLink | None) -> None:
        """Stream and recover until stopped; ``link``: one already streaming, or None."""
        while not self._stop.is_set():
            stalled = False
            try:
                if link is None:
                    self.state = State.CONNECTING
                    link = self._open()
                    if not self._resume(link):
                        self._initialise(link)
                        self._begin_stream(link)
                self._watch(link)
                stalled = True
            except PortUnusable as exc:
                self._fail(exc)
            except PortError as exc:
                if not self._stop.is_set():
                    # An unplug is an event; a port that stays missing is a condition.
                    period = EVENT_PERIOD if isinstance(exc, PortDisconnected) else None
                    self._warn(type(exc).__name__,
                               f'{exc} (retrying every {self.config.reconnect_interval:g} s)',
                               period)
            except DeviceTimeout as exc:
                if not self._stop.is_set():  # else: cut short on purpose
                    self._warn('timeout', f'device not answering: {exc} (wrong port or '
                                          f'address? ros2 run i3dmgx2_driver discover '
                                          f'finds sensors)')
            if self._stop.is_set():
                break  # whoever stopped us decides about the port
            self._release(send_stop=False)
            link = None
            self.state = State.DISCONNECTED
            if not (stalled and self.config.prompt_reopen):
                self._wait_to_reopen()  # a port closed for a stall is still there

    def _wait_to_reopen(self) -> None:
        """
        Wait ``reconnect_interval``, or less: a port seen missing is reopened once it is back.

        An unplugged adapter's device node goes, and comes back when it is
        plugged in again; looking for it costs a stat() every few tens of ms.
        """
        interval = self.config.reconnect_interval
        if not self.config.prompt_reopen:
            self._stop.wait(interval)
            return
        deadline = time.monotonic() + interval
        seen_missing = False
        while not self._stop.wait(PORT_WATCH_S) and time.monotonic() < deadline:
            if not os.path.exists(self.config.port):
                seen_missing = True
            elif seen_missing:
                self._stop.wait(PORT_SETTLE_S)
                return

    def _fail(self, exc: PortUnusable) -> None:
        """Give up for good: say why once, stop, and let the entry point exit."""
        self.fatal_error = exc
        self.last_error = str(exc)
        self.state = State.STOPPED
        self._stop.set()
        if self._on_fatal is not None:
            self._on_fatal(exc)  # the entry point says it, once, as it exits
        else:
            self._log.error(str(exc))

    def _open(self) -> DeviceLink:
        cfg = self.config
        port = self._port_factory(cfg.port, cfg.baud, low_latency=cfg.low_latency)
        if self._timings is not None:
            self._timings.opened()
        if port.low_latency_state != self.low_latency_state:
            self.low_latency_state = port.low_latency_state
            self._log.info(f'{cfg.port}: low-latency mode {port.low_latency_state}')
        observer = self._observer = LineObserver(cfg.port, cfg.address, cfg.wireless,
                                                 cfg.baud, self._on_finding)
        link = DeviceLink(port, cfg.address, self._on_record, wireless=cfg.wireless,
                          on_bytes=self._on_bytes, observer=observer, cancel=self._stop,
                          thread_policy=cfg.thread_policy, timings=self._timings)
        with self._link_lock:
            if self._stop.is_set():
                # Stopped while opening: the caller has released the link already.
                port.close()
                raise PortDisconnected(f'{cfg.port}: closed, the driver is stopping')
            self._link = link
        self.connections += 1
        if self.connections > 1:
            self.reconnects += 1
        return link

    def _release(self, send_stop: bool) -> None:
        """Close the current link, if any (once, whichever thread gets here first)."""
        with self._link_lock:
            link, self._link = self._link, None
        if link is None:
            return
        link.stop()
        if send_stop:
            try:
                link.stop_streaming(repeats=2, gap=0.01)
            except PortError:
                pass
        link.port.close()
        for key, value in link.parser.stats.as_dict().items():
            self.parser_totals[key] = self.parser_totals.get(key, 0) + value

    def _initialise(self, link: DeviceLink, require_answer: bool = False) -> None:
        """Quiet the device, start reading, and have the dialogue learn what it is."""
        self.state = State.INITIALISING
        self.dialogue.quiet(link)
        if link.running.is_set():
            # The reader runs already (a resume that was not confirmed): anchor afresh.
            self._anchor()
        else:
            self._start_reader(link)
        self.dialogue.initialise(link, require_answer, self._observed)

    def _observed(self) -> str:
        """Say what the line observer last found on this link ('' if nothing)."""
        seen = self._observer.last_finding if self._observer is not None else None
        return seen.message if seen is not None else ''

    def _anchor(self) -> None:
        """Let the consumer re-anchor before the first record of a new link reaches it."""
        if self._on_connect is not None:
            self._on_connect()
        if self._timings is not None:
            self._timings.connected()

    def _start_reader(self, link: DeviceLink) -> None:
        """Anchor the consumer, start the reader thread, log what its scheduling became."""
        self._anchor()
        link.start()
        if not link.running.wait(1.0):
            return
        outcome = link.policy_outcome
        if outcome != self._policy_logged:
            self._policy_logged = outcome
            if outcome.applied:
                self._log.info(f'reader thread: {", ".join(outcome.applied)}')
            for refusal in outcome.refused:
                self._log.warning(refusal)

    def _resume(self, link: DeviceLink) -> bool:
        """
        Resume a known sensor after a reconnect, or return False for the full dialogue.

        Returns False, with nothing done or the reader running, when the
        driver knows no sensor yet (or must not resume), or when the sensor
        does not answer or another serial number does.
        """
        if not self.dialogue.can_resume():
            return False
        self.state = State.INITIALISING
        self.dialogue.expect_stream(link)
        self._start_reader(link)
        if not self.dialogue.resume(link):
            return False
        if not self._stop.is_set():
            self.state = State.STREAMING
            self.advice = ''
            self.last_start = 'resumed'
            self.resumes += 1
        return True

    def _begin_stream(self, link: DeviceLink) -> None:
        """Start continuous mode on an initialised link; announce it once records arrive."""
        if self.dialogue.start_continuous(link):
            self.last_start = 'full'
            self.state = State.STREAMING
            self.advice = ''
            self.dialogue.announce_streaming()

    def _watch(self, link: DeviceLink) -> None:
        """Return when the link is lost or cannot be revived; recover stalls."""
        cfg = self.config
        stall_after = max(cfg.stall_timeout, 3 * self.dialogue.period)
        while not self._stop.wait(min(0.05, stall_after / 4)):
            if link.disconnected.is_set():
                raise PortDisconnected(link.error or 'device disconnected')
            if self._paused.is_set():
                continue
            quiet = time.monotonic() - link.last_data_mono
            if self.advice and quiet < stall_after:
                self.advice = ''  # records flow again: what was observed is past
            if quiet > stall_after:
                self.stalls += 1
                self.state = State.STALLED
                self._warn('stall', f'no data for {stall_after:.1f} s: re-requesting '
                                    f'continuous mode', EVENT_PERIOD)
                try:
                    resumed = self.dialogue.start_continuous(link)
                except DeviceTimeout:
                    self._warn('stall', 'stream did not resume: reopening the port',
                               EVENT_PERIOD)
                    return
                if resumed:
                    self.state = State.STREAMING
                    self._log.info('stream resumed')

    # -- exclusive operations for services ------------------------------------------------

    def run_paused(self, operation: Callable[[DeviceLink], Any]) -> Any:
        """
        Stop the stream, run ``operation(link)``, then restart the stream.

        Used by services that need the device's full attention (gyro bias
        capture, built-in test). Raises PortError or DeviceTimeout.
        """
        link = self._link
        if link is None or self.state not in (State.STREAMING, State.STALLED):
            raise DeviceTimeout(f'device not streaming (state: {self.state.value})')
        self._paused.set()
        self.state = State.PAUSED
        self._observe(False)  # a long operation (a 30 s bias capture) is quiet on purpose
        try:
            return self.dialogue.run_exclusive(link, operation)
        finally:
            try:
                self._observe(True)
                if not self._stop.is_set():
                    self.dialogue.start_continuous(link)
                    self.state = State.STREAMING
            finally:
                self._paused.clear()
