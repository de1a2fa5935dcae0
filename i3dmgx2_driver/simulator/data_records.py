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
their copies in non-volatile memory. A record is read off the codec's layout
table: ``RecordMaker`` builds a ``Cycle`` and takes from it each field of the
record's layout, by the quantity the field holds (``Field.quantity``, else its
name), in the layout's order. A record type added to the table is made from
the quantities a cycle already has; only a new quantity needs a line here.
"""

import functools
import math
import random
import struct
from typing import Any

from i3dmgx2_driver.codec import layouts as lay, records as rec
from i3dmgx2_driver.codec.orientation import euler_from_matrix

from .motion import Matrix3, Measurement, Motion, Vector3

_ACCEL_COUNTS_PER_G = 32768 / 5.0           # +-5 g over the 16-bit A/D range
_GYRO_COUNTS_PER_RAD_S = 32768 / 5.235988   # +-300 deg/s
_A2D_ZERO = 32768.0
_FLOAT3 = struct.Struct('>3f')
_ZERO: Vector3 = (0.0, 0.0, 0.0)
#: Quantities the inertial sensors do not give: a record of only these reads none of them.
_NOT_INERTIAL = frozenset({'timer', 'accel_code', 'gyro_codes'})


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
        # In effect (accel, gyro), and in non-volatile memory.
        self.accel = self.gyro = self._nv_accel = self._nv_gyro = _ZERO
        self._pending_gyro: tuple[float, Vector3] | None = None

    def restore(self) -> None:
        """Take the corrections from non-volatile memory (power-up)."""
        self.accel, self.gyro, self._pending_gyro = self._nv_accel, self._nv_gyro, None

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
        """Copy a correction to non-volatile memory; return the quantity (0xFFFF: unknown)."""
        if quantity == rec.ACCEL_BIAS_QUANTITY:
            self._nv_accel = self.accel
        elif quantity == rec.GYRO_BIAS_QUANTITY:
            self.apply_capture(rel)
            self._nv_gyro = self.gyro
        else:
            quantity = rec.INVALID_QUANTITY
        return quantity


class Cycle:
    """
    One calculation cycle's quantities, each named as the layout table names a field.

    The inertial sensors are read once, noise and all, when ``inertial`` says
    the record carries something they give (the device samples them every
    cycle); the temperature codes are read when a field asks for them. Each
    quantity is worked out when a record first asks for it.
    """

    def __init__(self, maker: 'RecordMaker', rel: float, timer: int, dt: float,
                 inertial: bool) -> None:
        self._maker, self._rel, self._dt, self.timer = maker, rel, dt, timer
        self._meas = maker.motion.measure(rel, maker.rng) if inertial else None

    @property
    def _measured(self) -> Measurement:
        if self._meas is None:  # pragma: no cover - _NOT_INERTIAL names an inertial quantity
            raise ValueError('the inertial sensors were not read this cycle')
        return self._meas

    @functools.cached_property
    def accel(self) -> Vector3:
        """Acceleration (g) less the host's accelerometer bias correction."""
        return _sub(self._measured.accel, self._maker.biases.accel)

    @functools.cached_property
    def angular_rate(self) -> Vector3:
        """Angular rate (rad/s) less the host's gyro bias correction."""
        return _sub(self._measured.angular_rate, self._maker.biases.gyro)

    @property
    def mag(self) -> Vector3:
        """Magnetic field (Gauss), NaN when the magnetometer has no new reading."""
        return self._measured.mag

    @property
    def matrix(self) -> Matrix3:
        """Orientation matrix M: the true attitude, its heading from the field read (iron)."""
        return self._measured.matrix

    @property
    def update_matrix(self) -> Matrix3:
        """Rotation over this cycle, M(t) * M(t - dt)^T (0xC6)."""
        return self._maker.motion.update_matrix(self._rel, self._dt)

    @property
    def accel_raw(self) -> Vector3:
        """Accelerometer A/D codes, from the corrected acceleration."""
        return tuple(_A2D_ZERO + a * _ACCEL_COUNTS_PER_G for a in self.accel)

    @property
    def angular_rate_raw(self) -> Vector3:
        """Gyro A/D codes, from the corrected angular rate."""
        return tuple(_A2D_ZERO + w * _GYRO_COUNTS_PER_RAD_S for w in self.angular_rate)

    @property
    def delta_angle(self) -> Vector3:
        """Angle turned over the cycle (rad)."""
        return _scale(self.angular_rate, self._dt)

    @property
    def delta_velocity(self) -> Vector3:
        """Velocity gained over the cycle (g*s)."""
        return _scale(self.accel, self._dt)

    @functools.cached_property
    def _euler(self) -> Vector3:
        return euler_from_matrix(self.matrix)

    roll = property(lambda self: self._euler[0], doc='Roll (rad) of M.')
    pitch = property(lambda self: self._euler[1], doc='Pitch (rad) of M.')
    yaw = property(lambda self: self._euler[2], doc='Yaw (rad) of M.')

    @functools.cached_property
    def stabilised_accel(self) -> Vector3:
        """Gyro-stabilised acceleration: the filter's estimate, smooth, biased alike."""
        truth, bias = self._measured.truth.accel, self._maker.motion.config.accel_bias
        return _sub(tuple(t + b for t, b in zip(truth, bias, strict=True)),
                    self._maker.biases.accel)

    @property
    def stabilised_mag(self) -> Vector3:
        """Gyro-stabilised field: smooth, NaN as the magnetometer is."""
        return self.mag if math.isnan(self.mag[0]) else self._measured.truth.mag

    def _temperature_code(self, above: float) -> int:
        """A/D code of a temperature sensor ``above`` C over ~25 C, warming up slowly."""
        warm = self._maker.temperature_c + 2.0 * (1.0 - math.exp(-self._rel / 600.0))
        value = ((warm + above) / 100.0 + 0.5) * 4096.0 / 3.3 + self._maker.rng.gauss(0.0, 0.4)
        return max(0, min(4095, round(value)))

    @property
    def accel_code(self) -> int:
        """A/D code of the accelerometer's temperature sensor."""
        return self._temperature_code(0.0)

    @property
    def gyro_codes(self) -> tuple[int, int, int]:
        """A/D codes of the three gyros' temperature sensors, a little warmer."""
        return (self._temperature_code(1.0), self._temperature_code(1.5),
                self._temperature_code(0.5))


class RecordMaker:
    """
    Builds the data records of a cycle; draws its noise from the sensor's ``rng``.

    It holds what outlives a cycle: the motion, the noise source, the
    temperature the sensor powers up at and the host's bias corrections.
    """

    def __init__(self, motion: Motion, rng: random.Random, temperature_c: float,
                 biases: BiasCorrections) -> None:
        self.motion, self.rng, self.temperature_c, self.biases = motion, rng, temperature_c, biases

    def record(self, code: int, rel: float, timer: int, dt: float) -> Any:
        """Build the record ``code`` of the cycle at ``rel`` (timer ``timer``, ``dt`` s long)."""
        layout = lay.LAYOUTS[code]
        quantities = [field.quantity or field.name for field in layout.reply]
        cycle = Cycle(self, rel, timer, dt, not _NOT_INERTIAL.issuperset(quantities))
        return layout.record_type(*(getattr(cycle, quantity) for quantity in quantities))
