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
Orientation: Shepperd's method against scipy, and the two frame conventions.

Conventions (docs/protocol.md §9 and orientation.py): the device's M maps earth NED
coordinates into sensor FRD coordinates (v_sensor = M v_earth), so M's rows are
the sensor's axes written in earth coordinates and M^T is the attitude. ROS
wants ENU and FLU: R_enu = P M^T D. The expected values of the known poses below
are worked out by hand from those two facts, not from the code under test.
"""

import math

from hypothesis import given, settings, strategies as st
from i3dmgx2_driver.codec import orientation as o
import numpy as np
import pytest
from scipy.spatial.transform import Rotation


# The attitudes as whole matrices: what the codec reads in place (o.quaternion), built
# step by step as the module docstring writes them.


def transpose(m: tuple) -> tuple:
    """Return the transpose of a row-major 3x3 matrix."""
    return (m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8])


def attitude_ned(m: tuple) -> tuple:
    """Sensor attitude in the device's own convention: NED world, FRD body."""
    return transpose(m)


def attitude_enu(m: tuple) -> tuple:
    """
    Sensor attitude per REP-103: ENU world, FLU body, as P * M^T * D.

    With A = M^T (row-major a0..a8), swapping the first two rows and negating
    the third gives P * A; negating the last two columns then applies D.
    """
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = transpose(m)
    return (a3, -a4, -a5,
            a0, -a1, -a2,
            -a6, a7, a8)


def attitude(m: tuple, convention: str) -> tuple:
    """Sensor attitude in the named convention (``'enu'`` or ``'ned'``)."""
    if convention == o.ENU:
        return attitude_enu(m)
    if convention == o.NED:
        return attitude_ned(m)
    raise ValueError(f'convention must be one of {o.CONVENTIONS}, got {convention!r}')


CI = settings(max_examples=300, deadline=None, database=None)
P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # NED -> ENU
D = np.diag([1.0, -1.0, -1.0])                                       # FLU -> FRD
HALF = math.sqrt(0.5)


def m9(matrix):
    """Row-major 9-tuple of a 3x3 numpy matrix, as the codec takes it."""
    return tuple(float(v) for v in np.asarray(matrix).ravel())


def mat(values):
    """3x3 numpy matrix of a row-major 9-tuple."""
    return np.array(values, dtype=float).reshape(3, 3)


def same_rotation(q, reference, tol):
    """Tell whether two (x, y, z, w) quaternions are equal up to sign."""
    q, reference = np.asarray(q, dtype=float), np.asarray(reference, dtype=float)
    return min(np.abs(q - reference).max(), np.abs(q + reference).max()) < tol


def test_same_rotation_helper_can_fail():
    """The comparison accepts q and -q, and nothing else."""
    assert same_rotation((0, 0, HALF, HALF), (0, 0, -HALF, -HALF), 1e-12)
    assert not same_rotation((0, 0, HALF, HALF), (0, 0, HALF, -HALF), 1e-3)


# ---------------------------------------------------------------- Shepperd

RANDOM_ROTATIONS = Rotation.random(3000, random_state=20260522)


def test_shepperd_matches_scipy_on_random_rotations():
    """3000 seeded random rotations: the same rotation as scipy's, to 1e-12, w >= 0."""
    for matrix, reference in zip(RANDOM_ROTATIONS.as_matrix(), RANDOM_ROTATIONS.as_quat(),
                                 strict=True):
        q = o.shepperd(m9(matrix))
        assert q.w >= 0.0
        assert same_rotation(q, reference, 1e-12)
        assert abs(math.fsum(c * c for c in q) - 1.0) < 1e-14


@CI
@given(st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(
    lambda q: math.fsum(c * c for c in q) > 1e-4))
