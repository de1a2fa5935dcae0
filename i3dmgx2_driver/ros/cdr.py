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
Fast DDS and Cyclone DDS write it; whoever publishes these bytes checks once
that the middleware in use reads them back as the message (:func:`reads_back`).
"""

from collections.abc import Iterable
import struct
from typing import Any

#: Encapsulation header of a serialized message: plain CDR, little endian.
CDR_LE = b'\x00\x01\x00\x00'


class StampedDoubles:
    """
    A message that is a ``std_msgs/Header`` and then float64s (Imu, MagneticField).

    One ``struct`` for the whole message: sec (int32), nanosec (uint32),
    frame_id as its length with the NUL (uint32), its bytes and a NUL,
    padding to the 8-byte alignment of the first float64, the float64s.
    The hot path calls :attr:`struct` itself, with :data:`CDR_LE`, the
    stamp, ``len(frame)`` and :attr:`frame` first: no method of this class
    in between (one Python call less a record: 0.45 us of 3.5).
    """

    def __init__(self, frame_id: str, doubles: int) -> None:
        #: The frame_id as it goes on the wire: UTF-8 and a NUL.
        self.frame = frame_id.encode() + b'\x00'
        self.struct = struct.Struct(
            f'<4siII{len(self.frame)}s{-(12 + len(self.frame)) % 8}x{doubles}d')


def reads_back(pairs: Iterable[tuple[bytes, Any]]) -> bool:
    """
    Tell whether each serialized message reads back as the message it stands for.

    rclpy deserializes with the middleware in use, so a middleware that did
    not read little-endian CDR makes the caller publish message objects
    instead. Compared as messages, not bytes: a serializer may leave its
    padding bytes uninitialised. The pairs are taken one at a time, so a
    message refilled in place may stand in several of them (pass a generator).
    Once per process and kind: ``deserialize_message`` keeps a little memory
    per call.
    """
    from rclpy.serialization import deserialize_message

    return all(deserialize_message(data, type(message)) == message for data, message in pairs)
