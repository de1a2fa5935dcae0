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
What a gyro bias capture came to, and how far a data rate may stray.

The services make these and diagnostics shows them: they live here so that
neither imports the other.
"""

from typing import NamedTuple

#: How far the measured data rate may be from the configured one before it is a warning.
RATE_TOLERANCE = 0.05


class Calibration(NamedTuple):
    """The outcome of the last gyro bias capture of this session."""

    #: Host time (s since the epoch) of the capture.
    time: float
    #: Whether the bias was accepted (the sensor stayed still).
    accepted: bool
    #: The captured bias (rad/s), sensor axes; None when no reply came.
    bias: tuple[float, float, float] | None
    sampling_ms: int
    #: One line on what happened (why it was refused, or that it is in use).
    summary: str
