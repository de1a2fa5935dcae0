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
The calibration file, and the ROS 2 parameter files the tools write.

``~/capture_gyro_bias`` writes an accepted capture here when the
``calibration_file`` parameter names a file; loaded with ``--params-file``
at the next start, the dialogue writes the bias with 0xCA, so a calibration
lasts without an EEPROM write (README, Calibration). It is the node's
parameter file, named by the node's name: ROS's side of keeping a bias,
where the capture itself (device/gyro_bias.py) knows no ROS. magcal's and
noise's files (``/**``: any node) are written by the same :func:`params_file`.
"""

from collections.abc import Sequence
import os
import time
from typing import Any

from ..codec.records import Vector3


def yaml_float(value: float, spec: str = '.6g') -> str:
    """Return ``value`` as YAML 1.1 reads a float (PyYAML, kalibr): always with a dot."""
    mantissa, e, exponent = format(float(value), spec).partition('e')
    if mantissa.lstrip('-').isdigit():
        mantissa += '.0'
    return mantissa + e + exponent


def params_file(comments: Sequence[str], node_name: str, values: dict[str, Any],
                spec: str = '.6g') -> str:
    """Return a parameter file setting ``values`` (floats, or lists of them) for ``node_name``."""
    lines = [f'# {line}' for line in comments] + [f'{node_name}:', '  ros__parameters:']
    for name, value in values.items():
        text = (yaml_float(value, spec) if isinstance(value, float) else
                '[' + ', '.join(yaml_float(v, spec) for v in value) + ']')
        lines.append(f'    {name}: {text}')
    return '\n'.join(lines) + '\n'


def calibration_yaml(node_name: str, bias: Vector3) -> str:
    """
    Return a ROS 2 parameter file that sets ``gyro_bias`` for ``node_name``.

    The values are written with ``repr`` (the spec ``''``), which reads back
    as the same double, so the bias the node writes next time is the one
    captured, to the bit; a mantissa without a point gets one (``1e-09`` is
    text to YAML 1.1, and a string is no bias).
    """
    stamp = time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())
    return params_file([f'Written by ~/capture_gyro_bias (i3dmgx2_driver) at {stamp}: load it '
                        'with', '--params-file <this file> (after the main one) to write this '
                        'bias at start.'], node_name, {'gyro_bias': bias}, spec='')


def write_calibration_file(path: str, node_name: str, bias: Vector3) -> None:
    """Write ``calibration_yaml`` to ``path`` whole (a new file renamed over the old)."""
    path = os.path.expanduser(path)
    temporary = f'{path}.tmp'
    with open(temporary, 'w') as handle:
        handle.write(calibration_yaml(node_name, bias))
    os.replace(temporary, path)
