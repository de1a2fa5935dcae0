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
Raw captures of the byte stream from the port, and the real-records fixture.

A capture keeps the bytes exactly as each read returned them, with the host
time of the read, so that a session can be replayed into a pseudo-terminal
(``tools.replay``) with its original pacing and fragmentation, or decoded
later (``tools.plot``) with a parser that did not exist when it was made.
Nothing here knows ROS or serial ports: bytes and times in, bytes and times
out.

``file_format`` reads and writes the capture file; ``fixtures`` turns the
real sensor's records into the reads a host would have made; ``raw_capture``
is the node's capture of every read, ``fault_capture`` the last seconds of
them, kept always and written when something goes wrong.
"""
