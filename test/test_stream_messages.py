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
The record -> message table for every stream, without a node.

The serialized fast path reads back as the filled message for every stream;
what a record lacks is zeros with -1 in its covariance; and an Euler record
(0xCF) gives the same orientation as the matrix record (0xCC) of the same
calculation cycle, both checked against scipy in both conventions.
"""

import math

from i3dmgx2_driver.codec import streams
from i3dmgx2_driver.codec.orientation import euler_from_matrix, matrix_from_euler
from i3dmgx2_driver.ros.conversions import MessageFactory, MessageSettings, stamp_parts
from i3dmgx2_driver.simulator.motion import Motion, MotionConfig
from i3dmgx2_driver.simulator.sensor import SimulatedSensor
from message_oracle import fill_imu, probe_records
import numpy as np
from packets import values_of
import pytest
from rclpy.serialization import deserialize_message
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu

NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FRD_TO_FLU = np.diag([1.0, -1.0, -1.0])
MISSING = [-1.0] + [0.0] * 8


def settings(stream: streams.Stream, convention: str) -> MessageSettings:
    return MessageSettings(
        frame_id='imu_link', frame_convention=convention, orientation_stddev=0.01,
        angular_velocity_stddev=0.002, linear_acceleration_stddev=0.03,
        magnetic_field_stddev=1e-6, stream=stream)


def factory(stream: streams.Stream, convention: str) -> MessageFactory:
    return MessageFactory(settings(stream, convention))


def imu(f: MessageFactory, record, stamp: float) -> Imu:
    """Return the Imu message the packer makes of ``record``, read back."""
    return deserialize_message(f.imu_cdr(values_of(record), *stamp_parts(stamp)), Imu)


def orientation(f: MessageFactory, record) -> tuple:
    o = imu(f, record, 1.0).orientation
    return (o.x, o.y, o.z, o.w)


def moving_sensor(seed: int) -> SimulatedSensor:
    """Return a sensor that turns through many attitudes (a large, varied motion)."""
    return SimulatedSensor(motion=Motion(MotionConfig(static=False)), seed=seed)


@pytest.mark.parametrize('convention', ['enu', 'ned'])
@pytest.mark.parametrize('stream', streams.STREAMS, ids=lambda s: s.name)
def test_serialized_reads_back_as_filled_for_every_stream(stream, convention):
    chosen = settings(stream, convention)
    f = MessageFactory(chosen)
    sensor = moving_sensor(stream.code)
    for i in range(200):
        record = sensor.record_at(stream.code, 0.37 * i).record
        for r in (record, *probe_records(stream)):
            assert imu(f, r, 5.0 + i) == fill_imu(chosen, r, 5.0 + i)


@pytest.mark.parametrize('stream', streams.STREAMS, ids=lambda s: s.name)
def test_what_a_record_lacks_is_marked_missing(stream):
    f = factory(stream, 'enu')
    record = moving_sensor(1).record_at(stream.code, 3.0).record
    msg = imu(f, record, 1.0)
    o = msg.orientation
    a = msg.linear_acceleration
    w = msg.angular_velocity
    assert (list(msg.orientation_covariance) == MISSING) == (stream.orientation is None)
    assert (list(msg.linear_acceleration_covariance) == MISSING) == (stream.accel is None)
    assert list(msg.angular_velocity_covariance) != MISSING
    if stream.orientation is None:
        assert (o.x, o.y, o.z, o.w) == (0.0, 0.0, 0.0, 0.0)
    else:
        assert math.isclose(o.x ** 2 + o.y ** 2 + o.z ** 2 + o.w ** 2, 1.0)
    if stream.accel is None:
        assert (a.x, a.y, a.z) == (0.0, 0.0, 0.0)
    else:
        assert (a.x, a.y, a.z) != (0.0, 0.0, 0.0)
    assert (w.x, w.y, w.z) != (0.0, 0.0, 0.0)


@pytest.mark.parametrize('stream', [streams.BY_NAME['full'], streams.BY_NAME['euler']],
                         ids=lambda s: s.name)
def test_an_unreadable_attitude_is_marked_missing(stream):
    f = factory(stream, 'ned')
    _, nan_record = probe_records(stream)
    msg = imu(f, nan_record, 1.0)
    assert list(msg.orientation_covariance) == MISSING
    # ...and the next good record has its covariance back.
    good, _ = probe_records(stream)
    msg = imu(f, good, 2.0)
    assert msg.orientation_covariance[0] == pytest.approx(1e-4)


def oracle_from_euler(roll: float, pitch: float, yaw: float, convention: str) -> np.ndarray:
    attitude = Rotation.from_euler('ZYX', [yaw, pitch, roll]).as_matrix()  # body -> NED
    if convention == 'enu':
        attitude = NED_TO_ENU @ attitude @ FRD_TO_FLU
    return Rotation.from_matrix(attitude).as_quat()


def same_rotation(q1, q2, tol: float) -> bool:
    q1, q2 = np.asarray(q1), np.asarray(q2)
    return min(np.abs(q1 - q2).max(), np.abs(q1 + q2).max()) < tol


@pytest.mark.parametrize('convention', ['enu', 'ned'])
def test_euler_and_matrix_records_of_one_cycle_give_one_orientation(convention):
    full = factory(streams.BY_NAME['full'], convention)
    euler = factory(streams.BY_NAME['euler'], convention)
    sensor = moving_sensor(7)
    for i in range(500):
        t = 0.113 * i
        cc = sensor.record_at(0xCC, t).record
        cf = sensor.record_at(0xCF, t).record
        q_cc, q_cf = orientation(full, cc), orientation(euler, cf)
        # The angles are float32, like the matrix: a few 1e-7 of difference.
        assert same_rotation(q_cc, q_cf, 2e-6), (i, q_cc, q_cf)
        assert same_rotation(q_cf, oracle_from_euler(cf.roll, cf.pitch, cf.yaw, convention),
                             1e-9)


def test_matrix_from_euler_inverts_euler_from_matrix():
    for i, rotation in enumerate(Rotation.random(2000, random_state=3)):
        m = tuple(rotation.as_matrix().T.flatten())  # M = attitude^T
        angles = euler_from_matrix(m)
        back = matrix_from_euler(*angles)
        assert np.allclose(back, m, atol=1e-12), i
        # And scipy agrees on the angles: body -> NED = Rz(yaw) Ry(pitch) Rx(roll).
        yaw, pitch, roll = rotation.as_euler('ZYX')
        assert np.allclose(angles, (roll, pitch, yaw), atol=1e-9) or abs(
            abs(pitch) - math.pi / 2) < 1e-6


@pytest.mark.parametrize('convention', ['enu', 'ned'])
def test_euler_and_matrix_agree_over_every_attitude(convention):
    """Random attitudes, float32 as the device sends them, away from gimbal lock."""
    full = factory(streams.BY_NAME['full'], convention)
    euler = factory(streams.BY_NAME['euler'], convention)
    f32 = np.float32
    checked = 0
    for rotation in Rotation.random(3000, random_state=11):
        m = tuple(float(f32(v)) for v in rotation.as_matrix().T.flatten())
        angles = tuple(float(f32(a)) for a in euler_from_matrix(m))
        if abs(angles[1]) > math.radians(85):
            continue
        q_cc, q_cf = orientation(full, matrix_record(m)), orientation(euler, euler_record(angles))
        assert same_rotation(q_cc, q_cf, 2e-6)
        checked += 1
    assert checked > 2500


def matrix_record(matrix):
    return streams.BY_NAME['full'].record_type((0.0,) * 3, (0.0,) * 3, (0.0,) * 3, matrix, 0)


def euler_record(angles):
    return streams.BY_NAME['euler'].record_type(*angles, (0.0,) * 3, 0)
