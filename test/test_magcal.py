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
magcal on the simulator's distorted field: what it recovers, refuses and warns about.

The sweeps are made in-process from the simulator's motion (``Motion.measure``:
the field through its hard and soft iron, the sensor's own attitude taking
its heading from that field), as records through the codec into a capture,
or as the node's messages; no process is started.
"""

import math
import random

from i3dmgx2_driver.capture.file_format import CaptureWriter, default_header, read_capture
from i3dmgx2_driver.codec.commands import encode_record
from i3dmgx2_driver.codec.framing import encode_wired_record
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.ros.conversions import MessageFactory, MessageSettings, stamp_parts
from i3dmgx2_driver.ros.mag_calibration import (
    field_correction, IDENTITY, is_matrix_list, one_sensors, per_sensor_problem)
from i3dmgx2_driver.simulator.motion import Motion, MotionConfig, MOTIONS
from i3dmgx2_driver.tools import magcal
from i3dmgx2_driver.tools.bag_io import capture_messages, write_bag
from i3dmgx2_driver.tools.noise import yaml_float
import numpy as np
from packets import as_sent, values_of
import pytest
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Imu, MagneticField

#: The distortion (Gauss, and the matrix the field is multiplied by): ~20 % of the field.
HARD = (0.08, -0.05, 0.03)
SOFT = (1.1, 0.05, -0.03, 0.05, 0.9, 0.02, -0.03, 0.02, 1.0)
#: A ground robot's iron: the vertical field does not leak into the horizontal.
SOFT_FLAT = (1.1, 0.05, 0.0, 0.05, 0.9, 0.0, 0.0, 0.0, 1.0)


def _measured(motion: str, seconds: float, hard=HARD, soft=SOFT, start: float = 0.0,
              **config) -> list:
    sensor = Motion(MotionConfig(hard_iron=hard, soft_iron=soft, **MOTIONS[motion], **config))
    rng = random.Random(57)
    return [sensor.measure(start + k * 0.1, rng) for k in range(round(seconds * 10))]


def _sweep(measured: list, source: str = 'simulated') -> magcal.Sweep:
    field = np.array([m.mag for m in measured]) * 1e-4
    down = -magcal._unit(np.array([m.accel for m in measured]))
    own = np.array([math.atan2(m.matrix[1], m.matrix[0]) for m in measured])
    return magcal.Sweep(field, down, own, source)


def _inverse(matrix, size: int = 3) -> np.ndarray:
    """Return the correction the distortion asks for, det 1 (magcal's scale)."""
    inv = np.linalg.inv(np.reshape(matrix, (3, 3))[:size, :size])
    return inv / np.linalg.det(inv) ** (1.0 / size)


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values ** 2)))


def _capture(path, measured: list) -> str:
    with CaptureWriter(path, default_header(address=None, wireless=False),
                       flush_interval=None) as writer:
        for k, m in enumerate(measured):
            record = AccelAngRateMagOrientation(m.accel, m.angular_rate, m.mag, m.matrix, k)
            writer.write(encode_wired_record(encode_record(record)), 1.7e9 + k * 0.1)
    return str(path)


def test_a_tumble_gives_the_offset_within_1_percent_and_the_matrix_within_2(tmp_path, capsys):
    measured = _measured('tumble', 300.0)
    path = _capture(tmp_path / 'tumble.gx2cap', measured)
    assert magcal.main(['--capture', path, '-o', str(tmp_path / 'out')]) == 0
    printed = capsys.readouterr().out
    result = magcal.fit(magcal.from_capture(path), planar=False)
    hard = np.array(HARD) * 1e-4
    assert np.linalg.norm(result.hard_iron - hard) < 0.01 * np.linalg.norm(hard)
    assert np.abs(result.soft_iron - _inverse(SOFT)).max() < 0.02
    # The corrected field's heading is the undistorted field's.
    sweep = magcal.from_capture(path)
    truth = np.array([m.truth.mag for m in measured])
    corrected = (sweep.field - result.hard_iron) @ result.soft_iron.T
    error = magcal._wrap_deg(magcal.headings(corrected, sweep.down)
                             - magcal.headings(truth, sweep.down))
    assert _rms(error) < 0.6  # the field's noise: 0.002 G on ~0.25 G horizontal, 0.46 deg
    # The distortion's heading error and the sensor's own, as printed: tens of degrees.
    assert 'heading error of the distortion' in printed
    assert 'advice: the sensor computes' in printed
    own = float(printed.split('the corrected field: ')[1].split(' deg rms')[0])
    assert 5.0 < own < 40.0, printed
    written = {p.name for p in (tmp_path / 'out').iterdir()}
    assert written == {'magcal.yaml', 'magcal.json', 'magcal.png'}
    hard_given, soft_given = magcal.applied_file(str(tmp_path / 'out' / 'magcal.yaml'))
    np.testing.assert_allclose(hard_given, result.hard_iron, rtol=1e-5)
    assert is_matrix_list(soft_given)


