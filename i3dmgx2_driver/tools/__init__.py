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
Command-line tools: ``replay`` and ``plot`` around captures, ``discover`` and ``bringup``.

They never use ROS, so that a capture can be replayed into a driver, or
looked at, and a sensor found, on any machine with Python. The one
exception is ``monitor``, a person's one-line view of the node's IMU topic:
a ROS subscriber, which nothing else imports, so that rclpy is loaded only
when it runs.
"""
