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
The line budget: whether a record streamed at a rate fits the serial line.

A streamed record that the line cannot carry is not queued by the sensor:
it is skipped, and the host sees a lower rate with no error anywhere. So the
driver does the arithmetic before it streams: packet bytes (from the
layout table and the framing, never typed by hand) times records a second,
against what the baud rate carries, 10 bits a byte (start, 8 data, stop).

A margin of :data:`MARGIN` (5 %) of the line is kept free: UART clocks are
allowed ~2 % of baud error, the base station adds gaps between packets, and
the radio retransmits, so a stream planned at 100 % of the line loses
records in practice. The highest rate that fits is a rate the device can
actually run at: 51200 / x for a whole divider x (``data_rate``).
"""

from collections.abc import Sequence
import math
from typing import NamedTuple

from .data_rate import MAX_DIVIDER, MIN_DIVIDER, rate_of_divider
from .framing import DATA_TRAILER_SIZE, HEADER_SIZE
from .layouts import LAYOUTS

#: Bits on the line per byte: start, 8 data bits, stop (8N1).
BITS_PER_BYTE = 10
#: Share of the line kept free (see the module docstring).
MARGIN = 0.05


def packet_size(code: int, wireless: bool) -> int:
    """
    Return the bytes one record of ``code`` takes on the line.

    Wireless: the data packet (header, record without its checksum, LQI,
    RSSI, packet checksum); wired: the record and its checksum.
    """
    layout = LAYOUTS[code]
    if not layout.record_size:
        raise ValueError(f'0x{code:02X} has no reply record')
    return HEADER_SIZE + layout.record_size + DATA_TRAILER_SIZE if wireless else layout.wired_size


def line_bytes_per_second(baud: int) -> float:
    """Return the bytes a second a serial line of ``baud`` carries (8N1)."""
    return baud / BITS_PER_BYTE


def usable_bytes_per_second(baud: int, margin: float = MARGIN) -> float:
    """Return the bytes a second a stream may use, the margin kept free."""
    return line_bytes_per_second(baud) * (1.0 - margin)


def bytes_per_second(code: int, rate_hz: float, wireless: bool) -> float:
    """Return the bytes a second ``code`` streamed at ``rate_hz`` needs."""
    return packet_size(code, wireless) * rate_hz


def wire_time(code: int, baud: int, wireless: bool) -> float:
    """Return the seconds one packet of ``code`` takes on the line, first bit to last."""
    return packet_size(code, wireless) * BITS_PER_BYTE / baud


def max_rate(code: int, baud: int, wireless: bool, margin: float = MARGIN) -> float | None:
    """
    Return the highest rate the device can run at (51200 / x) that fits, or None.

    None only when not even the slowest rate (1 Hz) fits.
    """
    return max_shared_rate((code,), baud, wireless, margin)


def shared_fits(streams: Sequence[tuple[int, float]], baud: int, wireless: bool,
                margin: float = MARGIN) -> bool:
    """Tell whether several sensors' streams, (code, rate) each, fit one line together."""
    return (sum(bytes_per_second(code, rate, wireless) for code, rate in streams)
            <= usable_bytes_per_second(baud, margin))


def max_shared_rate(codes: Sequence[int], baud: int, wireless: bool,
                    margin: float = MARGIN) -> float | None:
    """
    Return the highest rate (51200 / x) at which every sensor can stream its ``codes`` entry.

    Sensors behind one base station share its serial line: their packets
    together must fit it. None when not even 1 Hz each fits.
    """
    limit = usable_bytes_per_second(baud, margin) / sum(packet_size(c, wireless) for c in codes)
    divider = max(MIN_DIVIDER, math.ceil(rate_of_divider(1) / limit - 1e-9))
    if divider > MAX_DIVIDER:
        return None
    while not shared_fits([(c, rate_of_divider(divider)) for c in codes], baud, wireless, margin):
        divider += 1  # float rounding at the boundary: at most one step
    return rate_of_divider(divider)


class Budget(NamedTuple):
    """One stream on one line: what it needs, what the line gives, what would fit."""

    code: int
    rate_hz: float
    baud: int
    wireless: bool
    packet_bytes: int
    #: Bytes a second the stream needs.
    needed: float
    #: Bytes a second the line carries, and what the margin leaves of it.
    capacity: float
    usable: float
    #: Highest rate the device can run at that fits (None: none does).
    max_rate_hz: float | None

    @property
    def fits(self) -> bool:
        """Tell whether the stream fits the line, margin kept."""
        return self.needed <= self.usable

    @property
    def share(self) -> float:
        """Return the share of the whole line the stream uses (1.0: all of it)."""
        return self.needed / self.capacity


def budget(code: int, rate_hz: float, baud: int, wireless: bool, margin: float = MARGIN) -> Budget:
    """Return the line budget of ``code`` streamed at ``rate_hz``."""
    return Budget(code, rate_hz, baud, wireless, packet_size(code, wireless),
                  bytes_per_second(code, rate_hz, wireless), line_bytes_per_second(baud),
                  usable_bytes_per_second(baud, margin), max_rate(code, baud, wireless, margin))
