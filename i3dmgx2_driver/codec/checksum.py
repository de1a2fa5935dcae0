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
The one checksum of the protocol: a 16-bit sum of bytes.

Wired records, wireless command packets and wireless data packets all use it;
they differ only in which bytes are summed, which the framing module decides.
"""

from zlib import adler32

ByteString = bytes | bytearray | memoryview

#: The most bytes whose sum Adler-32's first half gives exactly: 256 * 255 < 65521.
EXACT_SUM_BYTES = 256


def checksum16(data: ByteString) -> int:
    """
    Return the sum of ``data`` modulo 65536.

    Adler-32's first half, started at 0, is the sum of the bytes modulo
    65521: the sum itself for up to ``EXACT_SUM_BYTES`` bytes, more than any
    packet of the protocol holds. Summed in C, a record's sum costs a few
    microseconds where Python's ``sum()`` over its bytes, on the cold cache of
    the reader thread between two records, cost 23 (docs/cpu.md).
    """
    return adler32(data, 0) & 0xFFFF if len(data) <= EXACT_SUM_BYTES else sum(data) & 0xFFFF
