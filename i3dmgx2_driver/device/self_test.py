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
The self test: the sensor's data polled, its built-in tests, the data rate.

The sensor's data polled (accel and rate, magnetometer, temperatures),
gravity judged at rest, each built-in test (0xFB) switched on and echoed,
then off again, and the data rate measured once the stream resumed. A step
whose command the sensor's firmware lacks is skipped with the reason
(:func:`temperature_step`), not failed: the sensor is not at fault. Each judgement is a pure
function of the numbers, tested without a device. The report is one line
per step for std_srvs/Trigger (:func:`format_report`) and one
DiagnosticStatus per step for diagnostic_msgs/SelfTest (ros/services.py),
from the same steps.
"""

from collections.abc import Callable, Sequence
import math
import threading
from typing import Any, NamedTuple

from .link import DeviceError, DeviceLink
from .operation import Device, format_vector, norm, OPERATION_ERRORS, poll_inertial, POLLS
from .record_rate import RATE_TOLERANCE, RateMeter
from .sensor_firmware import SensorFirmware
from ..codec import command_firmware as fw
from ..codec import commands, layouts
from ..codec.records import Vector3

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
    #: Not run: the sensor's firmware lacks its command (``passed`` stays True).
    skipped: bool = False

    @property
    def verdict(self) -> str:
        """Return ``PASS``, ``FAIL`` or ``SKIP``, as the report writes it."""
        return 'SKIP' if self.skipped else 'PASS' if self.passed else 'FAIL'


def format_report(steps: Sequence[Step]) -> str:
    """One line per step, ``PASS``/``FAIL``/``SKIP``, then a summary line."""
    lines = [f'{s.verdict} {s.name}: {s.detail}' for s in steps]
    failed, skipped = sum(not s.passed for s in steps), sum(s.skipped for s in steps)
    ran = len(steps) - skipped
    lines.append(f'self test {"passed" if not failed else "FAILED"}: {ran - failed}/{ran} steps '
                 f'passed' + (f', {skipped} skipped (the firmware lacks them)' if skipped else ''))
    return '\n'.join(lines)


def _answered(name: str, ask: Callable[[], str]) -> Step:
    """Step ``name``: passed with what ``ask()`` says, failed with the DeviceError it raises."""
    try:
        return Step(name, True, ask())
    except DeviceError as exc:
        return Step(name, False, str(exc))


def _poll(link: DeviceLink, code: int) -> Any:
    """Poll record ``code`` once; return its reply."""
    return link.request(bytes((code,)), code)


def temperature_step(link: DeviceLink, firmware: SensorFirmware) -> Step:
    """Poll the temperatures (0xD1) once; skipped on a firmware without them."""
    name, code = 'temperatures respond (0xD1)', layouts.TEMPERATURES
    if not fw.has(firmware.version, code):
        return Step(name, True, f'skipped: 0x{code:02X} needs firmware {fw.text(fw.needs(code))};'
                                f' this sensor has {fw.text(firmware.version)}', skipped=True)
    return _answered(name, lambda: f'accelerometer {_poll(link, code).accel_celsius:.1f} C')


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
    return Step('data rate', abs(error) <= tolerance, f'{measured_hz:.2f} Hz measured, '
                f'{expected_hz:.2f} Hz configured ({error:+.1%}, tolerance ±{tolerance:.0%})')


class SelfTestRun:
    """
    Run the self test's steps on the device and log the report.

    ``device`` runs the device steps with the stream paused;
    ``published()`` returns (records published, read time of the last), for
    the rate; ``forget_last_sample()`` keeps the pause from counting as lost
    records; ``stop`` cuts the rate window short at shutdown. ``log`` is any
    object with ``info/warning`` methods (the node's rclpy logger).
    """

    def __init__(self, device: Device, published: Callable[[], tuple[int, float]],
                 forget_last_sample: Callable[[], None], stop: threading.Event, log: Any) -> None:
        self._device, self._log = device, log
        self._published, self._forget, self._stop = published, forget_last_sample, stop

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
        polled: list[Vector3] = []

        def inertial() -> str:
            accel, rate = poll_inertial(link)
            polled.append(accel)
            return (f'mean of {POLLS}: accel {format_vector(accel, 4)} g, '
                    f'rate {format_vector(rate, 4)} rad/s')

        def magnetometer() -> str:
            mag = _poll(link, layouts.MAGNETOMETER).mag
            return (f'mag {format_vector(mag, 4)} G' if not any(map(math.isnan, mag))
                    else 'answered NaN (no new reading, or no magnetometer)')

        steps = [_answered('accel & angular rate respond (0xC2)', inertial),
                 _answered('magnetometer responds (0xC7)', magnetometer),
                 temperature_step(link, self._device.firmware),
                 gravity_step(polled[0]) if polled
                 else Step('gravity at rest', False, 'no acceleration to judge')]
        try:
            steps.extend(self._bit_step(link, *step) for step in BIT_STEPS)
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
        except DeviceError as exc:
            hint = '; power-cycle the sensor to be sure it is off' if not bit else ''
            return Step(label, False, f'{exc}{hint}')
        if reply.config != bit:
            return Step(label, False, f'device echoed config 0x{reply.config:02X}')
        detail = 'accepted'
        try:
            if sensor == layouts.MAGNETOMETER:
                detail += f'; mag under test {format_vector(_poll(link, sensor).mag, 4)} G'
            elif sensor == layouts.ACCEL_ANG_RATE:
                reading = _poll(link, sensor)
                detail += (f'; accel under test {format_vector(reading.accel, 4)} g, '
                           f'rate {format_vector(reading.angular_rate, 4)} rad/s')
        except DeviceError:
            detail += '; no reading under test (not judged)'
        return Step(label, True, detail)

    def _measure_rate(self) -> Step:
        """Measure the published rate over :data:`RATE_WINDOW` after the stream resumed."""
        meter = RateMeter()
        meter.update(*self._published(), running=True)
        if self._stop.wait(RATE_WINDOW):
            return Step('data rate', False, 'driver shutting down')
        measured = meter.update(*self._published(), running=True)
        return rate_step(measured, self._device.status().expected_rate_hz)
