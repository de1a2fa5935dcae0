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

On the hot path the node publishes each message already serialized:
:meth:`MessageFactory.imu_cdr` packs the same Imu that :meth:`fill_imu` fills
straight into its CDR bytes with one ``struct.pack``. That skips ~20 Python
attribute writes and rclpy's conversion of the message object to C, the
largest share of the driver's own time from a packet read to ``publish()``
returned. The bytes are checked against rclpy's own serializer once at
start-up (:meth:`MessageFactory.serialized_matches`), and the tests check them
on many records of every stream.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import math
from operator import attrgetter
from typing import Any, NamedTuple

from sensor_msgs.msg import Imu, MagneticField

from .cdr import CDR_LE, reads_back, StampedDoubles
from .mag_calibration import field_correction, IDENTITY, ZERO
from ..codec import streams
from ..codec.orientation import body_vector, ENU, matrix_from_euler, orientation, Quaternion
from ..codec.streams import Stream

#: Standard gravity (m/s^2 per g), the factor the device's g units use.
STANDARD_GRAVITY = 9.80665
#: Tesla per Gauss.
TESLA_PER_GAUSS = 1e-4
#: Covariance of a quantity the message does not carry (sensor_msgs/Imu).
MISSING_COVARIANCE = (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_ZERO3 = (0.0, 0.0, 0.0)
#: Orientation of a record without one: zeros, as sensor_msgs/Imu asks.
_NO_ORIENTATION = Quaternion(0.0, 0.0, 0.0, 0.0)
#: Orientation of a matrix that is no rotation (garbage): the identity, marked unknown.
_UNREADABLE_ORIENTATION = Quaternion(0.0, 0.0, 0.0, 1.0)


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


#: Field values of the fixed records for the start-up check of the serialized messages.
_PROBE_FIELDS = {
    'accel': (0.125, -0.5, -1.0), 'angular_rate': (0.01, -0.02, 0.03),
    'mag': (0.2, -0.1, 0.4), 'matrix': (0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0),
    'roll': 0.5, 'pitch': -0.25, 'yaw': 2.0, 'timer': 123456,
}


def probe_records(stream: Stream) -> list[Any]:
    """Return records of ``stream`` for checks: a plain one, one with a NaN attitude."""
    record_type = stream.record_type
    record = record_type(**{name: _PROBE_FIELDS[name] for name in record_type._fields})
    out = [record]
    if stream.orientation == streams.MATRIX:
        out.append(record._replace(matrix=(math.nan,) * 9))
    elif stream.orientation == streams.EULER:
        out.append(record._replace(roll=math.nan, pitch=math.nan, yaw=math.nan))
    return out


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
    Fill ``Imu`` and ``MagneticField`` messages from the records of one stream.

    The messages are allocated once and refilled for every record: publish()
    serialises them at once, and allocating on the hot path costs latency.
    What each part of the Imu comes from is chosen once, here, from the
    stream's row of the table; the per-record work is only the arithmetic.
    """

    def __init__(self, settings: MessageSettings) -> None:
        self.convention = convention = settings.frame_convention
        self.stream = stream = settings.stream
        self.frame_id = frame_id_for(settings.frame_id, convention)
        # Each Imu part: how to get it from a record, and its covariance (missing: -1).
        if stream.orientation == streams.MATRIX:
            self._attitude = attrgetter('matrix')
        elif stream.orientation == streams.EULER:
            angles = attrgetter('roll', 'pitch', 'yaw')
            self._attitude = lambda record: matrix_from_euler(*angles(record))
        else:
            self._attitude = None
        self._rate = attrgetter(stream.angular_rate) if stream.angular_rate else None
        self._accel = attrgetter(stream.accel) if stream.accel else None
        self._orientation_cov = (tuple(diagonal_covariance(settings.orientation_stddev))
                                 if self._attitude else MISSING_COVARIANCE)
        self._angular_velocity_cov = (
            tuple(diagonal_covariance(settings.angular_velocity_stddev))
            if self._rate else MISSING_COVARIANCE)
        self._linear_acceleration_cov = (
            tuple(diagonal_covariance(settings.linear_acceleration_stddev))
            if self._accel else MISSING_COVARIANCE)
        imu = Imu()
        imu.header.frame_id = self.frame_id
        imu.orientation_covariance = self._orientation_cov
        imu.angular_velocity_covariance = self._angular_velocity_cov
        imu.linear_acceleration_covariance = self._linear_acceleration_cov
        self._shown_orientation_cov = self._orientation_cov
        self.imu = imu
        mag = MagneticField()
        mag.header.frame_id = self.frame_id
        mag.magnetic_field_covariance = diagonal_covariance(settings.magnetic_field_stddev)
        self.mag = mag
        # The same messages in CDR: header, then Imu's 37 float64 (orientation 4 and its
        # covariance 9, angular velocity 3 and 9, linear acceleration 3 and 9), or
        # MagneticField's 12 (field 3 and its covariance 9).
        imu_layout = StampedDoubles(self.frame_id, 37)
        self._imu_struct, self._frame_cdr = imu_layout.struct, imu_layout.frame
        self._mag_struct = StampedDoubles(self.frame_id, 12).struct
        self._magnetic_field_cov = tuple(mag.magnetic_field_covariance)
        self._calibrate = field_correction(settings.mag_hard_iron, settings.mag_soft_iron,
                                           TESLA_PER_GAUSS)

    def orientation(self, record: Any) -> tuple[Quaternion, tuple[float, ...]]:
        """Return the record's orientation and its covariance (both marked when missing)."""
        if self._attitude is None:
            return _NO_ORIENTATION, MISSING_COVARIANCE
        q = orientation(self._attitude(record), self.convention)
        if math.isnan(q.w):
            # REP-145 / sensor_msgs: -1 in the first element: no orientation.
            return _UNREADABLE_ORIENTATION, MISSING_COVARIANCE
        return q, self._orientation_cov

    def angular_velocity(self, record: Any) -> tuple[float, float, float]:
        """Return the record's angular rate (rad/s) in the convention's body axes."""
        if self._rate is None:
            return _ZERO3
        return body_vector(self._rate(record), self.convention)

    def linear_acceleration(self, record: Any) -> tuple[float, float, float]:
        """Return the record's acceleration (m/s^2) in the convention's body axes."""
        if self._accel is None:
            return _ZERO3
        a = body_vector(self._accel(record), self.convention)
        g = STANDARD_GRAVITY
        return (a[0] * g, a[1] * g, a[2] * g)

    def fill_imu(self, record: Any, stamp: float) -> Imu:
        """Refill and return the Imu message for ``record``."""
        imu = self.imu
        set_stamp(imu.header, stamp)
        q, q_cov = self.orientation(record)
        if q_cov is not self._shown_orientation_cov:
            imu.orientation_covariance = q_cov
            self._shown_orientation_cov = q_cov
        o = imu.orientation
        o.x, o.y, o.z, o.w = q
        av = imu.angular_velocity
        av.x, av.y, av.z = self.angular_velocity(record)
        la = imu.linear_acceleration
        la.x, la.y, la.z = self.linear_acceleration(record)
        return imu

    def imu_cdr(self, record: Any, stamp: float) -> bytes:
        """Return the Imu message of :meth:`fill_imu`, serialized (CDR bytes)."""
        sec, nanosec = stamp_parts(stamp)
        q, q_cov = self.orientation(record)
        return self._imu_struct.pack(
            CDR_LE, sec, nanosec, len(self._frame_cdr), self._frame_cdr,
            *q, *q_cov, *self.angular_velocity(record), *self._angular_velocity_cov,
            *self.linear_acceleration(record), *self._linear_acceleration_cov)

    def mag_cdr(self, record: Any, stamp: float) -> bytes | None:
        """Return the MagneticField message of :meth:`fill_mag`, serialized (CDR bytes)."""
        mag_gauss = record.mag
        if not mag_is_valid(mag_gauss):
            return None
        sec, nanosec = stamp_parts(stamp)
        m = body_vector(self._calibrate(mag_gauss) if self._calibrate else mag_gauss,
                        self.convention)
        t = TESLA_PER_GAUSS
        return self._mag_struct.pack(
            CDR_LE, sec, nanosec, len(self._frame_cdr), self._frame_cdr,
            m[0] * t, m[1] * t, m[2] * t, *self._magnetic_field_cov)

    def packer(self, name: str, serialized: bool) -> Callable[[Any, float], Any]:
        """
        Return the packer ``name`` of a record topic (publishers.RECORD_TOPICS).

        ``<name>_cdr`` when ``serialized`` (CDR bytes), else ``fill_<name>``
        (the message object); either returns None for a record with nothing
        to publish on that topic (a field of NaN: no new reading).
        """
        return getattr(self, f'{name}_cdr' if serialized else f'fill_{name}')

    def serialized_matches(self) -> bool:
        """Tell whether :meth:`imu_cdr` and :meth:`mag_cdr` read back as the messages (cdr.py)."""
        stamp = 1_700_000_000.123456789
        probes = probe_records(self.stream)
        with_field = _FieldRecord(_PROBE_FIELDS['mag'])
        # A generator: fill_imu refills one message, compared before the next fill.
        pairs = ((self.imu_cdr(record, stamp), self.fill_imu(record, stamp))
                 for record in (*probes, probes[0]))
        return reads_back(pairs) and reads_back(
            [(self.mag_cdr(with_field, stamp), self.fill_mag(with_field, stamp))])

    def fill_mag(self, record: Any, stamp: float) -> MagneticField | None:
        """Refill and return the MagneticField message of ``record``; None: no new reading."""
        mag_gauss = record.mag
        if not mag_is_valid(mag_gauss):
            return None
        msg = self.mag
        set_stamp(msg.header, stamp)
        m = body_vector(self._calibrate(mag_gauss) if self._calibrate else mag_gauss,
                        self.convention)
        f = msg.magnetic_field
        f.x = m[0] * TESLA_PER_GAUSS
        f.y = m[1] * TESLA_PER_GAUSS
        f.z = m[2] * TESLA_PER_GAUSS
        return msg


class _FieldRecord(NamedTuple):
    """A record with a field alone: what the MagneticField packers read of one."""

    mag: tuple[float, float, float]


def mag_is_valid(mag_gauss: Sequence[float]) -> bool:
    """Tell whether a field is a reading: NaN means "no new reading" (docs/protocol.md §7)."""
    return not (math.isnan(mag_gauss[0]) or math.isnan(mag_gauss[1])
                or math.isnan(mag_gauss[2]))
