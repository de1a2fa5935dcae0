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
magcal listening to the running node: its Imu and field for some minutes, and its calibration.

Each field is paired with the Imu message of the same stamp (one record
makes both). A line on stderr says how many readings came and what the
sweep still lacks, with which way to turn; Ctrl-C (or SIGTERM) ends the
listening and magcal fits what came. The node's own ``mag_hard_iron`` and
``mag_soft_iron`` are read first (its get_parameters service), so that the
fit is made on the raw field whatever the node applies.
"""

from collections.abc import Callable
import sys
import time

from rcl_interfaces.srv import GetParameters
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from sensor_msgs.msg import Imu, MagneticField

from .sources import listening, paired, stamp_of
from ..ros.mag_calibration import HARD_IRON, SOFT_IRON

#: Seconds to wait for the node's parameters.
PARAMETERS_S = 10.0


def calibration(node: Node, name: str) -> list[list[float]]:
    """Return node ``name``'s mag_hard_iron and mag_soft_iron; ValueError when it does not say."""
    client = node.create_client(GetParameters, f'{name}/get_parameters')
    if not client.wait_for_service(timeout_sec=PARAMETERS_S):
        raise ValueError(f'node {name} does not answer get_parameters: is it running '
                         '(--node names it)?')
    future = client.call_async(GetParameters.Request(names=[HARD_IRON, SOFT_IRON]))
    deadline = time.monotonic() + PARAMETERS_S  # the listening's thread spins
    while not future.done() and time.monotonic() < deadline:
        time.sleep(0.05)
    values = future.result().values if future.done() else []
    if len(values) != 2:
        raise ValueError(f'node {name} did not give {HARD_IRON} and {SOFT_IRON}')
    return [list(parameter_value_to_python(v)) for v in values]


def listen(topic: str, node_name: str, seconds: float,
           lacks: Callable[[list], str | None]) -> tuple[list, list[list[float]]]:
    """
    Listen for ``seconds`` (or until Ctrl-C); return the pairs and the node's calibration.

    ``lacks`` says what the pairs so far lack (magcal's coverage check), for the display.
    """
    # The topics arrive in any order: a field finds its Imu when the pairs are asked for
    # (in a copy of the fields while the spinner thread adds to them).
    imu: dict[tuple[int, int], Imu] = {}
    fields: list[MagneticField] = []
    with listening('i3dmgx2_magcal', topic, lambda m: imu.update({stamp_of(m): m}),
                   fields.append) as (node, stopped):
        source = f'{node.resolve_topic_name(topic)} (live)'
        applied = calibration(node, node_name)
        start = time.monotonic()
        while time.monotonic() - start < seconds and not stopped.wait(1.0):
            pairs = paired(imu, fields[:])
            missing = lacks(pairs) if pairs else 'nothing yet'
            left = max(0.0, seconds - (time.monotonic() - start))
            print(f'\r{left:5.0f} s left, {len(pairs)} readings: '
                  f'{missing or "enough: Ctrl-C fits them"}'[:160].ljust(160), end='',
                  file=sys.stderr, flush=True)
    pairs = paired(imu, fields)
    if not pairs:
        raise ValueError(f'no field on {source} paired with an Imu message: is the driver '
                         'running, with publish_mag?')
    return pairs, applied
