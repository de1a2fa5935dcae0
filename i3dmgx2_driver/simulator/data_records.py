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
The data records of one calculation cycle: the motion measured, less the bias corrections.

``BiasCorrections`` keeps the corrections the host wrote or captured and
their copies in non-volatile memory; ``RecordMaker`` builds each data
record of the codec's table from the motion model, the corrections and
the sensor's noise.
"""

import math
import random
import struct
from typing import Any

from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.codec.orientation import euler_from_matrix

from .motion import Motion, Vector3

#: 0xD0 answer for a quantity it does not know.
INVALID_QUANTITY = 0xFFFF

_ACCEL_COUNTS_PER_G = 32768 / 5.0           # +-5 g over the 16-bit A/D range
_GYRO_COUNTS_PER_RAD_S = 32768 / 5.235988   # +-300 deg/s
_A2D_ZERO = 32768.0
_FLOAT3 = struct.Struct('>3f')
_ZERO: Vector3 = (0.0, 0.0, 0.0)


def float32(v: Vector3) -> Vector3:
    """Round to float32: the device keeps what fits in its registers."""
    return _FLOAT3.unpack(_FLOAT3.pack(*v))


def _sub(a: Vector3, b: Vector3) -> Vector3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _scale(v: Vector3, k: float) -> Vector3:
    return (v[0] * k, v[1] * k, v[2] * k)


class BiasCorrections:
    """
    The accelerometer and gyro bias corrections in effect, and in non-volatile memory.

    A captured gyro bias (0xCD) takes effect when its sampling time is over.
    Those stored in non-volatile memory (0xD0) survive power cycles.
    """

    def __init__(self) -> None:
        self.accel: Vector3 = _ZERO
        self.gyro: Vector3 = _ZERO
        self._nv_accel: Vector3 = _ZERO
        self._nv_gyro: Vector3 = _ZERO
        self._pending_gyro: tuple[float, Vector3] | None = None

    def restore(self) -> None:
        """Take the corrections from non-volatile memory (power-up)."""
        self.accel = self._nv_accel
        self.gyro = self._nv_gyro
        self._pending_gyro = None

    def forget_capture(self) -> None:
        """Drop a gyro capture still running (power lost)."""
        self._pending_gyro = None

    def set_gyro(self, gyro: Vector3) -> None:
        """Use this gyro correction from now (a capture still running is dropped)."""
        self.gyro = gyro
        self._pending_gyro = None

    def capture_gyro(self, done_rel: float, bias: Vector3) -> None:
        """Use ``bias`` from ``done_rel`` on, when the capture's sampling is over."""
        self._pending_gyro = (done_rel, bias)

    def apply_capture(self, rel: float) -> None:
        """Take a captured gyro bias whose sampling is over at ``rel``."""
        if self._pending_gyro is not None and rel >= self._pending_gyro[0]:
            self.gyro = self._pending_gyro[1]
            self._pending_gyro = None

    def store(self, quantity: int, rel: float) -> int:
        """Copy a correction to non-volatile memory (1: accel, 2: gyro); return the quantity."""
        if quantity == 1:
            self._nv_accel = self.accel
        elif quantity == 2:
            self.apply_capture(rel)
            self._nv_gyro = self.gyro
        else:
            quantity = INVALID_QUANTITY
        return quantity


class RecordMaker:
    """Builds the data records of a cycle; draws its noise from the sensor's ``rng``."""

    def __init__(self, motion: Motion, rng: random.Random, temperature_c: float,
                 biases: BiasCorrections) -> None:
        self.motion = motion
        self._rng = rng
        self._temperature_c = temperature_c
        self._biases = biases

    def temperature_codes(self, rel: float) -> tuple[int, tuple[int, int, int]]:
        """A/D codes of the four temperature sensors: ~25 C, warming up slowly."""
        warm = self._temperature_c + 2.0 * (1.0 - math.exp(-rel / 600.0))

        def code(celsius: float) -> int:
            value = (celsius / 100.0 + 0.5) * 4096.0 / 3.3 + self._rng.gauss(0.0, 0.4)
            return max(0, min(4095, round(value)))

        return code(warm), (code(warm + 1.0), code(warm + 1.5), code(warm + 0.5))

    def record(self, code: int, rel: float, timer: int, dt: float) -> Any:
        """Build the record ``code`` of the cycle at ``rel`` (timer ``timer``, ``dt`` s long)."""
        if code == lay.TEMPERATURES:
            accel_code, gyro_codes = self.temperature_codes(rel)
            return rec.Temperatures(accel_code, gyro_codes, timer)
        meas = self.motion.measure(rel, self._rng)
        m = meas.truth.matrix
        accel = _sub(meas.accel, self._biases.accel)
        rate = _sub(meas.angular_rate, self._biases.gyro)
        mag = meas.mag
        if code == lay.ACCEL_ANG_RATE_MAG_ORIENTATION:
            return rec.AccelAngRateMagOrientation(accel, rate, mag, m, timer)
        if code == lay.ACCEL_ANG_RATE_MAG:
            return rec.AccelAngRateMag(accel, rate, mag, timer)
        if code == lay.ACCEL_ANG_RATE:
            return rec.AccelAngRate(accel, rate, timer)
        if code == lay.ACCEL_ANG_RATE_ORIENTATION:
            return rec.AccelAngRateOrientation(accel, rate, m, timer)
        if code == lay.RAW_ACCEL_ANG_RATE:
            return rec.RawAccelAngRate(
                tuple(_A2D_ZERO + a * _ACCEL_COUNTS_PER_G for a in accel),
                tuple(_A2D_ZERO + w * _GYRO_COUNTS_PER_RAD_S for w in rate), timer)
        if code == lay.DELTA_ANGLE_VELOCITY:
            return rec.DeltaAngleVelocity(_scale(rate, dt), _scale(accel, dt), timer)
        if code == lay.DELTA_ANGLE_VELOCITY_MAG:
            return rec.DeltaAngleVelocityMag(_scale(rate, dt), _scale(accel, dt), mag, timer)
        if code == lay.ORIENTATION_MATRIX:
            return rec.OrientationMatrix(m, timer)
        if code == lay.ORIENTATION_UPDATE_MATRIX:
            return rec.OrientationUpdateMatrix(self.motion.update_matrix(rel, dt), timer)
        if code == lay.MAGNETOMETER:
            return rec.Magnetometer(mag, timer)
        if code == lay.EULER_ANGLES:
            return rec.EulerAngles(*euler_from_matrix(m), timer)
        if code == lay.EULER_ANGLES_ANG_RATE:
            return rec.EulerAnglesAngRate(*euler_from_matrix(m), rate, timer)
        if code == lay.STABILISED_ACCEL_ANG_RATE_MAG:
            # Gyro-stabilised vectors are the filter's estimates: smooth, biased alike.
            bias = self.motion.config.accel_bias
            stab_accel = _sub(tuple(meas.truth.accel[i] + bias[i] for i in range(3)),
                              self._biases.accel)
            stab_mag = mag if math.isnan(mag[0]) else meas.truth.mag
            return rec.StabilisedAccelAngRateMag(stab_accel, rate, stab_mag, timer)
        raise ValueError(f'0x{code:02X} is not a data record')  # pragma: no cover
