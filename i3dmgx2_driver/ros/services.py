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
The node's services: capture and store the gyro bias, and the self test.

``~/capture_gyro_bias``, ``~/store_gyro_bias`` and ``~/self_test`` are
std_srvs/Trigger (a yes or no and a text); the self test is also served as
``~/diagnostic_self_test``, a diagnostic_msgs/SelfTest, the ROS message for
exactly this (the sensor's serial number, passed, one DiagnosticStatus per
step), from the same steps.

Each needs the device to itself, so they run through the supervisor's
``run_paused``: the stream stops, the exchange runs, the stream restarts.
The reader thread keeps running throughout (it claims the replies), so
nothing waits on the executor but the service call itself; the services sit
in their own callback group, so that with a multi-threaded executor the
diagnostics keep ticking during a 30-second capture. Only one device
operation runs at a time; a second call is refused at once, not queued.

In the order of this file: what both operations share (the device as a
small ``Device`` Protocol the supervisor satisfies, the errors an operation
may end with, polled inertial readings averaged); the gyro bias capture
(0xCD), whether to trust what it captured, and how an accepted capture is
kept (stored on the sensor, 0xD0, or written to a parameter file for the
next start); the self test's steps and
their report; and :class:`DeviceServices`, which serves them. Each
judgement is a pure function of the numbers, tested without a device.
What a capture came to is a ``Calibration`` (calibration.py), so that
diagnostics reads it without importing this module.

Last, in its own section, ``~/save_capture`` (:class:`SaveCaptureService`):
the fault capture's last seconds written on demand. It borrows nothing from
the device, so it is not one of the operations above.
"""

from collections.abc import Callable, Sequence
import math
import os
import threading
import time
from typing import Any, NamedTuple, Protocol

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from diagnostic_msgs.srv import SelfTest
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.exceptions import ParameterUninitializedException
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.node import Node
from std_srvs.srv import Trigger

from .calibration import Calibration, RATE_TOLERANCE
from ..capture.fault_capture import FaultCapture
from ..codec import commands, layouts
from ..codec.errors import CodecError
from ..codec.records import GYRO_BIAS_QUANTITY, INVALID_QUANTITY
from ..device.dialogue import SensorDialogue
from ..device.link import DeviceLink, DeviceTimeout
from ..device.port import PortError
from ..device.status import DeviceStatus, State

# -- what both operations share ------------------------------------------------------

Vector3 = tuple[float, float, float]

#: Polled 0xC2 records averaged before and after a capture, and by the self test.
POLLS = 5
#: Errors a device operation can end with; anything else is a bug and propagates.
OPERATION_ERRORS = (PortError, DeviceTimeout, CodecError, OSError)


def norm(v: Sequence[float]) -> float:
    """Return the length of ``v``."""
    return math.sqrt(sum(x * x for x in v))


def _mean(vectors: Sequence[Sequence[float]]) -> Vector3:
    n = len(vectors)
    return (sum(v[0] for v in vectors) / n, sum(v[1] for v in vectors) / n,
            sum(v[2] for v in vectors) / n)


def format_vector(v: Sequence[float], digits: int = 5) -> str:
    """Write a vector as ``(x, y, z)``, the form the service messages use."""
    return '(' + ', '.join(f'{x:.{digits}f}' for x in v) + ')'


def poll_inertial(link: DeviceLink, count: int = POLLS, timeout: float = 0.5,
                  retries: int = 3) -> tuple[Vector3, Vector3]:
    """Poll 0xC2 ``count`` times; return the mean acceleration (g) and rate (rad/s)."""
    replies = [link.request(bytes((layouts.ACCEL_ANG_RATE,)), layouts.ACCEL_ANG_RATE,
                            timeout, retries) for _ in range(count)]
    return _mean([r.accel for r in replies]), _mean([r.angular_rate for r in replies])


class Device(Protocol):
    """What the services need of the device side (the supervisor is one)."""

    #: What is said to the sensor (the EEPROM writes it counts, for diagnostics).
    dialogue: SensorDialogue

    def status(self) -> DeviceStatus:
        """Return the device side's snapshot."""

    def run_paused(self, operation: Callable[[DeviceLink], Any]) -> Any:
        """Stop the stream, run ``operation(link)``, start the stream again."""


