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
for later, in the middle of the heap where it is never returned by itself.
tracemalloc found nothing the node keeps growing with the faults, yet the
memory curve's anonymous RSS rose with them (docs/soak.md): freed pages that
stayed mapped. ``malloc_trim(0)`` walks every arena and hands back every
whole free page (glibc 2.8 and later); it costs well under a millisecond on
a driver's heap, and it is called once after a fault has passed, never on a
sample's path. Where there is no glibc (musl, another platform) it is a no-op.
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