def test_turning_in_yaw_gives_the_horizontal_terms_within_2_percent(capsys):
    # A floor tilted by a degree: the accelerometer's tilt levels the circle.
    measured = _measured('yaw', 60.0, soft=SOFT_FLAT, hard=(0.08, -0.05, 0.0),
                         initial_attitude_deg=(1.0, -0.5, 0.0))
    result = magcal.fit(_sweep(measured), planar=True)
    hard = np.array((0.08, -0.05)) * 1e-4
    assert np.linalg.norm(result.hard_iron[:2] - hard) < 0.02 * np.linalg.norm(hard)
    horizontal = result.soft_iron[:2, :2] / np.linalg.det(result.soft_iron[:2, :2]) ** 0.5
    assert np.abs(horizontal - _inverse(SOFT_FLAT, 2)).max() < 0.02
    assert any('sees neither the vertical offset' in w for w in result.warnings)
    assert is_matrix_list(result.soft_iron.ravel().tolist())


def test_a_bag_of_the_nodes_messages_gives_the_same_fit(tmp_path, capsys):
    # The messages the node would publish from the capture (replay --bag's), as MCAP.
    path = _capture(tmp_path / 'tumble.gx2cap', _measured('tumble', 300.0))
    header, chunks = read_capture(path)
    write_bag(tmp_path / 'bag', capture_messages(chunks, header))
    assert magcal.main(['--bag', str(tmp_path / 'bag')]) == 0
    printed = capsys.readouterr().out
    assert '3000 readings, 3-D fit' in printed
    hard = [float(v) for v in printed.split('hard iron (T): [')[1].split(']')[0].split(',')]
    hard_iron = np.array(HARD) * 1e-4
    np.testing.assert_allclose(hard, hard_iron, atol=0.01 * np.linalg.norm(hard_iron))


def test_a_sweep_that_never_rolled_is_refused_with_the_axes_to_turn(tmp_path, capsys):
    path = _capture(tmp_path / 'sway.gx2cap', _measured('yaw', 60.0))
    assert magcal.main(['--capture', path, '-o', str(tmp_path / 'out')]) == 1
    said = capsys.readouterr().err
    assert "the field never came along the sensor's" in said and '-z (top)' in said
    assert 'turn the sensor so that each of them in turn points along the field' in said
    assert not (tmp_path / 'out').exists()


def test_a_turn_left_half_done_is_refused_with_the_way_to_go_on():
    with pytest.raises(ValueError, match='were not seen in 100 readings: keep turning in '
                                         'place, right'):
        magcal.fit(_sweep(_measured('yaw', 10.0)), planar=True)


def test_a_disturbance_that_moved_is_warned_about(tmp_path, capsys):
    before = _measured('tumble', 150.0)
    after = _measured('tumble', 150.0, hard=(0.12, -0.05, 0.03), start=150.0)
    path = _capture(tmp_path / 'moved.gx2cap', before + after)
    assert magcal.main(['--capture', path]) == 3
    assert 'warning: the offset moved during the recording' in capsys.readouterr().out