# -- the gyro bias capture -----------------------------------------------------------
#
# The device captures the bias over ``gyro_bias_sampling_ms`` and uses it at
# once, whatever happened meanwhile; so the driver polls the accelerometer and
# gyros before and after, judges them, and says whether the sensor was still.
# GyroBiasCapture runs the exchange and keeps what the captures came to, for
# diagnostics and ``~/is_calibrated``.

#: Seconds the capture reply may come after the sampling time (radio, scheduling).
CAPTURE_MARGIN = 2.0
#: A captured bias larger than this (rad/s, about 5.7 deg/s) is no bias: the
#: sensor turned. Real 3DM-GX2 biases are a few hundredths of a rad/s at most.
MAX_GYRO_BIAS = 0.1
#: After a capture the device subtracts the new bias, so a still sensor reads
#: about zero; more than this (rad/s, about 1.1 deg/s) means it is turning.
MAX_RESIDUAL_RATE = 0.02
#: The gravity vector may change this much (g, about 1.1 degrees of tilt)
#: between before and after the capture; more means the sensor was moved.
MAX_ACCEL_CHANGE = 0.02


def judge_capture(bias: Vector3, accel_before: Vector3, accel_after: Vector3,
                  rate_after: Vector3, max_bias: float = MAX_GYRO_BIAS,
                  max_residual: float = MAX_RESIDUAL_RATE,
                  max_accel_change: float = MAX_ACCEL_CHANGE) -> list[str]:
    """
    Return why a captured gyro bias cannot be trusted; empty if it can.

    Three independent signs of motion, so that no single unlucky moment (a
    sway reversing direction just as the capture ends) hides it: a bias too
    large to be one, a gravity vector that changed between before and after,
    and an angular rate that is not about zero once the new bias is applied.
    """
    reasons = []
    size = norm(bias)
    if not math.isfinite(size) or size > max_bias:
        reasons.append(f'captured bias |{size:.4f}| rad/s exceeds {max_bias:g}')
    change = norm([a - b for a, b in zip(accel_after, accel_before, strict=True)])
    if not math.isfinite(change) or change > max_accel_change:
        reasons.append(f'gravity vector changed by {change:.4f} g (over {max_accel_change:g})')
    residual = norm(rate_after)
    if not math.isfinite(residual) or residual > max_residual:
        reasons.append(f'angular rate after the capture |{residual:.4f}| rad/s '
                       f'(over {max_residual:g})')
    return reasons


