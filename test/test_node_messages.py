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
The node end to end: simulator on a pty, node process, rclpy subscriber.

Every value is checked against the simulator's ground truth: each valid
record published exactly once, in order, with the exact numbers in both frame
conventions, an orientation equal to an independent construction of the
attitude (numpy and scipy, not the codec), and stamps close to the true
sample times.
"""

import itertools
import math

from harness.processes import isolate_ros_domain, Listener, NodeProcess, stamp_seconds
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu, MagneticField

pytestmark = pytest.mark.slow

G = 9.80665
# The device's NED world and FRD body to REP-103's ENU world and FLU body.
NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FRD_TO_FLU = np.diag([1.0, -1.0, -1.0])


def stream_truth(sim: PtySimulator) -> list:
    """Return the valid 0xCC records the simulator wrote whole, in order."""
    return [t for t in sim.truth
            if t.valid and t.write_time is not None
            and isinstance(t.record, AccelAngRateMagOrientation)]


def expected_vectors(record, convention: str):
    """Return accel (m/s^2), rate (rad/s), field (T) as the convention wants them."""
    flip = FRD_TO_FLU if convention == 'enu' else np.eye(3)
    return (flip @ (np.array(record.accel) * G), flip @ np.array(record.angular_rate),
            flip @ (np.array(record.mag) * 1e-4))


def expected_quaternion(record, convention: str) -> np.ndarray:
    """Return the sensor attitude M^T in the convention's frames, by scipy (x, y, z, w)."""
    m = np.array(record.matrix, dtype=float).reshape(3, 3)
    attitude = m.T if convention == 'ned' else NED_TO_ENU @ m.T @ FRD_TO_FLU
    u, _, vt = np.linalg.svd(attitude)  # nearest rotation: float32 M is not exact
    return Rotation.from_matrix(u @ vt).as_quat()


def match(messages: list, truth: list, convention: str) -> list:
    """
    Pair each published message with the truth record it carries.

    Accelerations are noisy float32 values, unique in practice, so the exact
    float64 product is a key that identifies the record without trusting the
    node's stamps or order.
    """
    by_accel = {}
    for entry in truth:
        key = tuple(expected_vectors(entry.record, convention)[0])
        by_accel[key] = entry
    pairs = []
    for msg in messages:
        a = msg.linear_acceleration
        pairs.append((msg, by_accel.get((a.x, a.y, a.z))))
    return pairs


@pytest.fixture(scope='module')
def enu_run():
    """Run a node streaming from the simulator for a few seconds, then stop it."""
    isolate_ros_domain()
    sim = PtySimulator(SimulatorConfig(seed=11, mag_nan_probability=0.3)).start()
    listener = Listener({'imu/raw_data': Imu, 'imu/mag': MagneticField})
    node = NodeProcess({'port': sim.port, 'address': 95, 'orientation_stddev': 0.01,
                        'angular_velocity_stddev': 0.002,
                        'linear_acceleration_stddev': 0.05,
                        'magnetic_field_stddev': 1e-6})
    try:
        assert node.wait_for_output('streaming 0xCC'), node.output()
        listener.wait_for('imu/raw_data', 300, timeout=30)
        code, took = node.stop()
        yield {'sim': sim, 'listener': listener, 'node': node, 'code': code, 'took': took,
               'output': node.output()}
    finally:
        node.close()
        listener.close()
        sim.stop()


def test_every_valid_record_published_once_in_order(enu_run):
    messages = enu_run['listener'].received('imu/raw_data')
    truth = stream_truth(enu_run['sim'])
    pairs = match(messages, truth, 'enu')
    assert len(messages) >= 300
    assert all(entry is not None for _, entry in pairs), 'a message matches no valid record'
    indices = [entry.index for _, entry in pairs]
    assert len(set(indices)) == len(indices), 'a record was published twice'
    assert indices == sorted(indices), 'records published out of order'
    published = set(indices)
    # Between the first and the last record published, none was skipped.
    window = [t.index for t in truth if indices[0] <= t.index <= indices[-1]]
    assert [i for i in window if i not in published] == []


def test_values_exact_in_enu(enu_run):
    messages = enu_run['listener'].received('imu/raw_data')
    for msg, entry in match(messages, stream_truth(enu_run['sim']), 'enu'):
        accel, rate, _ = expected_vectors(entry.record, 'enu')
        assert (msg.linear_acceleration.x, msg.linear_acceleration.y,
                msg.linear_acceleration.z) == tuple(accel)
        assert (msg.angular_velocity.x, msg.angular_velocity.y,
                msg.angular_velocity.z) == tuple(rate)
        assert msg.header.frame_id == 'imu_link'


def test_orientation_matches_independent_oracle(enu_run):
    messages = enu_run['listener'].received('imu/raw_data')
    for msg, entry in match(messages, stream_truth(enu_run['sim']), 'enu'):
        q = np.array([msg.orientation.x, msg.orientation.y, msg.orientation.z,
                      msg.orientation.w])
        assert abs(np.linalg.norm(q) - 1.0) < 1e-9
        oracle = expected_quaternion(entry.record, 'enu')
        assert min(np.abs(q - oracle).max(), np.abs(q + oracle).max()) < 1e-6