def test_shepperd_inverts_any_quaternion(raw):
    """Property: matrix of any quaternion, back through Shepperd, gives it again (up to sign)."""
    q = np.array(raw) / math.sqrt(math.fsum(c * c for c in raw))
    matrix = Rotation.from_quat(q).as_matrix()
    result = o.shepperd(m9(matrix))
    assert same_rotation(result, q, 1e-12)
    assert result.w >= 0.0
    assert np.allclose(mat(o.matrix_from_quaternion(result)), matrix, atol=1e-12)


def test_identity():
    """No rotation is (0, 0, 0, 1) exactly."""
    assert o.shepperd(m9(np.eye(3))) == (0.0, 0.0, 0.0, 1.0)


@pytest.mark.parametrize('matrix, expected', [
    (np.diag([1.0, -1.0, -1.0]), (1.0, 0.0, 0.0, 0.0)),   # 180 degrees about x
    (np.diag([-1.0, 1.0, -1.0]), (0.0, 1.0, 0.0, 0.0)),   # about y
    (np.diag([-1.0, -1.0, 1.0]), (0.0, 0.0, 1.0, 0.0)),   # about z
], ids=['x', 'y', 'z'])
def test_exact_half_turns_about_the_axes(matrix, expected):
    """180 degrees about x, y, z: trace -1, the naive formula divides by zero; exact here."""
    q = o.shepperd(m9(matrix))
    assert q == expected  # exact: the chosen component is +1, the others exactly 0


@pytest.mark.parametrize('axis', [
    (1, 1, 0), (1, 0, 1), (0, 1, 1), (1, 1, 1), (-1, 2, 3), (3, -1, 0.5), (1e-3, 1, 1e-3)])
def test_half_turns_about_arbitrary_axes(axis):
    """180 degrees about a unit axis n: R = 2 n n^T - I, quaternion (n, 0)."""
    n = np.array(axis, dtype=float) / np.linalg.norm(axis)
    matrix = 2.0 * np.outer(n, n) - np.eye(3)
    q = o.shepperd(m9(matrix))
    assert same_rotation(q, (*n, 0.0), 1e-15 * 10)
    assert abs(q.w) < 1e-15


def test_seeded_half_turns_and_near_half_turns():
    """Random axes at 180 degrees and just short of it (trace close to -1)."""
    rng = np.random.default_rng(5)
    for _ in range(500):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        for epsilon in (0.0, 1e-12, 1e-9, 1e-6, 1e-3):
            angle = math.pi - epsilon
            expected = (*(n * math.sin(angle / 2)), math.cos(angle / 2))
            matrix = Rotation.from_rotvec(n * angle).as_matrix()
            assert np.trace(matrix) + 1.0 < 1e-5
            q = o.shepperd(m9(matrix))
            assert same_rotation(q, expected, 1e-12)
            assert q.w >= 0.0


@pytest.mark.parametrize('branch, rotvec', [
    ('trace', (0.1, -0.2, 0.3)),
    ('x', (math.pi * 0.99, 0.1, -0.1)),
    ('y', (0.1, math.pi * 0.99, 0.1)),
    ('z', (-0.1, 0.1, math.pi * 0.99)),
])
def test_each_branch(branch, rotvec):
    """Each of the four branches (largest of trace, A11, A22, A33) gives scipy's answer."""
    matrix = Rotation.from_rotvec(rotvec).as_matrix()
    diagonal = [np.trace(matrix), *np.diag(matrix)]
    assert ['trace', 'x', 'y', 'z'][int(np.argmax(diagonal))] == branch
    assert same_rotation(o.shepperd(m9(matrix)), Rotation.from_matrix(matrix).as_quat(), 1e-12)


def test_sign_convention():
    """Always w >= 0: a turn of 350 degrees about z is given as -10 degrees."""
    matrix = Rotation.from_euler('z', 350, degrees=True).as_matrix()
    q = o.shepperd(m9(matrix))
    assert q.w > 0.0
    assert np.allclose(q, (0.0, 0.0, -math.sin(math.radians(5)), math.cos(math.radians(5))),
                       atol=1e-15)
    # q and -q are one rotation: the same matrix comes back from both.
    negated = o.Quaternion(*(-c for c in q))
    assert np.allclose(mat(o.matrix_from_quaternion(negated)),
                       mat(o.matrix_from_quaternion(q)), atol=0.0)