class GyroBiasCapture:
    """
    Capture the gyro bias with the stream paused, judge it, and keep what it came to.

    ``device`` runs the exchange with the stream paused;
    ``forget_last_sample()`` keeps the pause from counting as lost records;
    ``calibrated(flag)`` is told whether the device uses a good gyro bias
    after every capture that reached the device (``~/is_calibrated``).
    """

    def __init__(self, device: Device, forget_last_sample: Callable[[], None],
                 calibrated: Callable[[bool], None], log: RcutilsLogger) -> None:
        self._device = device
        self._forget = forget_last_sample
        self._calibrated = calibrated
        self._log = log
        #: The last capture attempt and the last accepted one.
        self.last_capture: Calibration | None = None
        self.good_capture: Calibration | None = None

    def run(self, sampling_ms: int) -> tuple[bool, str]:
        """Capture over ``sampling_ms``; return (success, message)."""
        timeout = sampling_ms / 1000.0 + CAPTURE_MARGIN

        def operation(link: DeviceLink) -> tuple[Vector3, Any, Vector3, Vector3]:
            accel_before, _ = poll_inertial(link)
            reply = link.request(commands.capture_gyro_bias(sampling_ms),
                                 layouts.CAPTURE_GYRO_BIAS, timeout=timeout, retries=1)
            accel_after, rate_after = poll_inertial(link)
            # While the stream is still stopped: the timer gap across the pause is
            # the operation's doing, not the radio's.
            self._forget()
            return accel_before, reply, accel_after, rate_after

        self._log.info(f'capturing the gyro bias over {sampling_ms} ms: keep the sensor still')
        started = time.time()
        try:
            accel_before, reply, accel_after, rate_after = \
                self._device.run_paused(operation)
        except OPERATION_ERRORS as exc:
            summary = f'no capture: {exc}'
            self.last_capture = Calibration(started, False, None, sampling_ms, summary)
            self._log.warning(f'gyro bias capture failed: {exc}')
            return False, f'gyro bias capture failed: {exc}'
        bias: Vector3 = tuple(reply.bias)
        reasons = judge_capture(bias, accel_before, accel_after, rate_after)
        text = format_vector(bias)
        if reasons:
            summary = 'the sensor moved: ' + '; '.join(reasons)
            self.last_capture = Calibration(started, False, bias, sampling_ms, summary)
            self._calibrated(False)
            message = (f'refused: the sensor moved during the capture ({"; ".join(reasons)}). '
                       f'The device now uses the captured bias {text} rad/s until the next '
                       f'capture or a power cycle: capture again with the sensor still.')
            self._log.warning(message)
            return False, message
        calibration = Calibration(started, True, bias, sampling_ms, f'bias {text} rad/s')
        self.last_capture = self.good_capture = calibration
        # Written back after a power cycle from now on, in place of the parameter's.
        self._device.dialogue.keep_gyro_bias(bias)
        self._calibrated(True)
        message = (f'gyro bias captured over {sampling_ms} ms: {text} rad/s; the device uses '
                   f'it until power-off (not stored in non-volatile memory: '
                   f'~/store_gyro_bias stores it)')
        self._log.info(message)
        return True, message

    # -- keeping it ----------------------------------------------------------
    #
    # An accepted capture lives in the sensor's RAM. Two ways keep it: the
    # sensor's non-volatile memory (0xD0, asked for by ~/store_gyro_bias, one
    # EEPROM write each), or a parameter file the node loads at its next start
    # and writes with 0xCA (no EEPROM wear). Only the last capture, and only
    # when it was accepted: after a refused one the device holds the moved
    # bias, and storing would keep that.

    def store(self) -> tuple[bool, str]:
        """Store the last capture in the sensor's non-volatile memory: (success, message)."""
        good = self.good_capture
        if good is None or self.last_capture is not good:
            why = ('no gyro bias was captured in this session' if self.last_capture is None
                   else f'the last capture was not accepted ({self.last_capture.summary}), '
                        f'and the device uses what it captured')
            return False, (f'refused: {why}. Nothing stored: capture with the sensor still '
                           f'(~/capture_gyro_bias), then store.')
        text = format_vector(good.bias)

        def operation(link: DeviceLink) -> int:
            quantity = self._device.dialogue.transfer_to_non_volatile(link, GYRO_BIAS_QUANTITY)
            self._forget()  # the pause is the operation's, not the radio's
            return quantity

        try:
            quantity = self._device.run_paused(operation)
        except OPERATION_ERRORS as exc:
            message = (f'gyro bias store (0xD0) not confirmed: {exc}; the sensor may or may '
                       f'not have stored {text} rad/s (counted as an EEPROM write)')
            self._log.warning(message)
            return False, message
        if quantity != GYRO_BIAS_QUANTITY:
            refused = 'refused (0xFFFF)' if quantity == INVALID_QUANTITY else \
                f'answered quantity {quantity}, not {GYRO_BIAS_QUANTITY}'
            message = (f'gyro bias store {refused}: the sensor did not store {text} rad/s in '
                       f'its non-volatile memory; it uses it until power-off. Use the '
                       f'gyro_bias parameter (or calibration_file) to apply it at every start')
            self._log.error(message)
            return False, message
        message = (f"gyro bias {text} rad/s stored in the sensor's non-volatile memory "
                   f'(0xD0, one EEPROM write): it loads it at every power-up')
        self._log.warning(message)
        return True, message


def calibration_yaml(node_name: str, bias: Vector3) -> str:
    """
    Return a ROS 2 parameter file that sets ``gyro_bias`` for ``node_name``.

    The values are written with ``repr``, which reads back as the same double,
    so the bias the node writes next time is the one captured, to the bit; a
    mantissa without a point gets one (``1e-09`` is text to YAML 1.1, and a
    string is no bias).
    """
    def number(value: float) -> str:
        text = repr(float(value))
        mantissa, e, exponent = text.partition('e')
        return text if '.' in mantissa else f'{mantissa}.0{e}{exponent}'

    values = ', '.join(number(v) for v in bias)
    return (f'# Written by ~/capture_gyro_bias (i3dmgx2_driver) at '
            f'{time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}: load it with\n'
            f'# --params-file <this file> (after the main one) to write this bias at start.\n'
            f'{node_name}:\n'
            f'  ros__parameters:\n'
            f'    gyro_bias: [{values}]\n')


