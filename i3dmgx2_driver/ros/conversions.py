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
From a 0xCC record to sensor_msgs: units, frames and covariances.

Kept apart from the node so the arithmetic can be tested without a port, and
so the node's reader thread does nothing but fill preallocated messages.
"""

from collections.abc import Sequence
import math

from sensor_msgs.msg import Imu, MagneticField

from ..codec.orientation import body_vector, ENU, orientation
from ..codec.records import AccelAngRateMagOrientation

#: Standard gravity (m/s^2 per g), the factor the device's g units use.
STANDARD_GRAVITY = 9.80665
#: Tesla per Gauss.
TESLA_PER_GAUSS = 1e-4


def frame_id_for(frame_id: str, convention: str) -> str:
    """REP-103: a frame in NED axes carries the suffix ``_ned``."""
    if convention == ENU or frame_id.endswith('_ned'):
        return frame_id
    return frame_id + '_ned'


def diagonal_covariance(stddev: float) -> list:
    """Variance on the diagonal; all zeros (unknown) when ``stddev`` is 0."""
    variance = stddev * stddev
    return [variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance]


def set_stamp(header, stamp: float) -> None:
    """Write a float time (s) into a header's sec/nanosec."""
    sec = math.floor(stamp)
    nanosec = round((stamp - sec) * 1e9)
    if nanosec >= 1_000_000_000:
        sec += 1
        nanosec -= 1_000_000_000
    header.stamp.sec = int(sec)
    header.stamp.nanosec = nanosec


class MessageFactory:
    """
    Fill ``Imu`` and ``MagneticField`` messages from 0xCC records.

    The messages are allocated once and refilled for every record: publish()
    serialises them at once, and allocating on the hot path costs latency.
    """

    def __init__(self, frame_id: str, convention: str, orientation_stddev: float,
                 angular_velocity_stddev: float, linear_acceleration_stddev: float,
                 magnetic_field_stddev: float) -> None:
        self.convention = convention
        self.frame_id = frame_id_for(frame_id, convention)
        self._orientation_cov = diagonal_covariance(orientation_stddev)
        self._invalid_orientation_cov = [-1.0] + [0.0] * 8
        self._orientation_valid = True
        imu = Imu()
        imu.header.frame_id = self.frame_id
        imu.orientation_covariance = self._orientation_cov
        imu.angular_velocity_covariance = diagonal_covariance(angular_velocity_stddev)
        imu.linear_acceleration_covariance = diagonal_covariance(linear_acceleration_stddev)
        self.imu = imu
        mag = MagneticField()
        mag.header.frame_id = self.frame_id
        mag.magnetic_field_covariance = diagonal_covariance(magnetic_field_stddev)
        self.mag = mag

    def fill_imu(self, record: AccelAngRateMagOrientation, stamp: float) -> Imu:
        """Refill and return the Imu message for ``record``."""
        imu = self.imu
        convention = self.convention
        set_stamp(imu.header, stamp)
        q = orientation(record.matrix, convention)
        valid = not math.isnan(q.w)
        if valid != self._orientation_valid:
            # REP-145 / sensor_msgs: -1 in the first element: no orientation.
            imu.orientation_covariance = (self._orientation_cov if valid
                                          else self._invalid_orientation_cov)
            self._orientation_valid = valid
        o = imu.orientation
        if valid:
            o.x, o.y, o.z, o.w = q
        else:
            o.x, o.y, o.z, o.w = 0.0, 0.0, 0.0, 1.0
        w = body_vector(record.angular_rate, convention)
        av = imu.angular_velocity
        av.x, av.y, av.z = w
        a = body_vector(record.accel, convention)
        la = imu.linear_acceleration
        la.x = a[0] * STANDARD_GRAVITY
        la.y = a[1] * STANDARD_GRAVITY
        la.z = a[2] * STANDARD_GRAVITY
        return imu

    def fill_mag(self, mag_gauss: Sequence[float], stamp: float) -> MagneticField:
        """Refill and return the MagneticField message (caller skips NaN)."""
        msg = self.mag
        set_stamp(msg.header, stamp)
        m = body_vector(mag_gauss, self.convention)
        f = msg.magnetic_field
        f.x = m[0] * TESLA_PER_GAUSS
        f.y = m[1] * TESLA_PER_GAUSS
        f.z = m[2] * TESLA_PER_GAUSS
        return msg


def mag_is_valid(mag_gauss: Sequence[float]) -> bool:
    """Tell whether a field is a reading: NaN means "no new reading" (protocol.md)."""
    return not (math.isnan(mag_gauss[0]) or math.isnan(mag_gauss[1])
                or math.isnan(mag_gauss[2]))
