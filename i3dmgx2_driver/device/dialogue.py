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
exclusive operation. How each step goes (its request, its retries, how long
it waits for records or for silence) is sensor_steps.py's, the same for
``discover`` and ``bringup``; which steps the node takes, in which order,
and what it keeps of their answers is here. What to do when the dialogue
fails (reopen, back off, give up) is not: the supervisor's thread and its
lifecycle phases (supervisor.py) decide that, and drive this object through
their start-up steps. It has no thread and starts none; it can be tested
with a link and a simulator alone.

What it learns (identity, divider, whether the ping was answered, the line's
use) it keeps as attributes for the supervisor's status snapshot. The
phases share what they learn: continuous mode waits as long as the rate
says, the resume compares the serial number the identification read.

The data rate's divider cell wears with every write, so which dividers were
written is kept here, with the one rule that guards it: one change of
setting writes the cell once, however rough the radio (the write step's
rule), and never again from this driver's run (this dialogue's). A bias is
stored in non-volatile memory (0xD0) only when a service asks, once per
call; the steps count it with the divider's writes.

Known biases (the ``gyro_bias`` and ``accel_bias`` parameters) go to the
sensor's RAM at every start and every resume (0xCA, 0xC9: RAM only, so a
power cycle loses them and no EEPROM wears), each checked against the echo
the sensor sends back: a sensor that does not echo what was written is an
error with the two values, never a silent difference. They go again after a
stall the supervisor recovers on the same port, since a sensor power-cycled
while the port stayed open (a battery swap) stalls and has lost them too.
What is written is the gyro bias this dialogue keeps: the parameter's at
first, then each capture the driver accepted (:attr:`gyro_bias`), so a
rewrite never undoes a calibration made while running, and after a refused
(moved) capture a power cycle brings back the last good bias, not the moved one.

