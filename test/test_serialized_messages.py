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
``fill_imu`` and ``fill_mag`` build, for every record, both frame conventions,
any frame name (its length moves the padding) and stamps at the edges of a
second.
"""

import math
import random
from types import SimpleNamespace

from i3dmgx2_driver.codec.orientation import matrix_from_quaternion, Quaternion
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.ros.conversions import MessageFactory, MessageSettings, stamp_parts
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


def _factory(frame: str, convention: str) -> MessageFactory:
    return MessageFactory(MessageSettings(
        frame_id=frame, frame_convention=convention, orientation_stddev=0.01,
        angular_velocity_stddev=0.002, linear_acceleration_stddev=0.03,
        magnetic_field_stddev=1e-6))


@pytest.mark.parametrize('convention', ['enu', 'ned'])
@pytest.mark.parametrize('frame', FRAMES)
def test_imu_bytes_read_back_as_the_filled_message(convention, frame):
    rng = random.Random(hash((convention, frame)) & 0xFFFF)
    factory = _factory(frame, convention)
    for index in range(50):
        record = _random_record(rng)
        stamp = STAMPS[index % len(STAMPS)] + rng.random() * (index % 2)
        data = factory.imu_cdr(record, stamp)
        expected = factory.fill_imu(record, stamp)
        assert deserialize_message(data, Imu) == expected
        assert len(data) == len(serialize_message(expected))


@pytest.mark.parametrize('convention', ['enu', 'ned'])
def test_imu_bytes_without_an_orientation(convention):
    factory = _factory('imu_link', convention)
    record = _random_record(random.Random(5))
    for matrix in ((math.nan,) * 9, (math.inf,) * 9, (1.0, math.nan) + (0.0,) * 7):
        no_orientation = record._replace(matrix=matrix)
        message = deserialize_message(factory.imu_cdr(no_orientation, 1.5), Imu)
        assert message == factory.fill_imu(no_orientation, 1.5)
        assert message.orientation_covariance[0] == -1.0
        assert (message.orientation.x, message.orientation.w) == (0.0, 1.0)
    # And back: the covariance is the configured one again.
    message = deserialize_message(factory.imu_cdr(record, 2.5), Imu)
    assert message.orientation_covariance[0] == pytest.approx(0.01 ** 2)
    assert message == factory.fill_imu(record, 2.5)


@pytest.mark.parametrize('convention', ['enu', 'ned'])
@pytest.mark.parametrize('frame', FRAMES)
def test_mag_bytes_read_back_as_the_filled_message(convention, frame):
    rng = random.Random(7)
    factory = _factory(frame, convention)
    for stamp in STAMPS:
        record = SimpleNamespace(mag=tuple(rng.uniform(-0.6, 0.6) for _ in range(3)))
        data = factory.mag_cdr(record, stamp)
        expected = factory.fill_mag(record, stamp)
        assert deserialize_message(data, MagneticField) == expected
        assert len(data) == len(serialize_message(expected))


def test_a_field_of_nan_is_no_reading_and_no_magnetic_field_message():
    factory = _factory('imu_link', 'enu')
    nothing = SimpleNamespace(mag=(math.nan, math.nan, math.nan))
    assert factory.mag_cdr(nothing, 1.0) is None and factory.fill_mag(nothing, 1.0) is None
    assert factory.packer('mag', True) == factory.mag_cdr
    assert factory.packer('mag', False) == factory.fill_mag


def test_the_start_up_check_passes_with_this_middleware_and_catches_a_mistake():
    factory = _factory('imu_link', 'enu')
    assert factory.serialized_matches()
    broken = _factory('imu_link', 'enu')
    real = broken.imu_cdr
    broken.imu_cdr = lambda record, stamp: real(record, stamp + 1.0)
    assert not broken.serialized_matches()


@pytest.mark.parametrize('stamp, parts', [
    (1.0, (1, 0)), (1.5, (1, 500_000_000)), (0.9999999999, (1, 0)),
    (1_700_000_000.25, (1_700_000_000, 250_000_000)), (0.0, (0, 0)),
])
def test_stamp_parts(stamp, parts):
    assert stamp_parts(stamp) == parts
