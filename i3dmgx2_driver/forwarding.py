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
An attribute a facade reads from one of its parts.

A class split by concern stays behind as a facade, so that its callers keep
their API (``link.records``, ``dialogue.divider``, ``sim.port``); a property
for each such attribute repeated the same four lines dozens of times, each a
place where a rename could go wrong. One line says where the value lives.
No ROS, no serial: every layer above the codec may use it.
"""

from typing import Any


class Forwarded:
    """
    ``name = Forwarded('part', 'doc')``: ``obj.name`` reads ``obj.part.name``.

    ``attribute`` names the part's attribute when it differs; ``writable``
    lets ``obj.name = value`` set it on the part (otherwise it is read-only,
    as a property without a setter is).
    """

    def __init__(self, part: str, doc: str, attribute: str | None = None,
                 writable: bool = False) -> None:
        self.part = part
        self.attribute = attribute
        self.writable = writable
        self.__doc__ = doc

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name
        if self.attribute is None:
            self.attribute = name

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return getattr(getattr(obj, self.part), self.attribute)

    def __set__(self, obj: Any, value: Any) -> None:
        if not self.writable:
            raise AttributeError(f"property '{self.name}' of '{type(obj).__name__}' object "
                                 f'has no setter')
        setattr(getattr(obj, self.part), self.attribute, value)
