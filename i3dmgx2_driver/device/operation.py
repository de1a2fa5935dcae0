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
An operation that borrows the sensor from the stream, as a service runs it.

The supervisor's ``run_paused`` stops the stream, lends the operation the
link and starts the stream again; the gyro bias capture (gyro_bias.py) and
the self test (self_test.py) are two such operations. What both need is
here: the device as a small ``Device`` Protocol the supervisor satisfies,
the errors an operation may end with, and polled inertial readings
averaged, the reading both start from.
"""

from collections.abc import Callable, Sequence
import math
from typing import Any, Protocol

from .dialogue import SensorDialogue
from .link import DeviceError, DeviceLink
from .port import PortError
from .sensor_firmware import SensorFirmware
from .status import DeviceStatus
from ..codec import layouts
from ..codec.errors import CodecError
from ..codec.records import Vector3

#: Polled 0xC2 records averaged before and after a capture, and by the self test.
POLLS = 5
#: Errors a device operation can end with; anything else is a bug and propagates.
OPERATION_ERRORS = (PortError, DeviceError, CodecError, OSError)


def norm(v: Sequence[float]) -> float:
    """Return the length of ``v``."""
    return math.sqrt(sum(x * x for x in v))


def _mean(vectors: Sequence[Sequence[float]]) -> Vector3:
    return tuple(sum(axis) / len(vectors) for axis in zip(*vectors, strict=True))


def format_vector(v: Sequence[float], digits: int = 5) -> str:
    """Write a vector as ``(x, y, z)``, the form the service messages and diagnostics use."""
    return '(' + ', '.join(f'{x:.{digits}f}' for x in v) + ')'


def poll_inertial(link: DeviceLink, count: int = POLLS) -> tuple[Vector3, Vector3]:
    """Poll 0xC2 ``count`` times; return the mean acceleration (g) and rate (rad/s)."""
    code = layouts.ACCEL_ANG_RATE
    replies = [link.request(bytes((code,)), code) for _ in range(count)]
    return _mean([r.accel for r in replies]), _mean([r.angular_rate for r in replies])


class Device(Protocol):
    """What an operation needs of the device side (the supervisor is one): operations only."""

    #: The sensor's firmware (0xE9), asked before a gated command is sent.
    firmware: SensorFirmware
    #: The steps an operation takes on the lent link (an EEPROM write among them, each
    #: counted), and what is written back at every start (``gyro_bias``).
    dialogue: SensorDialogue

    def status(self) -> DeviceStatus:
        """Return the device side's snapshot."""

    def run_paused(self, operation: Callable[[DeviceLink], Any]) -> Any:
        """Stop the stream, run ``operation(link)``, start the stream again."""