def write_calibration_file(path: str, node_name: str, bias: Vector3) -> None:
    """Write ``calibration_yaml`` to ``path`` whole (a new file renamed over the old)."""
    path = os.path.expanduser(path)
    temporary = f'{path}.tmp'
    with open(temporary, 'w') as handle:
        handle.write(calibration_yaml(node_name, bias))
    os.replace(temporary, path)


# -- the self test -------------------------------------------------------------------
#
# The sensor's data polled (accel and rate, magnetometer), gravity judged at
# rest, each built-in test (0xFB) switched on and echoed, then off again, and
# the data rate measured once the stream resumed. The report is one line per
# step for std_srvs/Trigger and one DiagnosticStatus per step for
# diagnostic_msgs/SelfTest, from the same steps.

#: The self test expects |accel| = 1 g within this (g), the sensor at rest.
GRAVITY_TOLERANCE = 0.05
#: How long the self test measures the data rate after the stream resumes (s).
RATE_WINDOW = 1.0
#: Built-in test configuration bits (docs/protocol.md §6, 0xFB), one step each.
BIT_STEPS = (
    (0x04, 'magnetometer BIT', layouts.MAGNETOMETER),
    (0x08, 'reverse magnetometer BIT', layouts.MAGNETOMETER),
    (0x10, '+accel & rate BIT', layouts.ACCEL_ANG_RATE),
    (0x20, '-rate BIT', layouts.ACCEL_ANG_RATE),
)


class Step(NamedTuple):
    """One step of the self test: what, whether it passed, the numbers."""

    name: str
    passed: bool
    detail: str


def format_report(steps: Sequence[Step]) -> str:
    """One line per step, ``PASS``/``FAIL``, then a summary line."""
    lines = [f'{"PASS" if s.passed else "FAIL"} {s.name}: {s.detail}' for s in steps]
    failed = sum(1 for s in steps if not s.passed)
    lines.append(f'self test {"passed" if not failed else "FAILED"}: '
                 f'{len(steps) - failed}/{len(steps)} steps passed')
    return '\n'.join(lines)


def to_statuses(steps: Sequence[Step], prefix: str,
                hardware_id: str) -> list[DiagnosticStatus]:
    """One DiagnosticStatus per step: OK or ERROR, the step's numbers as its message."""
    return [DiagnosticStatus(
        level=DiagnosticStatus.OK if step.passed else DiagnosticStatus.ERROR,
        name=f'{prefix}{step.name}', message=step.detail, hardware_id=hardware_id,
        values=[KeyValue(key='result', value='PASS' if step.passed else 'FAIL')])
        for step in steps]


def gravity_step(accel: Vector3, tolerance: float = GRAVITY_TOLERANCE) -> Step:
    """Judge the mean acceleration of a sensor at rest: |a| = 1 g ± ``tolerance``."""
    size = norm(accel)
    passed = math.isfinite(size) and abs(size - 1.0) <= tolerance
    return Step('gravity at rest', passed,
                f'|accel| = {size:.4f} g (expected 1 ± {tolerance:g} g), '
                f'accel {format_vector(accel, 4)} g')


def rate_step(measured_hz: float | None, expected_hz: float | None,
              tolerance: float = RATE_TOLERANCE) -> Step:
    """Judge the data rate measured after the stream resumed."""
    if measured_hz is None:
        return Step('data rate', False, 'no records after the stream was restarted')
    if not expected_hz:
        return Step('data rate', False, f'{measured_hz:.1f} Hz; configured rate unknown')
    error = measured_hz / expected_hz - 1.0
    return Step('data rate', abs(error) <= tolerance,
                f'{measured_hz:.2f} Hz measured, {expected_hz:.2f} Hz configured '
                f'({error:+.1%}, tolerance ±{tolerance:.0%})')


