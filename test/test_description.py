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

"""The sensor in the robot's description: urdf/ expanded by xacro, read by urdf_parser_py."""

import math
from pathlib import Path

from i3dmgx2_driver.codec.orientation import body_vector, ENU, NED
from i3dmgx2_driver.ros.conversions import frame_id_for
from i3dmgx2_driver.ros.parameter_table import SPECS
import numpy as np
from urdf_parser_py.urdf import URDF
import xacro

URDF_DIR = Path(__file__).resolve().parents[1] / 'urdf'
#: The node's frames at the defaults, as it names them per convention.
FRAME = next(spec.default for spec in SPECS if spec.name == 'frame_id')
NED_FRAME = frame_id_for(FRAME, NED)


def _expand(path: Path) -> URDF:
    return URDF.from_xml_string(xacro.process_file(str(path)).toxml())


def _rotation(rpy) -> np.ndarray:
    (sr, cr), (sp, cp), (sy, cy) = ((math.sin(a), math.cos(a)) for a in rpy)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def test_the_example_robot_carries_the_nodes_frames_in_a_chain():
    robot = _expand(URDF_DIR / 'example.urdf.xacro')
    assert {link.name for link in robot.links} == {'base_link', FRAME, NED_FRAME}
    assert robot.get_chain('base_link', NED_FRAME, links=True, joints=False) == \
        ['base_link', FRAME, NED_FRAME]
    assert {joint.type for joint in robot.joints} == {'fixed'}
    assert robot.joint_map['imu_joint'].origin.xyz == [0.0, 0.0, 0.25]


def test_the_ned_frame_is_the_rep103_frame_turned_as_the_node_turns_its_vectors():
    robot = _expand(URDF_DIR / 'example.urdf.xacro')
    joint = next(j for j in robot.joints if j.child == NED_FRAME)
    assert joint.parent == FRAME and joint.origin.xyz == [0.0, 0.0, 0.0]
    turn = _rotation(joint.origin.rpy)
    # Each of the sensor's own axes (x forward, y right, z down), seen from imu_link, is
    # what the node publishes for it in enu: (1, 0, 0), (0, -1, 0), (0, 0, -1).
    for axis in np.eye(3):
        np.testing.assert_allclose(turn @ axis, body_vector(axis, ENU), atol=1e-12)


def test_the_macro_takes_a_parent_an_origin_a_prefix_and_a_case(tmp_path):
    robot_file = tmp_path / 'robot.urdf.xacro'
    robot_file.write_text(
        '<robot name="two" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        f'<xacro:include filename="{URDF_DIR / "i3dmgx2.urdf.xacro"}"/>'
        '<link name="arm"/>'
        '<xacro:i3dmgx2 parent="arm" prefix="left_" size="0.05 0.04 0.03">'
        '<origin xyz="0.1 0.2 0.3" rpy="0 0 1.5707963267948966"/></xacro:i3dmgx2></robot>')
    robot = _expand(robot_file)
    assert robot.get_chain('arm', 'left_' + NED_FRAME, links=True, joints=False) == \
        ['arm', 'left_' + FRAME, 'left_' + NED_FRAME]
    joint = robot.joint_map['left_imu_joint']
    assert joint.origin.xyz == [0.1, 0.2, 0.3] and joint.origin.rpy[2] == math.pi / 2
    box = robot.link_map['left_' + FRAME].visual.geometry
    assert box.size == [0.05, 0.04, 0.03]
    assert robot.link_map['left_' + FRAME].collision.geometry.size == box.size
    # Without a case given, no geometry: no figure is typed that no datasheet backs.
    assert _expand(URDF_DIR / 'example.urdf.xacro').link_map[FRAME].visual is None
