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
The node publishes ready-serialized messages: they must be the messages, exactly.

``MessageFactory.imu_cdr`` and ``mag_cdr`` pack the CDR bytes directly; rclpy
(through the middleware in use) must read them back as exactly the messages
the oracle fills field by field (message_oracle.py), for every record, both
frame conventions, any frame name (its length moves the padding) and stamps
at the edges of a second.
"""

import math
import random

from i3dmgx2_driver.codec.orientation import matrix_from_quaternion, Quaternion
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.ros.conversions import MessageFactory, MessageSettings, stamp_parts
from message_oracle import fill_imu, fill_mag
from packets import values_of
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Imu, MagneticField

FRAMES = ['imu_link', 'a', 'imu', 'abcdefg', 'abcdefgh', 'x' * 13, 'base/imu_ü', '']
STAMPS = [1_700_000_000.0, 1_700_000_000.999999999, 1_700_000_000.9999999996,
          1_700_000_000.123456789, 0.5, 2_000_000_000.000001]


def _random_record(rng: random.Random) -> AccelAngRateMagOrientation:
    q = [rng.gauss(0.0, 1.0) for _ in range(4)]
    norm = math.sqrt(sum(v * v for v in q))
    matrix = matrix_from_quaternion(Quaternion(*(v / norm for v in q)))

    def vector(scale: float) -> tuple:
        return tuple(rng.uniform(-scale, scale) for _ in range(3))

    return AccelAngRateMagOrientation(vector(5.0), vector(5.0), vector(0.6), matrix,
                                      rng.getrandbits(32))


def _settings(frame: str, convention: str) -> MessageSettings:
    return MessageSettings(
        frame_id=frame, frame_convention=convention, orientation_stddev=0.01,
        angular_velocity_stddev=0.002, linear_acceleration_stddev=0.03,
        magnetic_field_stddev=1e-6)


def _imu(factory: MessageFactory, record, stamp: float) -> bytes:
    return factory.imu_cdr(values_of(record), *stamp_parts(stamp))


def _mag(factory: MessageFactory, record, stamp: float) -> bytes | None:
    return factory.mag_cdr(values_of(record), *stamp_parts(stamp))


@pytest.mark.parametrize('convention', ['enu', 'ned'])
@pytest.mark.parametrize('frame', FRAMES)
def test_imu_bytes_read_back_as_the_filled_message(convention, frame):
    rng = random.Random(hash((convention, frame)) & 0xFFFF)
    settings = _settings(frame, convention)
    factory = MessageFactory(settings)
    for index in range(50):
        record = _random_record(rng)
        stamp = STAMPS[index % len(STAMPS)] + rng.random() * (index % 2)
        data = _imu(factory, record, stamp)
        expected = fill_imu(settings, record, stamp)
        assert deserialize_message(data, Imu) == expected
        assert len(data) == len(serialize_message(expected))


@pytest.mark.parametrize('convention', ['enu', 'ned'])
def test_imu_bytes_without_an_orientation(convention):
    settings = _settings('imu_link', convention)
    factory = MessageFactory(settings)
    record = _random_record(random.Random(5))
    for matrix in ((math.nan,) * 9, (math.inf,) * 9, (1.0, math.nan) + (0.0,) * 7):
        no_orientation = record._replace(matrix=matrix)
        message = deserialize_message(_imu(factory, no_orientation, 1.5), Imu)
        assert message == fill_imu(settings, no_orientation, 1.5)
        assert message.orientation_covariance[0] == -1.0
        assert (message.orientation.x, message.orientation.w) == (0.0, 1.0)
    # And back: the covariance is the configured one again.
    message = deserialize_message(_imu(factory, record, 2.5), Imu)
    assert message.orientation_covariance[0] == pytest.approx(0.01 ** 2)
    assert message == fill_imu(settings, record, 2.5)


@pytest.mark.parametrize('convention', ['enu', 'ned'])
@pytest.mark.parametrize('frame', FRAMES)
def test_mag_bytes_read_back_as_the_filled_message(convention, frame):
    rng = random.Random(7)
    settings = _settings(frame, convention)
    factory = MessageFactory(settings)
    for stamp in STAMPS:
        record = _random_record(rng)._replace(mag=tuple(rng.uniform(-0.6, 0.6) for _ in range(3)))
        data = _mag(factory, record, stamp)
        expected = fill_mag(settings, record, stamp)
        assert deserialize_message(data, MagneticField) == expected
        assert len(data) == len(serialize_message(expected))


def test_a_field_of_nan_is_no_reading_and_no_magnetic_field_message():
    settings = _settings('imu_link', 'enu')
    factory = MessageFactory(settings)
    nothing = _random_record(random.Random(3))._replace(mag=(math.nan, 0.1, 0.2))
    assert _mag(factory, nothing, 1.0) is None and fill_mag(settings, nothing, 1.0) is None
    assert factory.packer('mag') == factory.mag_cdr


@pytest.mark.parametrize('stamp, parts', [
    (1.0, (1, 0)), (1.5, (1, 500_000_000)), (0.9999999999, (1, 0)),
    (1_700_000_000.25, (1_700_000_000, 250_000_000)), (0.0, (0, 0)),
])
def test_stamp_parts(stamp, parts):
    assert stamp_parts(stamp) == parts