class SelfTestRun:
    """
    Run the self test's steps on the device and log the report.

    ``device`` runs the device steps with the stream paused;
    ``published()`` returns (records published, read time of the last), for
    the rate; ``forget_last_sample()`` keeps the pause from counting as lost
    records; ``stop`` cuts the rate window short at shutdown.
    """

    def __init__(self, device: Device, published: Callable[[], tuple[int, float]],
                 forget_last_sample: Callable[[], None], stop: threading.Event,
                 log: RcutilsLogger) -> None:
        self._device = device
        self._published = published
        self._forget = forget_last_sample
        self._stop = stop
        self._log = log

    def steps(self) -> list[Step]:
        """Run every step of the self test and log the report; return the steps."""
        try:
            steps = self._device.run_paused(self._device_steps)
        except OPERATION_ERRORS as exc:
            steps = [Step('device operation', False, f'could not complete: {exc}')]
        steps.append(self._measure_rate())
        report = format_report(steps)
        # One call site per severity: rclpy refuses to change a call site's severity.
        if all(step.passed for step in steps):
            self._log.info(f'self test:\n{report}')
        else:
            self._log.warning(f'self test:\n{report}')
        return steps

    def _device_steps(self, link: DeviceLink) -> list[Step]:
        """Run the steps that need the device alone (with the stream stopped)."""
        steps: list[Step] = []
        accel = None
        try:
            accel, rate = poll_inertial(link)
            steps.append(Step('accel & angular rate respond (0xC2)', True,
                              f'mean of {POLLS}: accel {format_vector(accel, 4)} g, '
                              f'rate {format_vector(rate, 4)} rad/s'))
        except DeviceTimeout as exc:
            steps.append(Step('accel & angular rate respond (0xC2)', False, str(exc)))
        try:
            mag = link.request(bytes((layouts.MAGNETOMETER,)), layouts.MAGNETOMETER).mag
            detail = (f'mag {format_vector(mag, 4)} G' if not any(map(math.isnan, mag))
                      else 'answered NaN (no new reading, or no magnetometer)')
            steps.append(Step('magnetometer responds (0xC7)', True, detail))
        except DeviceTimeout as exc:
            steps.append(Step('magnetometer responds (0xC7)', False, str(exc)))
        if accel is not None:
            steps.append(gravity_step(accel))
        else:
            steps.append(Step('gravity at rest', False, 'no acceleration to judge'))
        try:
            for bit, name, sensor in BIT_STEPS:
                steps.append(self._bit_step(link, bit, name, sensor))
        finally:
            steps.append(self._bit_step(link, 0x00, 'built-in test off', None))
            # While the stream is still stopped: the timer gap across the pause is
            # the operation's doing, not the radio's.
            self._forget()
        return steps

    @staticmethod
    def _bit_step(link: DeviceLink, bit: int, name: str, sensor: int | None) -> Step:
        """Switch one built-in test on (0: all off); PASS if the device echoes it."""
        label = f'{name} (0xFB config 0x{bit:02X})'
        try:
            reply = link.request(commands.built_in_test(bit), layouts.BUILT_IN_TEST)
        except DeviceTimeout as exc:
            hint = '; power-cycle the sensor to be sure it is off' if not bit else ''
            return Step(label, False, f'{exc}{hint}')
        if reply.config != bit:
            return Step(label, False, f'device echoed config 0x{reply.config:02X}')
        detail = 'accepted'
        try:
            if sensor == layouts.MAGNETOMETER:
                mag = link.request(bytes((sensor,)), sensor).mag
                detail += f'; mag under test {format_vector(mag, 4)} G'
            elif sensor == layouts.ACCEL_ANG_RATE:
                reading = link.request(bytes((sensor,)), sensor)
                detail += (f'; accel under test {format_vector(reading.accel, 4)} g, '
                           f'rate {format_vector(reading.angular_rate, 4)} rad/s')
        except DeviceTimeout:
            detail += '; no reading under test (not judged)'
        return Step(label, True, detail)

    def _measure_rate(self) -> Step:
        """Measure the published rate over :data:`RATE_WINDOW` after the stream resumed."""
        count, first = self._published()
        if self._stop.wait(RATE_WINDOW):
            return Step('data rate', False, 'driver shutting down')
        measured = None
        now_count, last = self._published()
        if now_count > count and last > first:
            measured = (now_count - count) / (last - first)
        return rate_step(measured, self._device.status().expected_rate_hz)


# -- the services --------------------------------------------------------------------