def test_float32_matrices_give_unit_quaternions():
    """Real matrices are float32 and orthonormal only to ~1e-7: still a unit quaternion."""
    rng = np.random.default_rng(11)
    for matrix, reference in zip(RANDOM_ROTATIONS.as_matrix()[:1000],
                                 RANDOM_ROTATIONS.as_quat()[:1000], strict=True):
        rough = (matrix + rng.normal(scale=2e-7, size=(3, 3))).astype(np.float32)
        q = o.shepperd(m9(rough))
        assert abs(math.sqrt(math.fsum(c * c for c in q)) - 1.0) < 1e-15
        assert same_rotation(q, reference, 2e-6)
        assert q.w >= 0.0


# ---------------------------------------------------------------- conventions

def test_attitude_ned_is_m_transposed():
    """NED attitude is M^T, and transpose() is the transpose."""
    for matrix in RANDOM_ROTATIONS.as_matrix()[:200]:
        assert np.array_equal(mat(attitude_ned(m9(matrix))), matrix.T)
        assert np.array_equal(mat(transpose(m9(matrix))), matrix.T)


def test_attitude_enu_is_p_mt_d():
    """ENU attitude equals P M^T D built with numpy, and is a proper rotation."""
    for matrix in RANDOM_ROTATIONS.as_matrix()[:500]:
        enu = mat(attitude_enu(m9(matrix)))
        assert np.allclose(enu, P @ matrix.T @ D, atol=0.0)
        assert np.allclose(enu @ enu.T, np.eye(3), atol=1e-12)
        assert abs(np.linalg.det(enu) - 1.0) < 1e-12


def test_attitude_enu_maps_body_vectors_consistently():
    """A body vector, to FLU then rotated to ENU, equals it rotated to NED then to ENU."""
    rng = np.random.default_rng(3)
    for matrix in RANDOM_ROTATIONS.as_matrix()[:300]:
        v_frd = rng.normal(size=3)
        enu_path = mat(attitude_enu(m9(matrix))) @ np.array(o.body_vector(v_frd, o.ENU))
        ned_path = P @ (mat(attitude_ned(m9(matrix))) @ np.array(o.body_vector(v_frd, o.NED)))
        assert np.allclose(enu_path, ned_path, atol=1e-12)


def test_orientation_and_attitude_dispatch():
    """orientation() is Shepperd of attitude(); an unknown convention is a ValueError."""
    matrix = m9(RANDOM_ROTATIONS.as_matrix()[0])
    for convention in o.CONVENTIONS:
        assert o.orientation(matrix, convention) == o.shepperd(attitude(matrix, convention))
    assert attitude(matrix, 'enu') == attitude_enu(matrix)
    assert attitude(matrix, 'ned') == attitude_ned(matrix)
    for call in (attitude, o.orientation, o.body_vector):
        with pytest.raises(ValueError):
            call(matrix if call is not o.body_vector else (1.0, 2.0, 3.0), 'nwu')


def test_body_vector():
    """FRD to FLU negates y and z; NED keeps the device's axes."""
    assert o.body_vector((1.0, 2.0, 3.0), 'enu') == (1.0, -2.0, -3.0)
    assert o.body_vector((1.0, 2.0, 3.0), 'ned') == (1.0, 2.0, 3.0)
    assert o.body_vector([0.0, 0.0, -1.0], 'enu') == (0.0, -0.0, 1.0)


def enu_yaw_deg(m):
    """Heading in ENU (counter-clockwise from east) of the sensor with matrix M."""
    r = mat(attitude_enu(m))
    return math.degrees(math.atan2(r[1, 0], r[0, 0]))