def test_the_node_corrects_the_field_and_magcal_fits_the_raw_one_under_it(tmp_path):
    measured = _measured('tumble', 300.0)
    applied = (np.array((0.05, 0.0, 0.01)) * 1e-4,
               (1.05, 0.01, 0.0, 0.01, 0.95, 0.0, 0.0, 0.0, 1.0))
    factory = MessageFactory(MessageSettings('imu_link', 'enu', mag_hard_iron=tuple(applied[0]),
                                             mag_soft_iron=applied[1]))
    pairs = []
    # The records as the node reads them (float32), packed as it packs them.
    sent = [as_sent(AccelAngRateMagOrientation(m.accel, m.angular_rate, m.mag, m.matrix, k))
            for k, m in enumerate(measured)]
    for k, record in enumerate(sent):
        values, stamp = values_of(record), stamp_parts(k * 0.1)
        pairs.append((deserialize_message(factory.imu_cdr(values, *stamp), Imu),
                      deserialize_message(factory.mag_cdr(values, *stamp), MagneticField)))
    # The published field is the sensor's corrected one, turned into REP-103 axes.
    correct = field_correction(*applied, 1e-4)
    x, y, z = correct(sent[0].mag)
    assert tuple(pairs[0][1].magnetic_field.__getattribute__(a) for a in 'xyz') == \
        pytest.approx((x * 1e-4, -y * 1e-4, -z * 1e-4), rel=1e-12)
    path = tmp_path / 'applied.yaml'
    path.write_text('/**:\n  ros__parameters:\n'
                    f'    mag_hard_iron: [{", ".join(map(yaml_float, applied[0]))}]\n'
                    f'    mag_soft_iron: {list(applied[1])}\n')
    sweep = magcal.undo(magcal.from_messages(pairs, 'bag'), *magcal.applied_file(str(path)))
    result = magcal.fit(sweep, planar=False)
    hard = np.array(HARD) * 1e-4
    assert np.linalg.norm(result.hard_iron - hard) < 0.01 * np.linalg.norm(hard)
    assert np.abs(result.soft_iron - _inverse(SOFT)).max() < 0.02
    # The sensor's own heading comes back from the published quaternion.
    own = np.array([math.atan2(m.matrix[1], m.matrix[0]) for m in sent])
    # (to float32's precision: the matrix is the wire's, orthonormal to about 1e-7)
    assert np.abs(magcal._wrap_deg(sweep.heading - own)).max() < 1e-4


def test_at_the_defaults_nothing_corrects_the_field():
    assert field_correction((0.0, 0.0, 0.0), IDENTITY, 1e-4) is None
    record = as_sent(AccelAngRateMagOrientation((0.0,) * 3, (0.0,) * 3, (0.25, -0.5, 0.125),
                                                (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0), 0))
    field = deserialize_message(MessageFactory(MessageSettings('imu_link', 'ned')).mag_cdr(
        values_of(record), 0, 0), MagneticField).magnetic_field
    assert (field.x, field.y, field.z) == (0.25e-4, -0.5e-4, 0.125e-4)
    assert not is_matrix_list((1.0, 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0))  # not symmetric
    assert not is_matrix_list((1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0))  # not definite
    assert is_matrix_list((*IDENTITY, 2.0, 0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0))


def test_the_simulators_own_heading_carries_the_distortions_error():
    undistorted = _measured('tumble', 10.0, hard=(0.0, 0.0, 0.0), soft=IDENTITY)
    assert all(m.matrix == m.truth.matrix for m in undistorted)
    distorted = _measured('tumble', 10.0)
    sweep = _sweep(distorted)
    from_field = magcal.headings(np.array([m.mag for m in distorted]), sweep.down)
    np.testing.assert_allclose(magcal._wrap_deg(sweep.heading - from_field), 0.0, atol=1.5)


def test_one_calibration_for_all_sensors_or_one_each():
    two = (*IDENTITY, 2.0, 0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0)
    assert one_sensors(two, 9, 1)[0] == 2.0 and one_sensors(IDENTITY, 9, 1) == IDENTITY
    assert per_sensor_problem((0.0,) * 6, two, 2) is None
    assert per_sensor_problem((0.0,) * 6, two, 3) == (
        "parameter 'mag_hard_iron' must give 3 values for all sensors or 3 per sensor "
        '(3 addresses), got 6')
