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
The node applying a magnetometer calibration: real node, simulator and rclpy across processes.

The simulated sensor rests with hard and soft iron on its field; the node,
given the calibration that undoes them, publishes the Earth's field as the
simulator knows it, and /diagnostics says a calibration is loaded. A matrix
that is no calibration stops the node at start with exit 2.
"""

import time

from diagnostic_msgs.msg import DiagnosticArray
from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.codec.orientation import body_vector, ENU
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.motion import Motion, MotionConfig
from i3dmgx2_driver.tools.noise import yaml_float
import numpy as np
import pytest
from sensor_msgs.msg import MagneticField

pytestmark = pytest.mark.slow

HARD = (0.08, -0.05, 0.03)
SOFT = (1.1, 0.05, -0.03, 0.05, 0.9, 0.02, -0.03, 0.02, 1.0)


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


def _listed(values) -> str:
    return '[' + ','.join(yaml_float(float(v)) for v in values) + ']'


def test_the_node_publishes_the_field_its_calibration_undistorts():
    motion = MotionConfig(static=True, hard_iron=HARD, soft_iron=SOFT)
    truth = np.array(body_vector(Motion(motion).state(0.0).mag, ENU)) * 1e-4
    correction = np.linalg.inv(np.reshape(SOFT, (3, 3)))
    with PtySimulator(SimulatorConfig(seed=57, motion=motion)) as sim:
        listener = Listener({'imu/mag': MagneticField, '/diagnostics': DiagnosticArray})
        node = NodeProcess({'port': sim.port, 'address': 95,
                            'mag_hard_iron': _listed(np.array(HARD) * 1e-4),
                            'mag_soft_iron': _listed(correction.ravel())})
        with listener, node:
            got = listener.wait_for('imu/mag', 50, timeout=30)
            assert len(got) >= 50, node.output()
            field = np.array([(m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z)
                              for m in got])
            # The distortion is ~20 % of the field (10 uT); the noise 0.2 uT a reading.
            np.testing.assert_allclose(field.mean(axis=0), truth, atol=1e-7)
            deadline = time.monotonic() + 15
            while not _says_loaded(listener) and time.monotonic() < deadline:
                time.sleep(0.1)
            assert _says_loaded(listener), node.output()
            assert node.stop()[0] == 0, node.output()


def _says_loaded(listener: Listener) -> bool:
    return any(kv.key == 'magnetometer calibration' and kv.value == 'loaded'
               for array in listener.received('/diagnostics') for status in array.status
               for kv in status.values)


def test_a_matrix_that_is_not_symmetric_stops_the_node_naming_it():
    node = NodeProcess({'address': 95, 'mag_soft_iron': _listed((1, 0.1, 0, 0, 1, 0, 0, 0, 1))})
    with node:
        assert node.wait(timeout=30) == 2
        assert "parameter 'mag_soft_iron' must be a symmetric (within 1e-6 relative), " \
            'positive-definite 3x3 matrix' in node.output(), node.output()
        assert 'Traceback' not in node.output(), node.output()
