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
What the node published, as the campaign's subscriber received it.

Each message is kept by its exact values (packed as the truth's keys are), its
stamp, its orientation and its arrival time: all the checks need of it.
"""

import time

from harness.campaign_truth import _KEY, _QUAT
from harness.processes import Listener
from sensor_msgs.msg import Imu


class Subscriber(Listener):
    """The harness's rclpy listener, keeping each Imu message's values, stamp and orientation."""

    def __init__(self, depth: int = 10000, topics: tuple[str, ...] = ('imu/raw_data',)) -> None:
        self.rows: list[tuple[bytes, int, bytes, float]] = []
        self._topics = topics
        super().__init__(dict.fromkeys(topics, Imu), depth=depth)

    def _store(self, topic: str, msg: Imu) -> None:
        la, av, o = msg.linear_acceleration, msg.angular_velocity, msg.orientation
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.rows.append((_KEY.pack(la.x, la.y, la.z, av.x, av.y, av.z), stamp,
                          _QUAT.pack(o.x, o.y, o.z, o.w), time.time()))

    @property
    def count(self) -> int:
        """Messages received so far."""
        return len(self.rows)

    def publishers(self) -> int:
        """Return how many publishers of the topic this subscriber's node knows of."""
        return sum(self.node.count_publishers(topic) for topic in self._topics)
