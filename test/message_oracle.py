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
The messages the packers' bytes must read back as, filled as message objects (the oracle).

Built from the named record, field by field, with the codec's orientation
functions on whole matrices: the way the driver filled its messages before it
packed their bytes, kept here to check the packers (ros/conversions.py).
"""

import math
from typing import Any

from i3dmgx2_driver.codec import streams
from i3dmgx2_driver.codec.orientation import body_vector, matrix_from_euler, orientation
from i3dmgx2_driver.ros.conversions import (
    diagonal_covariance, frame_id_for, MessageSettings, MISSING_COVARIANCE, set_stamp,
    STANDARD_GRAVITY, TESLA_PER_GAUSS,
)
from packets import as_sent
from sensor_msgs.msg import Imu, MagneticField

#: Field values of the fixed records for checks.
_PROBE_FIELDS = {
    'accel': (0.125, -0.5, -1.0), 'angular_rate': (0.01, -0.02, 0.03),
    'mag': (0.2, -0.1, 0.4), 'matrix': (0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0),
    'roll': 0.5, 'pitch': -0.25, 'yaw': 2.0, 'timer': 123456,
}


def probe_records(stream: streams.Stream) -> list[Any]:
    """Return records of ``stream`` for checks: a plain one, one with a NaN attitude."""
    record_type = stream.record_type
    record = record_type(**{name: _PROBE_FIELDS[name] for name in record_type._fields})
    out = [record]
    if stream.orientation == streams.MATRIX:
        out.append(record._replace(matrix=(math.nan,) * 9))
    elif stream.orientation == streams.EULER:
        out.append(record._replace(roll=math.nan, pitch=math.nan, yaw=math.nan))
    return out


def fill_imu(settings: MessageSettings, record: Any, stamp: float) -> Imu:
    """Return the Imu message of ``record`` (as sent: float32) stamped ``stamp``."""
    record = as_sent(record)
    stream, convention = settings.stream, settings.frame_convention
    imu = Imu()
    imu.header.frame_id = frame_id_for(settings.frame_id, convention)
    set_stamp(imu.header, stamp)
    if stream.orientation == streams.MATRIX:
        matrix = record.matrix
    elif stream.orientation == streams.EULER:
        matrix = matrix_from_euler(record.roll, record.pitch, record.yaw)
    else:
        matrix = None
    imu.orientation_covariance = MISSING_COVARIANCE
    if matrix is None:
        q = (0.0, 0.0, 0.0, 0.0)
    else:
        q = orientation(matrix, convention)
        if math.isnan(q[3]):
            q = (0.0, 0.0, 0.0, 1.0)
        else:
            imu.orientation_covariance = diagonal_covariance(settings.orientation_stddev)
    o = imu.orientation
    o.x, o.y, o.z, o.w = q
    imu.angular_velocity_covariance = MISSING_COVARIANCE
    if stream.angular_rate:
        av = imu.angular_velocity
        av.x, av.y, av.z = body_vector(getattr(record, stream.angular_rate), convention)
        imu.angular_velocity_covariance = diagonal_covariance(settings.angular_velocity_stddev)
    imu.linear_acceleration_covariance = MISSING_COVARIANCE
    if stream.accel:
        a = body_vector(getattr(record, stream.accel), convention)
        la = imu.linear_acceleration
        la.x, la.y, la.z = (a[0] * STANDARD_GRAVITY, a[1] * STANDARD_GRAVITY,
                            a[2] * STANDARD_GRAVITY)
        imu.linear_acceleration_covariance = diagonal_covariance(
            settings.linear_acceleration_stddev)
    return imu


def fill_mag(settings: MessageSettings, record: Any, stamp: float) -> MagneticField | None:
    """Return the MagneticField message of ``record`` (as sent); None for a field of NaN."""
    record = as_sent(record)
    mag_gauss = record.mag
    if any(math.isnan(v) for v in mag_gauss):
        return None
    msg = MagneticField()
    msg.header.frame_id = frame_id_for(settings.frame_id, settings.frame_convention)
    set_stamp(msg.header, stamp)
    msg.magnetic_field_covariance = diagonal_covariance(settings.magnetic_field_stddev)
    m = body_vector(mag_gauss, settings.frame_convention)
    f = msg.magnetic_field
    f.x, f.y, f.z = (m[0] * TESLA_PER_GAUSS, m[1] * TESLA_PER_GAUSS, m[2] * TESLA_PER_GAUSS)
    return msg
