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
The gyro bias capture (0xCD): run it, judge it, keep what it came to, store it (0xD0).

The device captures the bias over ``gyro_bias_sampling_ms`` and uses it at
once, whatever happened meanwhile; so the capture polls the accelerometer
and gyros before and after, judges them (a pure function of the numbers,
tested without a device), and says whether the sensor was still. What a
capture came to is a :class:`Calibration`, which diagnostics shows and
``~/is_calibrated`` follows. The services (ros/services.py) serve it; the
parameter file an accepted capture may be written to is ros/calibration_file.py.
"""

from collections.abc import Callable
import math
import time
from typing import Any, NamedTuple

from .link import DeviceLink
from .operation import Device, format_vector, norm, OPERATION_ERRORS, poll_inertial
from ..codec import commands, layouts
from ..codec.records import GYRO_BIAS_QUANTITY, INVALID_QUANTITY, Vector3

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


class Calibration(NamedTuple):
    """The outcome of the last gyro bias capture of this session."""

    #: Host time (s since the epoch) of the capture.
    time: float
    #: Whether the bias was accepted (the sensor stayed still).
    accepted: bool
    #: The captured bias (rad/s), sensor axes; None when no reply came.
    bias: Vector3 | None
    sampling_ms: int
    #: One line on what happened (why it was refused, or that it is in use).
    summary: str


def judge_capture(bias: Vector3, accel_before: Vector3, accel_after: Vector3, rate_after: Vector3,
                  max_bias: float = MAX_GYRO_BIAS, max_residual: float = MAX_RESIDUAL_RATE,
                  max_accel_change: float = MAX_ACCEL_CHANGE) -> list[str]:
    """
    Return why a captured gyro bias cannot be trusted; empty if it can.

    Three independent signs of motion, so that no single unlucky moment (a
    sway reversing direction just as the capture ends) hides it: a bias too
    large to be one, a gravity vector that changed between before and after,
    and an angular rate that is not about zero once the new bias is applied.
    """
    change = [a - b for a, b in zip(accel_after, accel_before, strict=True)]
    signs = ((norm(bias), max_bias, 'captured bias |{:.4f}| rad/s exceeds {:g}'),
             (norm(change), max_accel_change, 'gravity vector changed by {:.4f} g (over {:g})'),
             (norm(rate_after), max_residual,
              'angular rate after the capture |{:.4f}| rad/s (over {:g})'))
    return [text.format(size, limit) for size, limit, text in signs
            if not math.isfinite(size) or size > limit]


class GyroBiasCapture:
    """
    Capture the gyro bias with the stream paused, judge it, and keep what it came to.

    ``device`` runs the exchange with the stream paused;
    ``forget_last_sample()`` keeps the pause from counting as lost records;
    ``calibrated(flag)`` is told whether the device uses a good gyro bias
    after every capture that reached the device (``~/is_calibrated``).
    ``log`` is any object with ``info/warning/error`` methods (the node's
    rclpy logger).
    """

    def __init__(self, device: Device, forget_last_sample: Callable[[], None],
                 calibrated: Callable[[bool], None], log: Any) -> None:
        self._device, self._log = device, log
        self._forget, self._calibrated = forget_last_sample, calibrated
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
            accel_before, reply, accel_after, rate_after = self._device.run_paused(operation)
        except OPERATION_ERRORS as exc:
            summary = f'no capture: {exc}'
            self.last_capture = Calibration(started, False, None, sampling_ms, summary)
            self._log.warning(f'gyro bias capture failed: {exc}')
            return False, f'gyro bias capture failed: {exc}'
        bias: Vector3 = tuple(reply.bias)
        reasons = judge_capture(bias, accel_before, accel_after, rate_after)
        text = format_vector(bias)
        if reasons:
            self._reached_device(Calibration(started, False, bias, sampling_ms,
                                             'the sensor moved: ' + '; '.join(reasons)))
            message = (f'refused: the sensor moved during the capture ({"; ".join(reasons)}). '
                       f'The device now uses the captured bias {text} rad/s until the next '
                       f'capture or a power cycle: capture again with the sensor still.')
            self._log.warning(message)
            return False, message
        self._reached_device(Calibration(started, True, bias, sampling_ms, f'bias {text} rad/s'))
        lacking = self._device.firmware.refusal('the gyro bias store',
                                                layouts.TRANSFER_TO_NON_VOLATILE)
        keep = (f'{lacking}: the gyro_bias parameter applies it at every start' if lacking
                else '~/store_gyro_bias stores it')
        message = (f'gyro bias captured over {sampling_ms} ms: {text} rad/s; the device uses '
                   f'it until power-off (not stored in non-volatile memory: {keep})')
        self._log.info(message)
        return True, message

    def _reached_device(self, calibration: Calibration) -> None:
        """
        Keep what a capture the device answered came to, and say whether its bias is good.

        The device uses the captured bias either way; an accepted one is also
        written back after a power cycle from now on, in place of the parameter's.
        """
        self.last_capture = calibration
        if calibration.accepted:
            self.good_capture = calibration
            self._device.dialogue.gyro_bias = calibration.bias
        self._calibrated(calibration.accepted)

    # -- keeping it ----------------------------------------------------------
    #
    # An accepted capture lives in the sensor's RAM. Two ways keep it: the
    # sensor's non-volatile memory (0xD0, asked for by ~/store_gyro_bias, one
    # EEPROM write each), or a parameter file the node loads at its next start
    # and writes with 0xCA (no EEPROM wear; ros/calibration_file.py). Only the
    # last capture, and only when it was accepted: after a refused one the
    # device holds the moved bias, and storing would keep that.

    def store(self) -> tuple[bool, str]:
        """
        Store the last capture in the sensor's non-volatile memory: (success, message).

        Refused at once, nothing sent, on a firmware without 0xD0 (before
        2.1.12): it would answer nothing, and the store would look lost.
        """
        lacking = self._device.firmware.refusal('the gyro bias store',
                                                layouts.TRANSFER_TO_NON_VOLATILE)
        if lacking:
            return False, (f'refused: {lacking}. Nothing sent. A captured bias is used until '
                           f'power-off; the gyro_bias parameter (or calibration_file) applies '
                           f'one at every start')
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
