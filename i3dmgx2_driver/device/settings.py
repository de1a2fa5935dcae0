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
How to reach one device and how patient to be with it.

One frozen settings object for the supervisor (the port, the retry and
recovery timing) and the dialogue (the address, the stream, the request
timeouts). The node fills it from its parameter table, where each parameter
names the field it sets (``Spec.feeds`` in ros/parameter_table.py); a field no
parameter sets keeps its default here.
"""

from dataclasses import dataclass

from . import timeouts
from .realtime import NORMAL_SCHEDULING, ThreadPolicy
from ..codec import streams

Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class DeviceConfig:
    """How to reach the device and how patient to be with it."""

    port: str
    address: int
    baud: int = 115200
    wireless: bool = True
    low_latency: bool = True
    stall_timeout: float = timeouts.STALL_TIMEOUT
    reconnect_interval: float = timeouts.RECONNECT_INTERVAL
    data_rate_hz: float | None = None
    #: Command byte of the record to stream (one of codec.streams.STREAMS).
    stream: int = streams.DEFAULT.code
    request_timeout: float = timeouts.REQUEST_TIMEOUT
    request_retries: int = timeouts.REQUEST_RETRIES
    continuous_retries: int = timeouts.CONTINUOUS_TRIES
    #: Scheduling of the reader thread (its SCHED_FIFO priority).
    thread_policy: ThreadPolicy = NORMAL_SCHEDULING
    #: Reconnect to a known sensor with one serial-number read (False: the full dialogue).
    fast_reconnect: bool = True
    #: Per try and tries of that read: short, so that a reply lost in a stall is asked
    #: again soon after the radio is back.
    resume_timeout: float = timeouts.RESUME_TIMEOUT
    resume_retries: int = timeouts.RESUME_RETRIES
    #: Gyro bias (rad/s) and accelerometer bias (g) written to the sensor's RAM at
    #: every start (0xCA, 0xC9) and checked against its echo; None: leave it as it is.
    gyro_bias: Vector3 | None = None
    accel_bias: Vector3 | None = None
