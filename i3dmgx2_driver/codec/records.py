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
Immutable records: one class per reply of the 3DM-GX2, in the protocol's units.

Vectors are ``(x, y, z)`` tuples in the sensor's own axes (x forward, y right,
z down). Matrices are 9-tuples, row-major, exactly as the device sends them.
Units are the device's (g, rad/s, Gauss, timer ticks): conversion to SI and to
ROS conventions is the job of the layers above, so that nothing here can
round a value before a test compares it bit for bit.
"""

from typing import NamedTuple

Vector3 = tuple[float, float, float]
Matrix3 = tuple[float, float, float, float, float, float, float, float, float]

#: Ticks of the device timer per second (docs/protocol.md §8).
TICKS_PER_SECOND = 19_660_800


class PingReply(NamedTuple):
    """Answer of the base station to a wireless ping (0x02)."""

    ok: bool


class RawAccelAngRate(NamedTuple):
    """0xC1: raw A/D codes of the accelerometers and gyros."""

    accel_raw: Vector3
    angular_rate_raw: Vector3
    timer: int


class AccelAngRate(NamedTuple):
    """0xC2: acceleration (g) and angular rate (rad/s)."""

    accel: Vector3
    angular_rate: Vector3
    timer: int


class DeltaAngleVelocity(NamedTuple):
    """0xC3: delta angle (rad) and delta velocity (g*s) over one cycle."""

    delta_angle: Vector3
    delta_velocity: Vector3
    timer: int


class ContinuousModeReply(NamedTuple):
    """0xC4: the command the sensor now streams (0 when it stopped)."""

    command: int
    timer: int


class OrientationMatrix(NamedTuple):
    """0xC5: M, with v_sensor = M * v_earth (earth NED, sensor FRD)."""

    matrix: Matrix3
    timer: int


class OrientationUpdateMatrix(NamedTuple):
    """0xC6: the incremental rotation of the last calculation cycle."""

    matrix: Matrix3
    timer: int


class Magnetometer(NamedTuple):
    """0xC7: magnetic field (Gauss); NaN means no new reading."""

    mag: Vector3
    timer: int


class AccelAngRateOrientation(NamedTuple):
    """0xC8: acceleration, angular rate and orientation matrix."""

    accel: Vector3
    angular_rate: Vector3
    matrix: Matrix3
    timer: int


class AccelBias(NamedTuple):
    """0xC9: the accelerometer bias now in use (g)."""

    bias: Vector3
    timer: int


class GyroBias(NamedTuple):
    """0xCA: the gyro bias now in use (rad/s)."""

    bias: Vector3
    timer: int


class AccelAngRateMag(NamedTuple):
    """0xCB: acceleration, angular rate and magnetic field."""

    accel: Vector3
    angular_rate: Vector3
    mag: Vector3
    timer: int


class AccelAngRateMagOrientation(NamedTuple):
    """0xCC: the full inertial record the driver streams."""

    accel: Vector3
    angular_rate: Vector3
    mag: Vector3
    matrix: Matrix3
    timer: int


class CapturedGyroBias(NamedTuple):
    """0xCD: the gyro bias measured over the sampling time (rad/s)."""

    bias: Vector3
    timer: int


class EulerAngles(NamedTuple):
    """0xCE: roll, pitch, yaw (rad), aircraft ZYX convention."""

    roll: float
    pitch: float
    yaw: float
    timer: int


class EulerAnglesAngRate(NamedTuple):
    """0xCF: Euler angles (rad) and angular rate (rad/s)."""

    roll: float
    pitch: float
    yaw: float
    angular_rate: Vector3
    timer: int


#: 0xD0's quantities: which bias to store in non-volatile memory.
ACCEL_BIAS_QUANTITY = 1
GYRO_BIAS_QUANTITY = 2
#: 0xD0's reply when it stored nothing (an invalid quantity, or refused).
INVALID_QUANTITY = 0xFFFF


class TransferToNonVolatile(NamedTuple):
    """0xD0: the quantity stored to EEPROM (0xFFFF: invalid request)."""

    quantity: int
    timer: int


class Temperatures(NamedTuple):
    """0xD1: A/D codes of the accelerometer and the three gyro sensors."""

    accel_code: int
    gyro_codes: tuple[int, int, int]
    timer: int

    @property
    def accel_celsius(self) -> float:
        """Accelerometer temperature, by the formula of docs/protocol.md §7."""
        return code_to_celsius(self.accel_code)


class StabilisedAccelAngRateMag(NamedTuple):
    """0xD2: gyro-stabilised acceleration and magnetic field, angular rate."""

    accel: Vector3
    angular_rate: Vector3
    mag: Vector3
    timer: int


class DeltaAngleVelocityMag(NamedTuple):
    """0xD3: delta angle, delta velocity and magnetic field."""

    delta_angle: Vector3
    delta_velocity: Vector3
    mag: Vector3
    timer: int


class EepromWritten(NamedTuple):
    """0xE4: the word now stored at the written address."""

    value: int


class EepromWord(NamedTuple):
    """0xE5: the word read from EEPROM."""

    value: int


class FirmwareVersion(NamedTuple):
    """0xE9: firmware version number (e.g. 2103 for 2.1.03)."""

    version: int

    @property
    def text(self) -> str:
        """Return the version as the manual writes it (``2.1.03``)."""
        major, rest = divmod(self.version, 1000)
        minor, patch = divmod(rest, 100)
        return f'{major}.{minor}.{patch:02d}'


class DeviceIdentifier(NamedTuple):
    """0xEA: one of the device's identifier strings."""

    selector: int
    text: str


class BuiltInTest(NamedTuple):
    """0xFB: the test configuration bits the sensor accepted."""

    config: int


def code_to_celsius(code: int) -> float:
    """Convert a temperature A/D code to degrees Celsius (docs/protocol.md §7)."""
    return (code * 3.3 / 4096.0 - 0.5) * 100.0
