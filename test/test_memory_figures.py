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
The memory curve's figures mean what they say.

The curve subtracts what CPython's type cache alone keeps from the blocks
alive to show what else grows (``harness/type_cache.py``): the count must
rise when lookups by fresh names fill the cache, never pass its 4,096
entries, and fall to nothing when the cache is emptied. The curve's CSVs of
earlier runs (six columns) must still be read beside today's. The mappings
it reads (``--mappings``) must place pages touched for the first time in a
region that exists, and say when that region last grew.
"""

import ctypes
import gc
import mmap
import os
import sys
import threading

from harness.instrumented_node import HeapFigures
from harness.process_sampler import anon_by_mapping, append_mappings, mapping_changes
from harness.type_cache import ENTRIES, TypeCacheReader

ON_3_11 = sys.implementation.name == 'cpython' and sys.version_info[:2] == (3, 11)


def _look_up_fresh_names(count: int) -> None:
    """Look attributes up by names built at run time, on new classes (new versions)."""
    for index in range(count):
        kind = type(f'Kind{index}', (), {'field': index})
        name = ''.join(['fie', 'ld'])  # not the interned 'field': a str of its own
        assert getattr(kind, name) == index


def test_the_type_cache_reader_counts_the_names_only_the_cache_keeps():
    reader = TypeCacheReader()
    if not ON_3_11:
        assert not reader.found and reader.names_kept() is None
        return
    assert reader.found
    sys._clear_type_cache()
    emptied = reader.names_kept()
    _look_up_fresh_names(3000)
    filled = reader.names_kept()
    assert filled - emptied > 1000  # fresh names took entries (some share one, by hash)
    _look_up_fresh_names(20000)
    assert reader.names_kept() <= ENTRIES
    sys._clear_type_cache()
    assert reader.names_kept() <= emptied + 20  # the test runner's own lookups at most


def test_heap_figures_give_the_detail_only_when_asked():
    start_before = threading.Thread.start
    detail = HeapFigures(detail=True)
    try:
        started = detail()['threads_started']
        for _ in range(3):
            thread = threading.Thread(target=lambda: None)
            thread.start()
            thread.join()
        plain, detailed = HeapFigures(detail=False)(), detail()
    finally:
        detail.close()
    assert threading.Thread.start is start_before
    assert detailed['threads_started'] == started + 3
    assert 'type_cache_names' not in plain and 'malloc_arenas' not in plain
    assert plain['python_blocks'] > 0 and detailed['python_blocks'] > 0
    if ON_3_11:
        assert 0 <= detailed['type_cache_names'] <= ENTRIES
    if plain['malloc_in_use_kib'] is not None:  # glibc
        assert plain['malloc_mmapped_kib'] <= plain['malloc_in_use_kib']
        assert detailed['malloc_arenas'] >= 1


def test_the_level_after_a_full_collection_is_taken_by_the_collectors_own_callback():
    figures = HeapFigures(detail=True, collect_every=1e-6)
    try:
        first = figures()['after_full_gc']
        assert first['full_collections'] >= 1  # asked for: collected before the figures
        assert first['blocks'] > 0
        if ON_3_11:
            assert 0 <= first['type_cache'] <= ENTRIES
        gc.collect()  # anyone's full collection counts, not only those asked for
        assert figures()['after_full_gc']['full_collections'] >= first['full_collections'] + 1
    finally:
        figures.close()


def test_the_mappings_place_pages_touched_for_the_first_time_and_when(tmp_path):
    if not os.path.exists(f'/proc/{os.getpid()}/smaps'):
        assert anon_by_mapping(os.getpid()) is None
        return
    page = mmap.PAGESIZE
    # Anonymous and private, like an allocator's arena: no page touched yet.
    region = mmap.mmap(-1, 64 * page, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    try:
        # A flag of its own, so that the kernel does not merge it with a neighbour
        # (one of CPython's arenas, say) whose pages this process touches meanwhile.
        region.madvise(mmap.MADV_DONTFORK)
        view = ctypes.c_char.from_buffer(region)
        start = f'{ctypes.addressof(view):x}'
        del view
        assert start in anon_by_mapping(os.getpid())  # a mapping of its own
        path = str(tmp_path / 'mappings.jsonl')
        append_mappings(path, os.getpid(), 0.0, 0)
        untouched = anon_by_mapping(os.getpid())[start][2]
        for index in range(10):
            region[index * page] = 1
        append_mappings(path, os.getpid(), 60.0, 100)
        assert anon_by_mapping(os.getpid())[start][2] - untouched == 10 * page // 1024
        append_mappings(path, os.getpid(), 120.0, 200)  # nothing more touched
        line = next(text for text in mapping_changes(path) if f' {start} ' in text)
        assert line.split()[0] == f'+{10 * page // 1024}'
        assert line.endswith('last changed at 100 faults)')
        later = mapping_changes(path, from_faults=100)  # from the row at 100 on: none
        assert not any(f' {start} ' in text for text in later)
    finally:
        region.close()