The firmware (0xE9) is read with the identity, before anything that depends
on it is asked (firmware.py): a stream it lacks ends the initialisation at
once (FirmwareLacksStream), and :attr:`SensorDialogue.firmware` tells the
temperature poller and the bias store what this sensor answers.
"""

from collections.abc import Callable
import contextlib
import struct
import threading
import time
from typing import Any

from . import timeouts
from .identity import DeviceInfo, read_identifier, read_identity, SERIAL_NUMBER_SELECTOR
from .link import DeviceError, DeviceLink, DeviceTimeout, EchoMismatch
from .sensor_firmware import check_stream, SensorFirmware
from .sensor_steps import ping, SensorSteps
from .settings import DeviceConfig
from .throttle import EVENT_PERIOD, Throttle
from ..codec import commands, layouts, streams
from ..codec.data_rate import divider_for_rate, period_of_divider, rate_of_divider

#: ``warn(key, message, period)``: say a problem (throttled per key), keep it as the last error.
Warn = Callable[[str, str, float | None], None]


def first_poll_code(stream: int) -> int:
    """
    Return what the first polled requests ask for: never the record being streamed.

    A sensor may still stream while the dialogue starts it in full (its stop
    lost on the radio, or streaming from power-up); a record of the stream
    that arrives while a poll of the same code waits is taken for its reply,
    so it is neither published nor the answer, and the real reply, coming
    next, is published in its place (found by the hour-long soak, stream
    ``inertial``). 0xC2, or the magnetometer alone (0xC7, no stream's
    record) when 0xC2 is the stream.
    """
    return layouts.MAGNETOMETER if stream == layouts.ACCEL_ANG_RATE else layouts.ACCEL_ANG_RATE


def float32_vector(values: tuple[float, ...]) -> tuple[float, ...]:
    """Return ``values`` as float32 gives them back: what a sensor echoes of a write."""
    return struct.unpack('>3f', struct.pack('>3f', *values))


def _vector(values: tuple[float, ...]) -> str:
    return '(' + ', '.join(f'{v:.6g}' for v in values) + ')'


class SensorDialogue(SensorSteps):
    """
    Speak to the sensor at ``config.address`` through whatever link is open.

    The steps, with the request patience of ``config``, in the node's order.
    ``log`` has ``debug/info/warning/error``; ``warn`` says a problem once
    per key and period; ``cancel`` set makes the waits give up (the driver
    is stopping or pausing the stream; a failed read is then no reason to
    warn).
    """

    def __init__(self, config: DeviceConfig, log: Any, warn: Warn, cancel: threading.Event,
                 on_gyro_bias: Callable[[], None] | None = None) -> None:
        super().__init__(config.request_timeout, config.request_retries, cancel)
        self.config = config
        self._log, self._warn = log, warn
        self._throttle = Throttle()
        #: The device's identity, once read.
        self.info: DeviceInfo | None = None
        #: Its firmware (0xE9), read with the identity: what it answers.
        self.firmware = SensorFirmware()
        self._info_logged: DeviceInfo | None = None
        #: Whether the base station's ping was answered (None: wired, or not asked).
        self.ping_ok: bool | None = None
        #: The data-rate divider, once known.
        self.divider: int | None = None
        #: Dividers written (or tried): never written again by this dialogue.
        self._divider_written: set[int] = set()
        #: The stream's use of the line at the device's rate (once the rate is known),
        #: and, when it does not fit, what to do about it ('' when it fits).
        self.line_use = self.line_warning = ''
        #: The biases written at every start, resume and stall recovery: the
        #: parameters' at first; an accepted capture replaces the gyro bias (the
        #: sensor holds it in RAM already; a power cycle loses it, and the next
        #: stall recovery, resume or start writes it back).
        self.gyro_bias, self.accel_bias = config.gyro_bias, config.accel_bias
        #: Told each time a kept gyro bias was written and echoed (``~/is_calibrated``).
        self._on_gyro_bias = on_gyro_bias or (lambda: None)

    @property
    def expected_rate_hz(self) -> float | None:
        """Return the rate the divider gives, once known."""
        return rate_of_divider(self.divider) if self.divider else None

    @property
    def period(self) -> float:
        """Return the time between samples (s), or the factory rate's while it is unknown."""
        return period_of_divider(self.divider)

    def _serial_number(self) -> str:
        """Return the known sensor's serial number ('' while none is known)."""
        return self.info.serial_number if self.info is not None else ''

    # -- bring-up: who answers, what it is, its data rate -------------------------------

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
        self._introduce(link, require_answer, observed)
        check_stream(self.firmware.version, self.config.stream, self.config.address)
        self._configure_rate(link)
        self.write_biases(link)
        self._check_line()

    def _introduce(self, link: DeviceLink, require_answer: bool,
                   observed: Callable[[], str]) -> None:
        """
        Ping, make the first polled requests, read the identity.

        The first words to a sensor after it was quieted: whether the base
        station reaches it, a couple of polled requests (which make
        continuous mode dependable later), and what it says it is. A silent
        sensor is told apart here, with what the line carried instead.
        """
        cfg = self.config
        if link.wireless:
            self.ping_ok = ping(link, timeouts.PING_TIMEOUT, timeouts.PING_RETRIES)
            if not self.ping_ok:
                self._warn('ping', f'node {cfg.address} does not answer the base station '
                                   f'ping: check it is powered, its address (ros2 run '
                                   f'i3dmgx2_driver discover lists the nodes on the air) and '
                                   f'the radio channel', None)
        # The thesis author found continuous mode unreliable as the very first
        # command: a couple of polled requests first make it dependable.
        code = first_poll_code(cfg.stream)
        for _ in range(2):
            with contextlib.suppress(DeviceError):
                link.request(bytes((code,)), code, cfg.request_timeout,
                             timeouts.FIRST_POLL_RETRIES)
        if require_answer and not self.ping_ok and not link.heard:
            silent = (f'node {cfg.address} is silent: no answer to the base station '
                      f'ping or to polled requests (check it is powered, its address and the '
                      f'radio channel)' if link.wireless else
                      f'the sensor on {cfg.port} is silent: no answer to polled '
                      f'requests (check it is powered and the baud rate)')
            # What the line carried instead says what to change (address, framing, baud).
            seen = observed()
            raise DeviceTimeout(silent + (f'; observed on the line: {seen}' if seen else ''))
        self._identify(link)

    def _identify(self, link: DeviceLink) -> None:
        cfg = self.config
        info = read_identity(link, self.timeout, self.retries)
        if self._cancel.is_set():
            return
        if not any(info):
            self._warn('identity', 'the device did not tell its identity (0xEA, 0xE9): right '
                                   'port? ros2 run i3dmgx2_driver discover finds sensors; its '
                                   'firmware could not be checked', None)
            return
        self.info = info
        self.firmware.learn(info.firmware)
        if not info.firmware:
            self._warn('firmware', f'node {cfg.address} did not tell its firmware (0xE9): '
                                   f'could not check that it has the stream, the temperatures '
                                   f'and the bias store; they are asked for all the same', None)
        if info != self._info_logged:
            self._info_logged = info
            self._log.info(f'device: model {info.model_name or "?"} ({info.model_number or "?"}), '
                           f'serial {info.serial_number or "?"}, firmware {info.firmware or "?"}, '
                           f'options {info.options or "-"}, node {cfg.address}')

    def _configure_rate(self, link: DeviceLink) -> None:
        """Read the divider; write the one ``config.data_rate_hz`` asks for, if it differs."""
        cfg = self.config
        try:
            current = self.read_divider(link)
        except DeviceError:
            if cfg.data_rate_hz is not None or self._cancel.is_set():
                raise
            # Nothing to set, so streaming can go on without knowing the rate
            # (a replayed capture answers no request; lost packets and the
            # rate check in diagnostics then wait for a known divider).
            self._warn('rate', 'the device did not tell its data rate (EEPROM 0xFCA2)', None)
            return
        self.divider = current
        if cfg.data_rate_hz is None or (wanted := divider_for_rate(cfg.data_rate_hz)) == current:
            return
        if wanted in self._divider_written:
            # Written before: a retry, a reconnect or a restart of the stream must not
            # write the cell again. The sensor (or a reply that only looks valid, or
            # another sensor put in its place) says otherwise; go on with what it says,
            # and say so. (Not even the serial number can be trusted for this: a reply
            # that only looks valid can carry any.)
            self._warn('rate', f'the device reports divider {current} though {wanted} was '
                               f'written before: not writing its EEPROM again (restart the '
                               f'driver to write it)', None)
            return
        # Noted before the first write goes out: from then on the cell may be written,
        # whatever the replies say (found by the stateful dialogue test: a forged
        # read-back made the next initialise write again).
        self._divider_written.add(wanted)
        self.divider = self.write_divider(link, current, wanted)
        self._log.warning(
            f'data rate of node {cfg.address} set to {rate_of_divider(wanted):.2f} Hz (EEPROM '
            f'0xFCA2: {current} -> {wanted}); this persists across power cycles')

    # -- biases -------------------------------------------------------------------------

    def write_biases(self, link: DeviceLink) -> None:
        """
        Write the kept gyro and accel biases to the sensor's RAM; check the echoes.

        Raises DeviceTimeout when a write is not answered, or its echo is not
        the bias written (as float32, which is what the sensor keeps).
        """
        cfg = self.config
        writes = ((self.gyro_bias, 'gyro_bias', 'rad/s', commands.write_gyro_bias,
                   layouts.WRITE_GYRO_BIAS),
                  (self.accel_bias, 'accel_bias', 'g', commands.write_accel_bias,
                   layouts.WRITE_ACCEL_BIAS))
        for bias, name, unit, request, code in writes:
            if bias is None:
                continue
            try:
                echo = link.request(request(bias), code, self.timeout, self.retries).bias
            except DeviceError as exc:
                raise type(exc)(f'{name}: the sensor did not echo the bias written '
                                f'(0x{code:02X}): {exc}') from None
            if tuple(echo) != float32_vector(bias):
                raise EchoMismatch(f'{name}: wrote {_vector(bias)} {unit}, the sensor echoed '
                                   f'{_vector(echo)} {unit} (0x{code:02X}): it does not use '
                                   f'the bias asked for; check the parameter and the sensor')
            self._log.info(f'{name} {_vector(bias)} {unit} written to node {cfg.address} '
                           f'(RAM, echoed; lost at a power cycle, written again at start '
                           f'and after a stall)')
        if self.gyro_bias is not None:
            self._on_gyro_bias()

    def _check_line(self) -> None:
        """
        Warn when the device's rate is more than the line carries for the stream.

        A requested rate that does not fit was refused before the node
        started; this catches a device already set (data_rate 0) to a rate the
        stream cannot keep, which would otherwise show only as records missing.
        """
        if not self.divider:
            return
        cfg = self.config
        stream = streams.BY_CODE[cfg.stream]
        budget = streams.line_budget(stream, self.expected_rate_hz, cfg.baud, cfg.wireless)
        self.line_use = streams.describe(budget)
        self.line_warning = '' if budget.fits else (
            'the device is set to a rate the line cannot carry, records will be skipped: '
            + streams.advice(stream, budget))
        if self.line_warning and self._throttle.allow('line'):
            self._log.warning(self.line_warning)

    # -- continuous mode ----------------------------------------------------------------
    #
    # After a reconnect, a sensor already identified is confirmed with one
    # serial-number read and kept streaming; anything else gets the full dialogue.

    def start_continuous(self, link: DeviceLink) -> bool:
        """
        Start the configured stream, at the rate the divider gives, until its records arrive.

        Returns True once a record has arrived, False if cancelled first;
        raises DeviceTimeout when none comes, PortDisconnected if the port goes.
        """
        cfg = self.config
        return self.start_stream(link, cfg.stream, self.period, cfg.continuous_retries)

    def announce_streaming(self) -> None:
        """Say that records flow: called only once one has arrived on this link."""
        cfg = self.config
        stream = streams.BY_CODE[cfg.stream]
        self._log.info(f'streaming {stream.label} from node {cfg.address} on {cfg.port}'
                       + (f' at {self.expected_rate_hz:.1f} Hz' if self.divider else '')
                       + ' (first record received)')

    def resume(self, link: DeviceLink) -> bool:
        """
        Confirm with one serial-number read that the known sensor is back; keep it streaming.

        The link's reader runs already, with records of the stream counted as
        samples from the first one. Returns False when the driver knows no
        sensor yet (or must not resume), or when the sensor does not answer or
        another serial number does: the caller then runs the full dialogue.
        """
        cfg = self.config
        known = self._serial_number()
        try:
            serial = read_identifier(link, SERIAL_NUMBER_SELECTOR, cfg.resume_timeout,
                                     cfg.resume_retries)
        except DeviceError:
            if self._cancel.is_set():
                raise
            if self._throttle.allow('resume', EVENT_PERIOD):
                self._log.info(f'node {cfg.address} did not confirm its serial number: '
                               f'starting it in full')
            return False
        if serial != known:
            self._log.warning(f'another sensor answers as node {cfg.address}: serial '
                              f'{serial or "?"}, not {known}; identifying it in full')
            self.info = None
            return False
        # The link counts only records of the stream (expect_stream said which): a
        # sensor power-cycled meanwhile streams nothing, or the record its EEPROM says.
        deadline = time.monotonic() + min(2 * self.period, timeouts.RESUME_LOOK_S)
        while not link.records and time.monotonic() < deadline and not self._cancel.is_set():
            time.sleep(timeouts.RESUME_POLL_S)
        # Not streaming (power-cycled meanwhile), or streaming another record: ask for it.
        # A power cycle meanwhile lost the biases in the sensor's RAM: write them again.
        self.write_biases(link)
        if not link.records and not self.start_continuous(link):
            return True  # cancelled: nothing more to do here
        self._log.info(f'streaming {streams.BY_CODE[cfg.stream].label} again from node '
                       f'{cfg.address} on {cfg.port}: same sensor (serial {serial}), identity '
                       f'and data rate not asked again')
        return True

    def expect_stream(self, link: DeviceLink) -> None:
        """Drop what is in flight; count records of the stream as samples from the first."""
        link.flush_input()
        link.set_streamed(self.config.stream)

    def can_resume(self) -> bool:
        """Whether a reconnect may try :meth:`resume` (a known sensor, and allowed to)."""
        return bool(self.config.fast_reconnect and self._serial_number())
