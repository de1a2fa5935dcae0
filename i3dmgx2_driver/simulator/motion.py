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
Believable motion of the simulated sensor, as a closed-form function of time.

The attitude is given by aircraft (ZYX) Euler angles that sway sinusoidally
around an initial pose while the heading turns slowly, so the rotation axis
keeps changing and the angular rate never stays constant. Because the angles
are analytic, the body angular rate follows exactly from their derivatives
(the ZYX kinematic equations), and the orientation matrix, the gravity
reaction and the magnetic field are exactly consistent with it: a test can
integrate the rates or differentiate M and must find the other.

Frames follow docs/protocol.md §9: earth north-east-down, sensor x forward, y right,
z down, and ``v_sensor = M * v_earth``. Accelerations are in g (a sensor
lying flat reads about -1 g on z), rates in rad/s, fields in Gauss. Noise is
Gaussian and drawn from a caller-supplied ``random.Random`` so that a seed
reproduces a run. The default noise and biases are those measured on the
real records in fixtures/gx2_real_0xcc_records.txt.
"""

import dataclasses
import math
import random
from typing import NamedTuple

from i3dmgx2_driver.codec.orientation import matrix_from_euler

from .noise_model import NoiseConfig, NoiseStream

Vector3 = tuple[float, float, float]
Matrix3 = tuple[float, float, float, float, float, float, float, float, float]

_NAN = float('nan')
_ZERO: Vector3 = (0.0, 0.0, 0.0)
_TWO_PI = 2.0 * math.pi


@dataclasses.dataclass
class MotionConfig:
    """
    How the simulated sensor moves and how its inertial sensors err.

    Angles are in degrees because people think of poses that way; rates,
    biases and noise are in the device's units (g, rad/s, Gauss) so that they
    compare directly with what the records carry.
    """

    #: A sensor at rest: the attitude stays at ``initial_attitude_deg``.
    static: bool = False
    #: Roll, pitch, yaw (deg) of the resting pose; (0, 0, 0) is flat, facing north.
    initial_attitude_deg: Vector3 = (0.0, 0.0, 30.0)
    #: Peak sway of roll, pitch and yaw around the resting pose (deg).
    sway_amplitude_deg: Vector3 = (8.0, 5.0, 10.0)
    #: Period of each sway (s); unequal periods make the rotation axis wander.
    sway_period_s: Vector3 = (7.0, 11.0, 17.0)
    #: Steady turn of the heading (deg/s), on top of the yaw sway.
    yaw_rate_dps: float = 2.0
    #: Gyro bias (rad/s) the sensor shows before any bias correction.
    gyro_bias: Vector3 = (-0.0033, -0.0217, -0.0052)
    #: Accelerometer bias (g).
    accel_bias: Vector3 = (0.0, 0.0, 0.0)
    #: Standard deviation of the accelerometer noise (g).
    accel_noise: float = 0.00025
    #: Standard deviation of the gyro noise (rad/s).
    gyro_noise: float = 0.0015
    #: Standard deviation of the magnetometer noise (Gauss).
    mag_noise: float = 0.002
    #: Total intensity of the Earth's field (Gauss).
    field_strength: float = 0.5
    #: Inclination (dip) of the field below the horizon (deg; positive: north hemisphere).
    inclination_deg: float = 60.0
    #: Declination of the field east of true north (deg).
    declination_deg: float = -2.0
    #: No magnetometer (like the Inertia-Link): every reading is NaN.
    nan_mag: bool = False
    #: Chance that a cycle has no new magnetometer reading (NaN), as it updates slower.
    mag_nan_probability: float = 0.0
    #: The inertial sensors' noise term by term (noise_model.py: white noise, bias
    #: instability, random walk per axis) instead of ``gyro_noise`` and ``accel_noise``
    #: alone; None: those alone, white, as the simulator always made it.
    noise: NoiseConfig | None = None
    #: Iron that moves with the sensor (docs/magcal.md): the field read is
    #: ``soft_iron * true + hard_iron`` (Gauss, sensor axes, row-major), and the
    #: sensor's own attitude takes its heading from that field, as its filter does
    #: (magnetic: north of the field, not true north).
    hard_iron: Vector3 = (0.0, 0.0, 0.0)
    soft_iron: Matrix3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


#: The sway of each ``--motion``: the default; through every attitude (a magnetometer
#: calibration's sweep); level, turning in yaw alone (a ground robot turning in place).
MOTIONS = {'sway': {},
           'tumble': {'sway_amplitude_deg': (180.0, 80.0, 0.0), 'sway_period_s': (23.0, 37.0, 1.0),
                      'yaw_rate_dps': 13.0},
           'yaw': {'sway_amplitude_deg': (0.0, 0.0, 0.0), 'yaw_rate_dps': 12.0}}


class TrueState(NamedTuple):
    """The exact physical state at one instant, before any sensor error."""

    #: M, row-major: v_sensor = M * v_earth.
    matrix: Matrix3
    #: Body angular rate (rad/s), sensor axes.
    angular_rate: Vector3
    #: Specific force (g), sensor axes: the reaction to gravity.
    accel: Vector3
    #: Earth magnetic field (Gauss), sensor axes.
    mag: Vector3
    #: Roll, pitch, yaw (rad) of the attitude, yaw in (-pi, pi].
    euler: Vector3


class Measurement(NamedTuple):
    """What the raw sensors read at one instant: truth plus bias and noise."""

    accel: Vector3
    angular_rate: Vector3
    mag: Vector3
    truth: TrueState
    #: The sensor's own attitude (0xC5, 0xC8, 0xCC, Euler): its heading from the field read.
    matrix: Matrix3


def tilted_heading(field: Vector3, roll: float, pitch: float) -> float:
    """Return the heading (rad) a compass levelled by ``roll`` and ``pitch`` reads."""
    sr, cr, sp, cp = math.sin(roll), math.cos(roll), math.sin(pitch), math.cos(pitch)
    north = field[0] * cp + (field[1] * sr + field[2] * cr) * sp
    return math.atan2(field[2] * sr - field[1] * cr, north)


def mat_vec(m: Matrix3, v: Vector3) -> Vector3:
    """Return M * v for a row-major 3x3 matrix."""
    return (m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
            m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
            m[6] * v[0] + m[7] * v[1] + m[8] * v[2])


def mat_mul_transpose(a: Matrix3, b: Matrix3) -> Matrix3:
    """Return A * B^T, the rotation that takes B's frame to A's."""
    return tuple(
        a[3 * i] * b[3 * j] + a[3 * i + 1] * b[3 * j + 1] + a[3 * i + 2] * b[3 * j + 2]
        for i in range(3) for j in range(3))


class Motion:
    """
    The trajectory of one sensor: attitude, rates and fields at any time.

    Time is in seconds since the sensor powered up. ``set_static`` can freeze
    and release the motion at run time without a jump in attitude, so that a
    test can hold the sensor still for a gyro-bias capture, or shake it during
    one to see the capture go wrong.
    """

    def __init__(self, config: MotionConfig | None = None) -> None:
        self.config = c = config if config is not None else MotionConfig()
        self._base = tuple(math.radians(a) for a in c.initial_attitude_deg)
        self._amp = tuple(math.radians(a) for a in c.sway_amplitude_deg)
        self._omega = tuple(_TWO_PI / p if p > 0 else 0.0 for p in c.sway_period_s)
        self._yaw_rate = math.radians(c.yaw_rate_dps)
        inc, dec = math.radians(c.inclination_deg), math.radians(c.declination_deg)
        self.earth_field: Vector3 = (c.field_strength * math.cos(inc) * math.cos(dec),
                                     c.field_strength * math.cos(inc) * math.sin(dec),
                                     c.field_strength * math.sin(inc))
        # Motion time runs with true time while moving and stands still while
        # static, so that freezing and releasing never makes the attitude jump.
        self._frozen_tau: float | None = 0.0 if c.static else None
        self._offset = 0.0
        self._noise: NoiseStream | None = None
        self._iron = c.hard_iron != (0.0, 0.0, 0.0) or c.soft_iron != MotionConfig.soft_iron

    @property
    def static(self) -> bool:
        """Whether the sensor is at rest now."""
        return self._frozen_tau is not None

    def set_static(self, static: bool, t: float) -> None:
        """Stop (``True``) or resume (``False``) the motion at time ``t``."""
        if static and self._frozen_tau is None:
            self._frozen_tau = t - self._offset
        elif not static and self._frozen_tau is not None:
            self._offset = t - self._frozen_tau
            self._frozen_tau = None

    def _angles(self, t: float) -> tuple[Vector3, Vector3]:
        """Return the Euler angles and their time derivatives at ``t``."""
        frozen = self._frozen_tau is not None
        tau = self._frozen_tau if frozen else t - self._offset
        sway = [(base + amp * math.sin(omega * tau), amp * omega * math.cos(omega * tau))
                for base, amp, omega in zip(self._base, self._amp, self._omega, strict=True)]
        (roll, droll), (pitch, dpitch), (yaw, dyaw) = sway
        angles = (roll, pitch, yaw + self._yaw_rate * tau)
        return angles, _ZERO if frozen else (droll, dpitch, dyaw + self._yaw_rate)

    def state(self, t: float) -> TrueState:
        """Return the exact state at ``t`` (seconds since power-up)."""
        (roll, pitch, yaw), (droll, dpitch, dyaw) = self._angles(t)
        sr, cr, sp, cp = math.sin(roll), math.cos(roll), math.sin(pitch), math.cos(pitch)
        # ZYX kinematics: body rates from the Euler angle rates.
        rate = (droll - dyaw * sp, dpitch * cr + dyaw * sr * cp, -dpitch * sr + dyaw * cr * cp)
        m = matrix_from_euler(roll, pitch, yaw)
        # The accelerometer feels the reaction to gravity: -1 g along earth down.
        accel = (-m[2], -m[5], -m[8])
        # Heading as the device reports it: wrapped into (-pi, pi].
        heading = math.atan2(math.sin(yaw), math.cos(yaw))
        return TrueState(m, rate, accel, mat_vec(m, self.earth_field), (roll, pitch, heading))

    def update_matrix(self, t: float, dt: float) -> Matrix3:
        """Return the rotation of the last ``dt`` seconds, M(t) * M(t - dt)^T (0xC6)."""
        return mat_mul_transpose(self.state(t).matrix, self.state(t - dt).matrix)

    def mean_rate(self, t0: float, t1: float, points: int = 64) -> Vector3:
        """Return the true body rate averaged over [t0, t1] (for a bias capture)."""
        if t1 <= t0 or points < 2:
            return self.state(t0).angular_rate
        rates = [self.state(t0 + (t1 - t0) * k / (points - 1)).angular_rate
                 for k in range(points)]
        return tuple(sum(axis) / points for axis in zip(*rates, strict=True))

    def measure(self, t: float, rng: random.Random) -> Measurement:
        """Return what the raw sensors read at ``t``: truth, biases and noise."""
        c, truth, gauss = self.config, self.state(t), rng.gauss
        if c.noise is None:   # white alone, the accelerometer's drawn first
            accel_error = [gauss(0.0, c.accel_noise) for _ in range(3)]
            gyro_error = [gauss(0.0, c.gyro_noise) for _ in range(3)]
        else:
            if self._noise is None:  # seeded from the sensor's noise source: a seed repeats
                self._noise = NoiseStream(c.noise, rng.getrandbits(63))
            gyro_error, accel_error = self._noise.sample(t)
        accel = tuple(truth.accel[i] + c.accel_bias[i] + accel_error[i] for i in range(3))
        rate = tuple(truth.angular_rate[i] + c.gyro_bias[i] + gyro_error[i] for i in range(3))
        field, matrix = truth.mag, truth.matrix
        if self._iron:
            soft = mat_vec(c.soft_iron, field)
            field = tuple(f + h for f, h in zip(soft, c.hard_iron, strict=True))
            # As the sensor's filter: tilt from gravity, magnetic heading from the field read.
            roll, pitch, _ = truth.euler
            matrix = matrix_from_euler(roll, pitch, tilted_heading(field, roll, pitch))
        if c.nan_mag or (c.mag_nan_probability > 0.0 and rng.random() < c.mag_nan_probability):
            mag = (_NAN, _NAN, _NAN)
        else:
            mag = tuple(field[i] + gauss(0.0, c.mag_noise) for i in range(3))
        return Measurement(accel, rate, mag, truth, matrix)
