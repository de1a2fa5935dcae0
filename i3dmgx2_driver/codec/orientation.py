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
Orientation: Shepperd's matrix-to-quaternion method and the two conventions.

The device's matrix M maps earth (north-east-down) coordinates into sensor
(x forward, y right, z down) coordinates, so the sensor's attitude in the
earth frame is M transposed. ROS (REP-103) wants east-north-up and x forward,
y left, z up; both changes of axes are fixed permutations with sign flips,
applied on each side of the attitude:

    R_enu_flu = P * M^T * D,   P = [[0, 1, 0], [1, 0, 0], [0, 0, -1]],
                               D = diag(1, -1, -1).

Pure Python, so the codec needs no numpy: the node's packers call
:func:`quaternion` on a record's fields where they lie, and the tests compare
it with scipy and with the attitudes built as matrices.
"""

from collections.abc import Sequence
import math
from typing import NamedTuple

Vector3 = tuple[float, float, float]
Matrix3 = tuple[float, float, float, float, float, float, float, float, float]

#: The two frame conventions the driver can publish in.
ENU = 'enu'
NED = 'ned'
CONVENTIONS = (ENU, NED)


class Quaternion(NamedTuple):
    """A unit quaternion in ROS order (x, y, z, w), with w >= 0."""

    x: float
    y: float
    z: float
    w: float


def quaternion(m: Sequence[float], at: int = 0, convention: str = '') -> tuple:
    """
    Return (x, y, z, w) of the rotation matrix ``m[at:at + 9]`` (row-major), by Shepperd.

    ``convention`` ENU or NED: ``m`` is the device's matrix M, and the
    quaternion is of the sensor's attitude in that convention (the module
    docstring), its elements read where they lie in ``m`` (a record's
    fields) without a matrix made in between; '': ``m`` is the attitude.

    Shepperd (1978) takes the square root of whichever of the trace and the
    three diagonal terms is largest, so the divisor is never below 1/2 and the
    result stays accurate for every rotation, 180 degrees included. The result
    is normalised because real matrices are float32 and only close to
    orthonormal, and w is made non-negative so that equal rotations give equal
    quaternions. A matrix that is no rotation gives NaNs.
    """
    if convention == ENU:  # P * M^T * D
        m00, m01, m02 = m[at + 1], -m[at + 4], -m[at + 7]
        m10, m11, m12 = m[at], -m[at + 3], -m[at + 6]
        m20, m21, m22 = -m[at + 2], m[at + 5], m[at + 8]
    elif convention == NED:  # M^T
        m00, m01, m02 = m[at], m[at + 3], m[at + 6]
        m10, m11, m12 = m[at + 1], m[at + 4], m[at + 7]
        m20, m21, m22 = m[at + 2], m[at + 5], m[at + 8]
    else:
        m00, m01, m02, m10, m11, m12, m20, m21, m22 = m[at:at + 9]
    # A rotation's elements square-sum to 3; far from that (a zero matrix,
    # garbage that passed a checksum) there is no orientation to give.
    if not 2.5 < m00 * m00 + m01 * m01 + m02 * m02 + m10 * m10 + m11 * m11 + m12 * m12 \
            + m20 * m20 + m21 * m21 + m22 * m22 < 3.5:
        return _NAN4
    trace = m00 + m11 + m22
    if trace >= m00 and trace >= m11 and trace >= m22:
        s = 2.0 * math.sqrt(max(1.0 + trace, 0.0)) or math.nan
        w, x, y, z = 0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s
    elif m00 >= m11 and m00 >= m22:
        s = 2.0 * math.sqrt(max(1.0 + m00 - m11 - m22, 0.0)) or math.nan
        w, x, y, z = (m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s
    elif m11 >= m22:
        s = 2.0 * math.sqrt(max(1.0 - m00 + m11 - m22, 0.0)) or math.nan
        w, x, y, z = (m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 - m00 - m11 + m22, 0.0)) or math.nan
        w, x, y, z = (m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if not 0.0 < norm < math.inf:
        # Garbage in (NaN, infinities, a zero matrix): say so, never raise.
        return _NAN4
    if w < 0.0:
        norm = -norm
    return (x / norm, y / norm, z / norm, w / norm)


_NAN4 = (math.nan,) * 4


def _checked(convention: str) -> str:
    if convention not in CONVENTIONS:
        raise ValueError(f'convention must be one of {CONVENTIONS}, got {convention!r}')
    return convention


def shepperd(m: Sequence[float]) -> Quaternion:
    """Convert a row-major 3x3 rotation matrix to a unit quaternion (:func:`quaternion`)."""
    return Quaternion(*quaternion(m))


def orientation(m: Sequence[float], convention: str) -> Quaternion:
    """Quaternion of the sensor attitude in the named convention."""
    return Quaternion(*quaternion(m, 0, _checked(convention)))


def body_vector(v: Sequence[float], convention: str) -> Vector3:
    """
    Express a body-frame vector (accel, rate, field) in the convention's body.

    FRD to FLU negates y and z; NED keeps the device's axes.
    """
    return (v[0], -v[1], -v[2]) if _checked(convention) == ENU else (v[0], v[1], v[2])


def matrix_from_quaternion(q: Quaternion) -> Matrix3:
    """Return the rotation matrix of a unit quaternion (row-major)."""
    x, y, z, w = q
    return (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y))


def euler_from_matrix(m: Sequence[float]) -> Vector3:
    """Roll, pitch, yaw (rad) from M as docs/protocol.md §9 defines them."""
    return (math.atan2(m[5], m[8]), math.asin(max(-1.0, min(1.0, -m[2]))),
            math.atan2(m[1], m[0]))


def matrix_from_euler(roll: float, pitch: float, yaw: float) -> Matrix3:
    """
    Return M (v_sensor = M * v_earth) from the aircraft ZYX angles of 0xCE/0xCF.

    The inverse of :func:`euler_from_matrix`: M = Rx(roll)^T Ry(pitch)^T
    Rz(yaw)^T, the earth-to-sensor rotation, so that an Euler record and a
    matrix record of the same attitude give the same orientation.
    """
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    sy, cy = math.sin(yaw), math.cos(yaw)
    return (cp * cy, cp * sy, -sp,
            sr * sp * cy - cr * sy, sr * sp * sy + cr * cy, sr * cp,
            cr * sp * cy + sr * sy, cr * sp * sy - sr * cy, cr * cp)
