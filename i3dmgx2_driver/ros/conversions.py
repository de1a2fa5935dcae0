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
From a streamed record to sensor_msgs: units, frames and covariances.

Kept apart from the node so the arithmetic can be tested without a port, and
so the node's reader thread does nothing but fill preallocated messages.

Which quantities a record carries comes from its row in the stream table
(``codec/streams.py``, read off the command table's layouts); here each
becomes its part of the message. A quantity the record lacks is marked as
sensor_msgs/Imu defines it: zeros, and -1 in element 0 of its covariance.
An orientation comes from the matrix M (0xCC, 0xC8) or from the Euler angles
(0xCF) through the same matrix, so both give the same quaternion for the
same attitude, in either convention.

The node publishes each message already serialized (cdr.py says why): a
packer turns a record's fields, where they lie in the unpacked packet
(``DataPacket.values``), into the message's CDR bytes with one
precompiled ``struct``, the frame and the covariances packed into it once.
``test/test_serialized_messages.py`` holds the bytes to rclpy's own
serializer on many records of every stream.
"""

from collections.abc import Callable
from dataclasses import dataclass
import math
import struct

from .cdr import CDR_LE, StampedDoubles
from .mag_calibration import field_correction, IDENTITY, ZERO
from ..codec import streams
from ..codec.layouts import LAYOUTS
from ..codec.orientation import ENU, matrix_from_euler, quaternion
from ..codec.streams import Stream

#: Standard gravity (m/s^2 per g), the factor the device's g units use.
STANDARD_GRAVITY = 9.80665
#: Tesla per Gauss.
TESLA_PER_GAUSS = 1e-4
#: Covariance of a quantity the message does not carry (sensor_msgs/Imu).
MISSING_COVARIANCE = (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
#: Orientation of a record without one: zeros, as sensor_msgs/Imu asks.
_NO_ORIENTATION = (0.0, 0.0, 0.0, 0.0)
#: Orientation of a matrix that is no rotation (garbage): the identity, marked unknown.
_UNREADABLE_ORIENTATION = (0.0, 0.0, 0.0, 1.0)
#: A covariance as it goes in the message: nine little-endian float64.
_COVARIANCE = struct.Struct('<9d')
#: A record's fields, as a packer takes them, and the stamp's sec and nanosec.
Packer = Callable[[tuple, int, int], bytes | None]


def frame_id_for(frame_id: str, convention: str) -> str:
    """REP-103: a frame in NED axes carries the suffix ``_ned``."""
    if convention == ENU or frame_id.endswith('_ned'):
        return frame_id
    return frame_id + '_ned'


def diagonal_covariance(stddev: float) -> list:
    """Variance on the diagonal; all zeros (unknown) when ``stddev`` is 0."""
    variance = stddev * stddev
    return [variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance]


def stamp_parts(stamp: float) -> tuple[int, int]:
    """Split a float time (s) into the (sec, nanosec) of a builtin_interfaces/Time."""
    sec = math.floor(stamp)
    nanosec = round((stamp - sec) * 1e9)
    if nanosec >= 1_000_000_000:
        sec += 1
        nanosec -= 1_000_000_000
    return int(sec), nanosec


def set_stamp(header, stamp: float) -> None:
    """Write a float time (s) into a header's sec/nanosec."""
    header.stamp.sec, header.stamp.nanosec = stamp_parts(stamp)


@dataclass(frozen=True)
class MessageSettings:
    """
    How one sensor's records become messages: its frame, the axes, the covariances.

    The fields are named as the parameters that set them (ros/parameter_table.py);
    a standard deviation of 0 is unknown (all-zero covariance).
    """

    frame_id: str
    frame_convention: str
    orientation_stddev: float = 0.0
    angular_velocity_stddev: float = 0.0
    linear_acceleration_stddev: float = 0.0
    magnetic_field_stddev: float = 0.0
    stream: Stream = streams.DEFAULT
    #: The field's calibration, the sensor's axes (mag_calibration.py): T, and row-major.
    mag_hard_iron: tuple[float, ...] = ZERO
    mag_soft_iron: tuple[float, ...] = IDENTITY


class MessageFactory:
    """
    The packers of one sensor's records: its stream, frame, axes and covariances bound once.

    :attr:`imu_cdr` and :attr:`mag_cdr` take a record's fields
    (``DataPacket.values``) and the stamp's sec and nanosec, and return the
    message's CDR bytes; ``mag_cdr`` None for a field of NaN (no new
    reading), and is None itself for a stream without a field. Where each
    quantity sits in the fields is read once from the stream's row of the
    command table; per record there is only the arithmetic and one pack.
    """

    def __init__(self, settings: MessageSettings) -> None:
        self.convention = settings.frame_convention
        self.stream = stream = settings.stream
        self.frame_id = frame_id_for(settings.frame_id, self.convention)
        layout = LAYOUTS[stream.code]
        #: Where each field of the stream's records starts in their values.
        self._at = {field.name: plan if isinstance(plan, int) else plan.start
                    for field, plan in zip(layout.reply, layout.plan, strict=True)}
        self.imu_cdr = self._imu(settings)
        self.mag_cdr = self._mag(settings) if stream.mag else None

    def packer(self, name: str) -> Packer:
        """Return the packer ``name`` of a record topic (publishers.RECORD_TOPICS)."""
        return getattr(self, f'{name}_cdr')

    def _imu(self, settings: MessageSettings) -> Packer:
        """
        Return the Imu packer: orientation by Shepperd's method, SI units, covariances.

        A quantity the stream lacks is zeros with -1 in its covariance.
        """
        stream, at, enu = self.stream, self._at, self.convention == ENU
        convention = self.convention
        # Header, then orientation (4 float64) and its covariance, angular velocity (3)
        # and its covariance, linear acceleration (3) and its covariance.
        layout = StampedDoubles(self.frame_id, '4d72s3d72s3d72s')
        frame, flen, pack = layout.frame, len(layout.frame), layout.struct.pack
        matrix = at.get('matrix') if stream.orientation == streams.MATRIX else None
        roll = at.get('roll') if stream.orientation == streams.EULER else None
        rate = at.get(stream.angular_rate) if stream.angular_rate else None
        accel = at.get(stream.accel) if stream.accel else None
        missing = _COVARIANCE.pack(*MISSING_COVARIANCE)
        q_cov, w_cov, a_cov = (
            _COVARIANCE.pack(*diagonal_covariance(stddev)) if present else missing
            for present, stddev in ((stream.orientation, settings.orientation_stddev),
                                    (rate is not None, settings.angular_velocity_stddev),
                                    (accel is not None, settings.linear_acceleration_stddev)))
        g, isnan = STANDARD_GRAVITY, math.isnan

        def imu_cdr(v: tuple, sec: int, nanosec: int) -> bytes:
            if matrix is not None:
                q, qc = quaternion(v, matrix, convention), q_cov
            elif roll is not None:
                q = quaternion(matrix_from_euler(v[roll], v[roll + 1], v[roll + 2]), 0,
                               convention)
                qc = q_cov
            else:
                q, qc = _NO_ORIENTATION, missing
            if isnan(q[3]):
                # REP-145 / sensor_msgs: -1 in the first element: no orientation.
                q, qc = _UNREADABLE_ORIENTATION, missing
            if rate is None:
                wx = wy = wz = 0.0
            elif enu:  # FRD to FLU: y and z negated
                wx, wy, wz = v[rate], -v[rate + 1], -v[rate + 2]
            else:
                wx, wy, wz = v[rate], v[rate + 1], v[rate + 2]
            if accel is None:
                ax = ay = az = 0.0
            elif enu:
                ax, ay, az = v[accel] * g, -v[accel + 1] * g, -v[accel + 2] * g
            else:
                ax, ay, az = v[accel] * g, v[accel + 1] * g, v[accel + 2] * g
            return pack(CDR_LE, sec, nanosec, flen, frame, q[0], q[1], q[2], q[3], qc,
                        wx, wy, wz, w_cov, ax, ay, az, a_cov)
        return imu_cdr

    def _mag(self, settings: MessageSettings) -> Packer:
        """Return the MagneticField packer (tesla): None for a field of NaN, no new reading."""
        layout = StampedDoubles(self.frame_id, '3d72s')
        frame, flen, pack = layout.frame, len(layout.frame), layout.struct.pack
        cov = _COVARIANCE.pack(*diagonal_covariance(settings.magnetic_field_stddev))
        field, enu, t = self._at[self.stream.mag], self.convention == ENU, TESLA_PER_GAUSS
        isnan = math.isnan
        # The field's calibration, in the sensor's axes, Gauss (None: none asked for).
        calibrate = field_correction(settings.mag_hard_iron, settings.mag_soft_iron, t)

        def mag_cdr(v: tuple, sec: int, nanosec: int) -> bytes | None:
            x, y, z = v[field], v[field + 1], v[field + 2]
            if isnan(x) or isnan(y) or isnan(z):  # no new reading (docs/protocol.md §7)
                return None
            if calibrate is not None:
                x, y, z = calibrate((x, y, z))
            if enu:
                y, z = -y, -z
            return pack(CDR_LE, sec, nanosec, flen, frame, x * t, y * t, z * t, cov)
        return mag_cdr
