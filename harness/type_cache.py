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
How many names CPython's type method cache alone keeps alive, read without tracing.

The memory curve's CPython blocks grow by a little over one a fault, and
tracemalloc, the only tool that places blocks, shows the type cache's names
among them but scatters too much to count them. CPython 3.11 keeps the cache
in the interpreter's state, 4,096 entries of (version, name, value), indexed
by the type's version and the name's *address*; each entry holds a reference
to its name. The generated message code looks attributes up by C string,
a fresh ``str`` each time, so an entry may be the only holder of its name:
one block the cache keeps until another name takes the entry. This module
finds the table (a probe lookup whose name and value it knows, searched for
in the interpreter state's mapping) and counts, at any moment, the entries
whose name has no other holder. Bounded by construction (4,096), so a curve
can subtract it and show what else grows.

CPython 3.11 only (the table's place and layout change in 3.12); ``None``
elsewhere. Read under the GIL (ctypes' ``from_address``, no foreign call),
so no other thread changes the table while it is read.
"""

import ctypes
import struct
import sys

#: Entries of the table (1 << MCACHE_SIZE_EXP in CPython 3.11).
ENTRIES = 4096
#: Bytes of one entry: an unsigned int (padded to 8), two pointers.
_ENTRY = 24
#: How far past the interpreter state's address the table is looked for (bytes).
_SEARCH = 4 << 20


class _Probe:
    """A class whose one attribute is looked up to leave a known entry in the table."""

    marker = object()


def _mapping_end(address: int) -> int | None:
    """Return the end of the mapping of this process that holds ``address``."""
    with open('/proc/self/maps') as maps:
        for line in maps:
            start, end = (int(part, 16) for part in line.split(None, 1)[0].split('-'))
            if start <= address < end:
                return end
    return None


def _probe() -> str:
    """
    Look ``marker`` up on a ``_Probe`` by a fresh name; return the name.

    A str of its own at its own address, not the interned one: a miss, which
    leaves an entry holding this name and the marker.
    """
    name = ''.join(['mar', 'ker'])
    getattr(_Probe(), name)
    return name


def _find_table() -> int | None:
    """
    Return the address of the table's first entry, or None if it is not found.

    Every place in the mapping that holds the probe's (name, value) pair is a
    candidate (the first one seen may be a copy elsewhere in the state): the
    table is where a second probe, by another fresh name, lands at the index
    CPython's hash gives it. A few tries, in case another lookup took the
    probe's entry first.
    """
    if sys.implementation.name != 'cpython' or sys.version_info[:2] != (3, 11):
        return None
    get = ctypes.pythonapi.PyInterpreterState_Get
    get.restype = ctypes.c_void_p
    interpreter = get()
    end = _mapping_end(interpreter)
    if end is None:
        return None
    length = min(_SEARCH, end - interpreter)
    _Probe().marker  # noqa: B018 - the lookup gives the type its version tag
    for _ in range(5):
        name = _probe()
        memory = bytes((ctypes.c_char * length).from_address(interpreter))
        pattern = struct.pack('PP', id(name), id(_Probe.marker))
        found = memory.find(pattern)
        while found >= 8:
            version = struct.unpack_from('I', memory, found - 8)[0]
            index = (version ^ (id(name) >> 3)) & (ENTRIES - 1)
            table = interpreter + found - 8 - index * _ENTRY
            if interpreter <= table and table + ENTRIES * _ENTRY <= end \
                    and _lands_at(table, version):
                return table
            found = memory.find(pattern, found + 1)
    return None


def _lands_at(table: int, version: int) -> bool:
    """Tell whether a second probe's entry is where ``table`` and CPython's hash put it."""
    other = _probe()
    index = (version ^ (id(other) >> 3)) & (ENTRIES - 1)
    entry = bytes((ctypes.c_char * _ENTRY).from_address(table + index * _ENTRY))
    return entry[8:] == struct.pack('PP', id(other), id(_Probe.marker))


class TypeCacheReader:
    """Counts the names only CPython's type method cache keeps (None if not found)."""

    def __init__(self) -> None:
        self._table = _find_table()

    @property
    def found(self) -> bool:
        """Tell whether the table is known: CPython 3.11, and the probe's entry was seen."""
        return self._table is not None

    def names_kept(self) -> int | None:
        """Return how many entries hold a name nothing else refers to."""
        if self._table is None:
            return None
        # No other thread may run between the copy and the last refcount read (a name
        # replaced meanwhile may be freed): nothing below lets the GIL go, and the
        # interpreter is asked not to take it away for the few ms the count takes.
        interval = sys.getswitchinterval()
        sys.setswitchinterval(60.0)
        try:
            memory = bytes((ctypes.c_char * (ENTRIES * _ENTRY)).from_address(self._table))
            none = id(None)
            kept = 0
            for offset in range(0, ENTRIES * _ENTRY, _ENTRY):
                name = struct.unpack_from('P', memory, offset + 8)[0]
                if name and name != none and ctypes.c_ssize_t.from_address(name).value == 1:
                    kept += 1
        finally:
            sys.setswitchinterval(interval)
        return kept
