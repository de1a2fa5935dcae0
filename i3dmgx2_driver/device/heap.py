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
Give the C heap's free pages back to the system after a fault.

A fault is a burst of allocation in threads that live for one connection
(a new reader, the dialogue's replies, the log lines, a capture written):
glibc serves each thread from an arena of its own and keeps what they free
for later, in the middle of the heap, where it is not returned by itself.
``malloc_trim(0)`` walks every arena and hands back every whole free page
(glibc 2.8 and later); it costs microseconds on a driver's heap, and it is
called once after a fault has passed, never on a sample's path, so that a
node that meets faults for weeks holds what it uses, not what it once used.
(The memory curve's steady growth had another cause, a callback kept per
executor wake: ros/main.py.) Where there is no glibc it is a no-op.
"""

from collections.abc import Callable
import ctypes
import functools


@functools.cache
def _malloc_trim() -> Callable[[int], int]:
    """Return glibc's ``malloc_trim``, or a stand-in that gives nothing back."""
    try:
        # The process's own symbols (libc's among them): find_library would run ldconfig.
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError, TypeError):
        return lambda pad: 0
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_heap() -> bool:
    """Return the C heap's free pages to the system; True if anything was given back."""
    return bool(_malloc_trim()(0))
