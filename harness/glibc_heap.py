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
glibc's own figures for the process's C heap: what is in use, and how many arenas.

RSS also counts memory an allocator keeps after it was freed, so the memory
benchmarks read the heap in use beside it (the instrumented node's rows,
``benchmarks/rosout_memory.py``). glibc 2.33 and later only; elsewhere
every figure is None.
"""

import ctypes

#: The C library (and the rest of the process's symbols), opened once.
_LIBC = ctypes.CDLL(None)


class MallInfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2`` (every field a size_t)."""

    _fields_ = [(name, ctypes.c_size_t) for name in (
        'arena', 'ordblks', 'smblks', 'hblks', 'hblkhd', 'usmblks', 'fsmblks', 'uordblks',
        'fordblks', 'keepcost')]


def _mallinfo2_function():  # noqa: ANN202 - a ctypes function, or None
    try:
        function = _LIBC.mallinfo2
    except (AttributeError, OSError):
        return None  # not glibc, or older than 2.33
    function.restype = MallInfo2
    return function


_MALLINFO2 = _mallinfo2_function()


def mallinfo2() -> MallInfo2 | None:
    """Return glibc's figures over all arenas now (None off glibc or before 2.33)."""
    return _MALLINFO2() if _MALLINFO2 is not None else None


def malloc_arenas() -> int | None:
    """Return how many arenas glibc's allocator has (``malloc_info``), None off glibc."""
    try:
        open_memstream, malloc_info = _LIBC.open_memstream, _LIBC.malloc_info
    except AttributeError:
        return None
    buffer, size = ctypes.c_char_p(), ctypes.c_size_t()
    open_memstream.restype = ctypes.c_void_p
    stream = open_memstream(ctypes.byref(buffer), ctypes.byref(size))
    if not stream:
        return None
    try:
        malloc_info(0, ctypes.c_void_p(stream))
    finally:
        _LIBC.fclose(ctypes.c_void_p(stream))
    text = ctypes.string_at(buffer, size.value)
    _LIBC.free(buffer)
    return text.count(b'<heap nr=')
