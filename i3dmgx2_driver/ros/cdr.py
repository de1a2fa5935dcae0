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
The records' messages written as the bytes the middleware sends: plain CDR, little endian.

rclpy publishes ``bytes`` as they are (``publish_raw``), which skips the
conversion of a message object to C. That conversion is not only time: the
generated C code looks every field up by a C string
(``PyObject_GetAttrString``), a new ``str`` each time, and CPython's type
cache keeps the last name of each of its 4,096 entries, indexed by the
name's address, so a node that publishes message objects keeps a slowly
growing set of dead names (docs/soak.md, "The type cache"). The node's
records, on the hot path, are packed with one ``struct`` each
(:class:`StampedDoubles`); the messages of once a second or less
(``/diagnostics``, the temperature, ``~/is_calibrated``) are message
objects: packing them by hand is not worth its code.

Alignment counts from the end of the 4-byte encapsulation header, as
Fast DDS and Cyclone DDS write and read it (both read little-endian CDR
whatever the host; ``test/test_serialized_messages.py`` reads the bytes back
with rclpy's own deserializer).
"""

import struct

#: Encapsulation header of a serialized message: plain CDR, little endian.
CDR_LE = b'\x00\x01\x00\x00'


class StampedDoubles:
    """
    A message that is a ``std_msgs/Header`` and then float64s (Imu, MagneticField).

    One ``struct`` for the whole message: sec (int32), nanosec (uint32),
    frame_id as its length with the NUL (uint32), its bytes and a NUL,
    padding to the 8-byte alignment of the first float64, then ``doubles``
    (struct codes: ``d`` a float64, ``72s`` nine of them packed once, a
    covariance). The hot path calls :attr:`struct`'s ``pack`` itself, with
    :data:`CDR_LE`, the stamp, ``len(frame)`` and :attr:`frame` first.
    """

    def __init__(self, frame_id: str, doubles: str) -> None:
        #: The frame_id as it goes on the wire: UTF-8 and a NUL.
        self.frame = frame_id.encode() + b'\x00'
        self.struct = struct.Struct(
            f'<4siII{len(self.frame)}s{-(12 + len(self.frame)) % 8}x{doubles}')
