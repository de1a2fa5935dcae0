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
The calibration file: a ROS 2 parameter file that sets ``gyro_bias`` for the node.

``~/capture_gyro_bias`` writes an accepted capture here when the
``calibration_file`` parameter names a file; loaded with ``--params-file``
at the next start, the dialogue writes the bias with 0xCA, so a calibration
lasts without an EEPROM write (README, Calibration). It is the node's
parameter file, named by the node's name: ROS's side of keeping a bias,
where the capture itself (device/gyro_bias.py) knows no ROS.
"""

import os
import time

from ..codec.records import Vector3


def calibration_yaml(node_name: str, bias: Vector3) -> str:
    """
    Return a ROS 2 parameter file that sets ``gyro_bias`` for ``node_name``.

    The values are written with ``repr``, which reads back as the same double,
    so the bias the node writes next time is the one captured, to the bit; a
    mantissa without a point gets one (``1e-09`` is text to YAML 1.1, and a
    string is no bias).
    """
    def number(value: float) -> str:
        text = repr(float(value))
        mantissa, e, exponent = text.partition('e')
        return text if '.' in mantissa else f'{mantissa}.0{e}{exponent}'

    values = ', '.join(number(v) for v in bias)
    return (f'# Written by ~/capture_gyro_bias (i3dmgx2_driver) at '
            f'{time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}: load it with\n'
            f'# --params-file <this file> (after the main one) to write this bias at start.\n'
            f'{node_name}:\n'
            f'  ros__parameters:\n'
            f'    gyro_bias: [{values}]\n')


def write_calibration_file(path: str, node_name: str, bias: Vector3) -> None:
    """Write ``calibration_yaml`` to ``path`` whole (a new file renamed over the old)."""
    path = os.path.expanduser(path)
    temporary = f'{path}.tmp'
    with open(temporary, 'w') as handle:
        handle.write(calibration_yaml(node_name, bias))
    os.replace(temporary, path)
