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
The device layer: the serial port and the protocol dialogue, no ROS.

``port`` opens the serial port and reads what is there as soon as it is
there; ``link`` is one sensor's connection (the reader thread, the
request/reply exchanges, and the one rule that tells a reply from a record
of the stream), read in one of ``reader_threads``, kept for the process's
life and handed port after port; ``shared_port`` opens a port the same
way for a sensor alone and for several sensors whose links share one port
and its reader. ``sensor_steps`` holds the steps
every conversation with a sensor is made of (quiet, stop, start a stream
and see its records, the divider, a bias stored), with the waits of
``timeouts``: the node's ``dialogue`` puts them in its order, and
``discover`` and ``bringup`` use them directly; ``identity`` reads what a
sensor says it is. ``supervisor`` keeps a link alive through stalls and
unplugs (its policies in ``watchdog``, its state and counters in
``status``). The operations that borrow the sensor from the stream
(``operation``): ``gyro_bias`` and ``self_test``, with ``record_rate``.
``clock`` and ``sample_clock`` turn device timer ticks into host timestamps.
"""