def wrap_deg(angle):
    """Wrap an angle difference in degrees to [-180, 180)."""
    return (angle + 180.0) % 360.0 - 180.0


C30, S30 = math.cos(math.radians(30)), math.sin(math.radians(30))
C20, S20 = math.cos(math.radians(20)), math.sin(math.radians(20))


def test_level_facing_north():
    """M = I: flat, level, x to the north. NED: no rotation. ENU: yaw +90 degrees."""
    identity = m9(np.eye(3))
    assert o.orientation(identity, 'ned') == (0.0, 0.0, 0.0, 1.0)
    enu = mat(attitude_enu(identity))
    # Columns: forward -> north (0, 1, 0), left -> west (-1, 0, 0), up -> up (0, 0, 1).
    assert np.array_equal(enu, [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert enu_yaw_deg(identity) == 90.0
    assert np.allclose(o.orientation(identity, 'enu'), (0.0, 0.0, HALF, HALF), atol=1e-15)
    assert o.euler_from_matrix(identity) == (0.0, -0.0, 0.0)


def test_level_facing_east_and_west():
    """Facing east, ENU attitude is the identity; facing west, a half turn about up."""
    # Rows of M are the sensor axes in NED: forward = east (0, 1, 0), right = south.
    east = (0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert np.allclose(mat(attitude_enu(east)), np.eye(3), atol=0.0)
    assert np.allclose(o.orientation(east, 'enu'), (0, 0, 0, 1), atol=1e-15)
    assert math.degrees(o.euler_from_matrix(east)[2]) == 90.0  # NED yaw: clockwise from north
    west = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert enu_yaw_deg(west) == 180.0
    assert same_rotation(o.orientation(west, 'enu'), (0, 0, 1, 0), 1e-15)
    assert math.degrees(o.euler_from_matrix(west)[2]) == -90.0


def test_nose_up_30_degrees_facing_north():
    """Forward = (cos30, 0, -sin30) in NED; in ENU it is north and up: (0, cos30, sin30)."""
    m = (C30, 0.0, -S30, 0.0, 1.0, 0.0, S30, 0.0, C30)
    roll, pitch, yaw = o.euler_from_matrix(m)
    assert (roll, yaw) == (0.0, 0.0)
    assert math.degrees(pitch) == pytest.approx(30.0, abs=1e-12)
    enu = mat(attitude_enu(m))
    assert np.allclose(enu[:, 0], (0.0, C30, S30), atol=1e-15)   # forward
    assert np.allclose(enu[:, 1], (-1.0, 0.0, 0.0), atol=1e-15)  # left: west, level
    # ROS pitch is about the left axis, positive nose down: -30 degrees here.
    expected = Rotation.from_euler('ZYX', [90.0, -30.0, 0.0], degrees=True).as_quat()
    assert same_rotation(o.orientation(m, 'enu'), expected, 1e-15 * 10)


def test_rolled_right_20_degrees_facing_north():
    """Right wing 20 degrees down: right = (0, cos20, sin20) in NED; left goes up in ENU."""
    m = (1.0, 0.0, 0.0, 0.0, C20, S20, 0.0, -S20, C20)
    roll, pitch, yaw = o.euler_from_matrix(m)
    assert math.degrees(roll) == pytest.approx(20.0, abs=1e-12)
    assert (pitch, yaw) == (-0.0, 0.0)
    enu = mat(attitude_enu(m))
    assert np.allclose(enu[:, 1], (-C20, 0.0, S20), atol=1e-15)  # left: west and up


def test_upside_down():
    """Rolled 180 degrees: z (down) points up and reads +1 g; FLU up points down in ENU."""
    m = (1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)
    enu = mat(attitude_enu(m))
    assert np.array_equal(enu, P)
    assert np.allclose(enu[:, 2], (0.0, 0.0, -1.0))
    up = enu @ np.array(o.body_vector((0.0, 0.0, 1.0), 'enu'))
    assert np.allclose(up, (0.0, 0.0, 1.0))


@pytest.mark.parametrize('heading', range(0, 360, 30))
def test_flat_at_rest_accel_points_up_at_any_heading(heading):
    """Flat, z down: accel (0, 0, -1) g; in FLU (0, 0, 1); rotated to ENU: up, any heading."""
    h = math.radians(heading)
    # Rows: forward (cos h, sin h, 0), right (-sin h, cos h, 0), down (0, 0, 1).
    m = (math.cos(h), math.sin(h), 0.0, -math.sin(h), math.cos(h), 0.0, 0.0, 0.0, 1.0)
    up = mat(attitude_enu(m)) @ np.array(o.body_vector((0.0, 0.0, -1.0), 'enu'))
    assert np.allclose(up, (0.0, 0.0, 1.0), atol=1e-15)
    assert wrap_deg(math.degrees(o.euler_from_matrix(m)[2]) - heading) == pytest.approx(
        0.0, abs=1e-9)
    # ENU yaw is measured from east, counter-clockwise: 90 - heading.
    assert wrap_deg(enu_yaw_deg(m) - (90.0 - heading)) == pytest.approx(0.0, abs=1e-9)


# ---------------------------------------------------------------- Euler angles

def test_euler_angles_match_scipy_zyx():
    """docs/protocol.md §9's ZYX angles of M equal scipy's intrinsic Z-Y-X angles of M^T."""
    for matrix in RANDOM_ROTATIONS.as_matrix()[:1000]:
        roll, pitch, yaw = o.euler_from_matrix(m9(matrix.T))
        reference_yaw, reference_pitch, reference_roll = Rotation.from_matrix(
            matrix).as_euler('ZYX')
        if abs(reference_pitch) < math.radians(89):
            assert np.allclose((roll, pitch, yaw),
                               (reference_roll, reference_pitch, reference_yaw), atol=1e-9)


def test_euler_angles_round_trip():
    """Angles made into M by hand (M = Rx(roll) Ry(pitch) Rz(yaw), frame rotations) return."""
    roll, pitch, yaw = math.radians(10), math.radians(-35), math.radians(120)

    def frame_x(a):
        return np.array([[1, 0, 0], [0, math.cos(a), math.sin(a)], [0, -math.sin(a), math.cos(a)]])

    def frame_y(a):
        return np.array([[math.cos(a), 0, -math.sin(a)], [0, 1, 0], [math.sin(a), 0, math.cos(a)]])

    def frame_z(a):
        return np.array([[math.cos(a), math.sin(a), 0], [-math.sin(a), math.cos(a), 0], [0, 0, 1]])

    m = frame_x(roll) @ frame_y(pitch) @ frame_z(yaw)
    assert np.allclose(o.euler_from_matrix(m9(m)), (roll, pitch, yaw), atol=1e-15 * 10)


def test_euler_pitch_clamped_past_90_degrees():
    """A float32 M13 a hair beyond -1 or 1 gives pitch +-90 degrees, not a math error."""
    assert o.euler_from_matrix((0, 0, -1.0000001, 0, 1, 0, 1, 0, 0))[1] == math.pi / 2
    assert o.euler_from_matrix((0, 0, 1.0000001, 0, 1, 0, -1, 0, 0))[1] == -math.pi / 2


def test_a_matrix_that_is_no_rotation_gives_no_orientation():
    """Garbage with a valid checksum must not pass for an attitude."""
    for matrix in ([0.0] * 9, [2.0] * 9, [1.0, 0, 0, 0, 0, 0, 0, 0, 0]):
        assert all(math.isnan(c) for c in o.shepperd(matrix))
    # float32 rounding of a real rotation is still a rotation
    assert abs(sum(c * c for c in o.shepperd([1.0000001, 0, 0, 0, 0.9999999, 0, 0, 0, 1])) - 1) \
        < 1e-12