class DeviceServices:
    """
    The ``~/capture_gyro_bias``, ``~/store_gyro_bias`` and ``~/self_test`` services.

    ``node`` provides the services, the logger and the
    ``gyro_bias_sampling_ms`` parameter; ``device`` the status and the
    exclusive operations; ``published()`` returns (records published, read
    time of the last), for the self test's rate; ``forget_last_sample()``
    keeps a pause from counting as lost records; ``capture_on_start`` asks
    for one capture once streaming. ``refusal``, if given, returns why a
    call must be refused now ('' to serve it): a managed node that is not
    active answers so at once. ``calibrated(flag)``, if given, is told
    whether the device uses a good gyro bias after every capture that
    reached the device (``~/is_calibrated``). ``prefix`` goes before the
    services' names (``~/<name>/`` for each of several sensors). With one
    sensor, an accepted capture is written to the ``calibration_file``
    parameter's file when it names one, and a configured ``gyro_bias`` (the
    dialogue writes it at every start) makes the device calibrated from the
    start.
    """

    def __init__(self, node: Node, device: Device, published: Callable[[], tuple[int, float]],
                 forget_last_sample: Callable[[], None], capture_on_start: bool = False,
                 refusal: Callable[[], str] | None = None,
                 calibrated: Callable[[bool], None] | None = None,
                 prefix: str = '~/') -> None:
        self.node = node
        self._calibrated = calibrated or (lambda flag: None)
        self._device = device
        self._refusal = refusal or (lambda: '')
        self._log = node.get_logger()
        self._busy = threading.Lock()
        self._stop = threading.Event()
        #: What is running now ('' when idle), for diagnostics.
        self.operation = ''
        #: The capture (and what the last ones came to), and the self test.
        self.gyro_bias = GyroBiasCapture(device, forget_last_sample, self._calibrated,
                                         self._log)
        self.self_test_run = SelfTestRun(device, published, forget_last_sample, self._stop,
                                         self._log)
        group = MutuallyExclusiveCallbackGroup()
        self.capture_service = node.create_service(
            Trigger, f'{prefix}capture_gyro_bias', self._on_capture, callback_group=group)
        self.store_service = node.create_service(
            Trigger, f'{prefix}store_gyro_bias', self._on_store, callback_group=group)
        #: One sensor's node: the calibration file and a known bias are its (parameters.py).
        self._single = prefix == '~/'
        if self._single and self._parameter('gyro_bias'):
            self._calibrated(True)
        self.self_test_service = node.create_service(
            Trigger, f'{prefix}self_test', self._on_self_test, callback_group=group)
        self.diagnostic_self_test_service = node.create_service(
            SelfTest, f'{prefix}diagnostic_self_test', self._on_diagnostic_self_test,
            callback_group=group)
        self._start_thread: threading.Thread | None = None
        if capture_on_start:
            self._start_thread = threading.Thread(
                target=self._capture_on_start, name='gx2-bias-on-start', daemon=True)
            self._start_thread.start()

    def stop(self) -> None:
        """Stop waiting (the capture at start, the rate window); the link aborts the rest."""
        self._stop.set()

    def destroy(self) -> None:
        """Stop, and remove the services from the node (the managed node's cleanup)."""
        self.stop()
        self.node.destroy_service(self.capture_service)
        self.node.destroy_service(self.store_service)
        self.node.destroy_service(self.self_test_service)
        self.node.destroy_service(self.diagnostic_self_test_service)

    def wait_idle(self, timeout: float) -> bool:
        """
        Wait until no operation runs (after the supervisor stopped); True if none does.

        At shutdown, so that a call cut short by the link's abort still gets
        its answer out before the node (and its service) is destroyed.
        """
        if not self._busy.acquire(timeout=timeout):
            return False
        self._busy.release()
        return True

    def calibration(self) -> tuple[Calibration | None, Calibration | None]:
        """Return the last capture attempt and the last accepted capture (diagnostics)."""
        return self.gyro_bias.last_capture, self.gyro_bias.good_capture

    # -- service callbacks (executor) ---------------------------------------

    def _on_capture(self, request: Trigger.Request, response: Trigger.Response
                    ) -> Trigger.Response:
        response.success, response.message = self.capture_gyro_bias()
        return response

    def _on_store(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        response.success, response.message = self.store_gyro_bias()
        return response

    def _on_self_test(self, request: Trigger.Request, response: Trigger.Response
                      ) -> Trigger.Response:
        response.success, response.message = self.self_test()
        return response

    def _on_diagnostic_self_test(self, request: SelfTest.Request,
                                 response: SelfTest.Response) -> SelfTest.Response:
        steps = self.self_test_steps()
        info = self._device.status().info
        response.id = info.serial_number if info is not None and info.serial_number else ''
        response.passed = bytes((all(step.passed for step in steps),))
        response.status = to_statuses(steps, f'{self.node.get_name()}: ', response.id)
        return response

    # -- operations -----------------------------------------------------------

    def _exclusive(self, name: str, body: Callable[[], tuple[bool, str]]) -> tuple[bool, str]:
        """Run one operation at a time; refuse at once when another runs."""
        refusal = self._refusal()
        if refusal:
            return False, f'refused: {refusal}'
        if not self._busy.acquire(blocking=False):
            return False, f'refused: {self.operation or "another operation"} is in progress'
        self.operation = name
        try:
            return body()
        finally:
            self.operation = ''
            self._busy.release()

    def capture_gyro_bias(self) -> tuple[bool, str]:
        """Capture the gyro bias (0xCD) with the stream paused; return (success, message)."""
        return self._exclusive('gyro bias capture', self._capture)

    def _parameter(self, name: str) -> Any:
        """Return a parameter's value; None when the node does not declare it or it is unset."""
        if not self.node.has_parameter(name):
            return None
        try:
            return self.node.get_parameter(name).value
        except ParameterUninitializedException:
            return None  # an empty array (the bias left to the sensor) is declared unset

    def _capture(self) -> tuple[bool, str]:
        ok, message = self.gyro_bias.run(int(self._parameter('gyro_bias_sampling_ms')))
        path = self._parameter('calibration_file') if self._single else ''
        if ok and path:
            bias = self.gyro_bias.good_capture.bias
            try:
                write_calibration_file(path, self.node.get_fully_qualified_name(), bias)
            except OSError as exc:
                note = f'calibration_file {path} not written: {exc}'
                self._log.error(note)
                return False, f'{message}; but {note}'
            note = (f'written to {path} (gyro_bias): load it with --params-file {path} at '
                    f'the next start')
            self._log.info(f'gyro bias {note}')
            message = f'{message}; {note}'
        return ok, message

    def store_gyro_bias(self) -> tuple[bool, str]:
        """Store the last accepted capture on the sensor (0xD0); return (success, message)."""
        return self._exclusive('gyro bias store', self.gyro_bias.store)

    def _capture_on_start(self) -> None:
        """Wait for the first streaming start, then capture once (own thread)."""
        while self._device.status().state is not State.STREAMING:
            if self._stop.wait(0.1):
                return
        ok, message = self.capture_gyro_bias()
        if not ok:
            self._log.warning(f'capture_gyro_bias_on_start: {message}')

    def self_test(self) -> tuple[bool, str]:
        """Run the self test; return (all steps passed, one line per step)."""
        return self._exclusive('self test', self._self_test)

    def self_test_steps(self) -> list[Step]:
        """Run the self test; return its steps (one failed step when it is refused)."""
        steps: list[Step] = []

        def run() -> tuple[bool, str]:
            steps.extend(self.self_test_run.steps())
            return True, ''

        _, refusal = self._exclusive('self test', run)
        return steps or [Step('self test', False, refusal)]

    def _self_test(self) -> tuple[bool, str]:
        steps = self.self_test_run.steps()
        return all(step.passed for step in steps), format_report(steps)


# -- ~/save_capture: the fault capture's last seconds, on demand ------------------------

class SaveCaptureService:
    """
    ``~/save_capture`` (std_srvs/Trigger): write the fault capture's last seconds now.

    One per node (the capture is the port's, whichever sensors share it).
    The reply's message is the file's path, or why none was written (the
    fault capture off, nothing read yet, the directory not writable). Its
    own callback group: writing a few hundred kilobytes never waits for a
    30 s gyro bias capture, nor holds one up.
    """

    def __init__(self, node: Node, capture: FaultCapture) -> None:
        self._node = node
        self._capture = capture
        self.service = node.create_service(
            Trigger, '~/save_capture', self._save,
            callback_group=MutuallyExclusiveCallbackGroup())

    def _save(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            path = self._capture.save('request')
        except (OSError, ValueError) as exc:
            response.success, response.message = False, f'no capture written: {exc}'
            return response
        self._node.get_logger().info(f'capture saved on request: {path}')
        response.success, response.message = True, path
        return response

    def destroy(self) -> None:
        """Remove the service from the node (a managed node's cleanup)."""
        self._node.destroy_service(self.service)
