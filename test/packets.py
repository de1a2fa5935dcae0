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


"""The flat records the parser hands out (framing.DataPacket), made from named ones for tests."""

from typing import Any

from i3dmgx2_driver.codec.commands import encode_record, LAYOUT_BY_TYPE, record_of
from i3dmgx2_driver.codec.framing import DataPacket


def values_of(record: Any) -> tuple:
    """Return a named record's fields as the parser unpacks them (``DataPacket.values``)."""
    return LAYOUT_BY_TYPE[type(record)].reply_struct.unpack_from(encode_record(record), 1)


def packet_of(address: int | None, record: Any, lqi: int | None = None,
              rssi: int | None = None) -> DataPacket:
    """Return the DataPacket the parser hands out for ``record``."""
    return DataPacket(address, LAYOUT_BY_TYPE[type(record)].code, values_of(record), lqi, rssi)


def as_sent(record: Any) -> Any:
    """Return ``record`` as it comes out of its bytes (its floats float32)."""
    return record_of(LAYOUT_BY_TYPE[type(record)].code, values_of(record))
