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

"""A facade's forwarded attributes read, and write only where allowed, through the part."""

from types import SimpleNamespace

from i3dmgx2_driver.forwarding import Forwarded
import pytest


class Facade:
    """Two parts, three attributes forwarded."""

    count = Forwarded('counter', 'How many so far.')
    total = Forwarded('counter', 'The sum, under another name.', 'sum_')
    code = Forwarded('watch', 'The code streamed.', writable=True)

    def __init__(self) -> None:
        self.counter = SimpleNamespace(count=3, sum_=7)
        self.watch = SimpleNamespace(code=None)


def test_reads_come_from_the_part_as_it_is_now():
    facade = Facade()
    assert (facade.count, facade.total, facade.code) == (3, 7, None)
    facade.counter.count = 4
    assert facade.count == 4


def test_a_writable_one_writes_to_the_part():
    facade = Facade()
    facade.code = 0xCC
    assert facade.watch.code == 0xCC and facade.code == 0xCC
    assert 'code' not in vars(facade)


def test_a_read_only_one_refuses_as_a_property_does():
    facade = Facade()
    with pytest.raises(AttributeError, match="'count' of 'Facade' object has no setter"):
        facade.count = 5
    assert facade.counter.count == 3


def test_the_class_shows_the_descriptor_and_its_doc():
    assert Facade.total.__doc__ == 'The sum, under another name.'
    assert Facade.code.writable and not Facade.count.writable