def test_gravity_points_up_in_enu(enu_run):
    """REP-145: at rest, +9.81 m/s^2 along the world's up, rotated into the body."""
    msg = enu_run['listener'].received('imu/raw_data')[-1]
    q = msg.orientation
    world = Rotation.from_quat([q.x, q.y, q.z, q.w]).apply(
        [msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z])
    assert world[2] == pytest.approx(G, abs=0.5)
    assert math.hypot(world[0], world[1]) < 0.5


def test_covariances_from_parameters(enu_run):
    msg = enu_run['listener'].received('imu/raw_data')[0]
    assert list(msg.orientation_covariance) == pytest.approx(
        [1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4])
    assert list(msg.angular_velocity_covariance) == pytest.approx(
        [4e-6, 0, 0, 0, 4e-6, 0, 0, 0, 4e-6])
    assert list(msg.linear_acceleration_covariance) == pytest.approx(
        [0.0025, 0, 0, 0, 0.0025, 0, 0, 0, 0.0025])


def test_stamps_monotonic_and_close_to_sample_times(enu_run):
    messages = enu_run['listener'].received('imu/raw_data')
    pairs = match(messages, stream_truth(enu_run['sim']), 'enu')
    stamps = [stamp_seconds(msg) for msg, _ in pairs]
    assert all(b > a for a, b in itertools.pairwise(stamps))
    errors = np.array([stamp_seconds(msg) - entry.sample_time for msg, entry in pairs])
    print(f'stamp - sample time: median {np.median(errors) * 1e3:.3f} ms, '
          f'std (second half) {errors[len(errors) // 2:].std() * 1e6:.1f} us')
    # The radio latency (simulated: a few ms) is what remains uncompensated;
    # the spread is what device timestamps remove.
    # The wire time is compensated; what remains is the simulated radio
    # latency (2 ms), which no host can observe.
    assert 0.0 <= np.median(errors) < 0.005
    settled = errors[len(errors) // 2:]
    assert settled.std() < 0.002


def test_magnetic_field_skips_nan_and_is_in_tesla(enu_run):
    truth = stream_truth(enu_run['sim'])
    mags = enu_run['listener'].received('imu/mag')
    imus = enu_run['listener'].received('imu/raw_data')
    pairs = match(imus, truth, 'enu')
    expected = [expected_vectors(entry.record, 'enu')[2] for _, entry in pairs
                if not math.isnan(entry.record.mag[0])]
    assert 0 < len(expected) < len(pairs)  # some cycles had no new reading
    got = [(m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z) for m in mags]
    assert got == [tuple(e) for e in expected]
    assert all(0.1e-4 < math.sqrt(sum(c * c for c in g)) < 1e-4 for g in got)
    assert mags[0].magnetic_field_covariance[0] == pytest.approx(1e-12)


def test_clean_shutdown_sends_stop_and_exits_zero(enu_run):
    assert enu_run['code'] == 0, enu_run['output']
    assert enu_run['took'] < 2.0
    stops = [t for t, c in enu_run['sim'].commands if c.code == 0xFA]
    assert stops, 'the node did not stop the stream on exit'
    assert enu_run['sim'].streaming == 0
    assert 'port closed' in enu_run['output']


def test_ned_convention_and_host_time():
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=12)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95, 'frame_convention': 'ned',
                            'time_source': 'host', 'publish_mag': False})
        with listener, node:
            messages = listener.wait_for('imu/raw_data', 100, timeout=30)
            received = {id(m): t for t, m in listener.messages['imu/raw_data']}
            assert len(messages) >= 100, node.output()
            for msg, entry in match(messages, stream_truth(sim), 'ned'):
                assert entry is not None
                accel, rate, _ = expected_vectors(entry.record, 'ned')
                assert (msg.linear_acceleration.x, msg.linear_acceleration.y,
                        msg.linear_acceleration.z) == tuple(accel)
                assert (msg.angular_velocity.x, msg.angular_velocity.y,
                        msg.angular_velocity.z) == tuple(rate)
                q = np.array([msg.orientation.x, msg.orientation.y, msg.orientation.z,
                              msg.orientation.w])
                oracle = expected_quaternion(entry.record, 'ned')
                assert min(np.abs(q - oracle).max(), np.abs(q + oracle).max()) < 1e-6
                assert msg.header.frame_id == 'imu_link_ned'
                # Host stamps: the read time, so after the write that carried the
                # packet's last byte (write_time is read just before it) and before
                # the message arrived here. A device stamp (the sample time) would
                # fall before write_time by the radio latency and the wire time.
                assert entry.write_time <= stamp_seconds(msg) <= received[id(msg)]
            assert node.stop()[0] == 0
