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

"""The C heap's free pages go back to the system: what keeps a node's RSS from creeping."""

import sys

from i3dmgx2_driver.device.heap import release_free_heap
import pytest


def anonymous_kib() -> int:
    """Return this process's anonymous resident memory (KiB)."""
    with open('/proc/self/status') as status:
        for line in status:
            if line.startswith('RssAnon:'):
                return int(line.split()[1])
    raise AssertionError('no RssAnon in /proc/self/status')


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='glibc and /proc: Linux')
def test_freed_memory_in_the_middle_of_the_heap_is_given_back():
    # 40 MiB in 4-KiB blocks (malloc's, not CPython's small-object arenas), then every
    # block but one in 64 freed: the heap cannot shrink from its top, and glibc keeps
    # the holes mapped until it is told.
    blocks = [bytearray(4096) for _ in range(10_000)]
    keep = blocks[::64]
    del blocks
    before = anonymous_kib()
    assert release_free_heap()
    after = anonymous_kib()
    assert before - after > 20_000, (before, after)
    assert len(keep) == 157
