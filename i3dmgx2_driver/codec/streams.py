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
The streams the driver offers: a name for each streamable record, what it carries.

What a record carries is read from its layout in the command table (the
reply's field names), not listed again here: ``accel``, ``angular_rate``,
``mag``, and the attitude as the matrix M (``matrix``) or as Euler angles
(``roll``, ``pitch``, ``yaw``). The ROS side turns exactly those into
messages; a quantity a record lacks is marked missing there.

Users choose a stream by its name or by its command byte written as text
(``0xC2``), which is what readers of the protocol manual type.
"""

from collections.abc import Sequence
import math
import re
from typing import NamedTuple

from . import layouts as lay
from .data_rate import divider_for_rate, rate_of_divider
from .line_budget import (
    Budget, budget, bytes_per_second, line_bytes_per_second, max_shared_rate, shared_fits,
    usable_bytes_per_second,
)

MATRIX = 'matrix'
EULER = 'euler'


class Stream(NamedTuple):
    """One streamable record and what it carries."""

    name: str
    code: int
    record_type: type
    #: What it carries, in words (parameter table, README, logs).
    summary: str
    #: Record field of the acceleration (g), or None.
    accel: str | None
    #: Record field of the angular rate (rad/s), or None.
    angular_rate: str | None
    #: Record field of the magnetic field (Gauss), or None.
    mag: str | None
    #: How the record gives the attitude: MATRIX, EULER or None.
    orientation: str | None

    @property
    def label(self) -> str:
        """Return the command byte and the name, as logs show a stream."""
        return f'0x{self.code:02X} ({self.name})'


def _stream(name: str, code: int, summary: str) -> Stream:
    names = {field.name for field in lay.LAYOUTS[code].reply}
    attitude = MATRIX if MATRIX in names else EULER if {'roll', 'pitch', 'yaw'} <= names else None
    return Stream(name, code, lay.LAYOUTS[code].record_type, summary,
                  *(key if key in names else None for key in ('accel', 'angular_rate', 'mag')),
                  attitude)


#: Every stream the driver offers, the default first.
STREAMS: tuple[Stream, ...] = (
    _stream('full', lay.ACCEL_ANG_RATE_MAG_ORIENTATION,
            'acceleration, angular rate, magnetic field, orientation'),
    _stream('inertial_orientation', lay.ACCEL_ANG_RATE_ORIENTATION,
            'acceleration, angular rate, orientation (no magnetic field)'),
    _stream('inertial_mag', lay.ACCEL_ANG_RATE_MAG,
            'acceleration, angular rate, magnetic field (no orientation)'),
    _stream('inertial', lay.ACCEL_ANG_RATE,
            'acceleration and angular rate only: the fastest inertial stream'),
    _stream('euler', lay.EULER_ANGLES_ANG_RATE,
            'orientation (from Euler angles) and angular rate (no acceleration)'),
    _stream('stabilised', lay.STABILISED_ACCEL_ANG_RATE_MAG,
            'gyro-stabilised acceleration and magnetic field, angular rate '
            '(no orientation)'),
)
DEFAULT = STREAMS[0]
BY_NAME = {stream.name: stream for stream in STREAMS}
BY_CODE = {stream.code: stream for stream in STREAMS}

_CODE_TEXT = re.compile(r'(0x)?([0-9a-f]{2})')


def valid_text() -> str:
    """Return what ``parse`` accepts, in words."""
    names = ', '.join(repr(s.name) for s in STREAMS)
    codes = ', '.join(f'0x{s.code:02X}' for s in STREAMS)
    return f'one of {names}, or a command byte: {codes}'


def parse(text: str) -> Stream:
    """Return the stream named ``text`` (a name or a command byte such as 0xC2)."""
    key = text.strip().lower()
    if key in BY_NAME:
        return BY_NAME[key]
    match = _CODE_TEXT.fullmatch(key)
    if match is not None and int(match.group(2), 16) in BY_CODE:
        return BY_CODE[int(match.group(2), 16)]
    raise ValueError(f'unknown stream {text!r}: {valid_text()}')


def names_a_stream(text: str) -> bool:
    """Whether ``text`` is a stream's name or command byte, as :func:`parse` takes it."""
    try:
        parse(text)
    except ValueError:
        return False
    return True


def _hz(rate: float) -> str:
    return f'{rate:.1f}'.removesuffix('.0')


def _limit(b: Budget) -> str:
    # Rounded down: a data_rate of the shown value still maps to a divider that fits.
    return f'{math.floor(b.max_rate_hz)} Hz' if b.max_rate_hz else 'none'


def line_budget(stream: Stream, rate_hz: float, baud: int, wireless: bool) -> Budget:
    """Return the budget of ``stream`` at the rate the device runs for ``rate_hz``."""
    return budget(stream.code, rate_of_divider(divider_for_rate(rate_hz)), baud, wireless)


def describe(b: Budget) -> str:
    """Say what a stream uses of the line, in one line for logs and diagnostics."""
    return (f'0x{b.code:02X} at {_hz(b.rate_hz)} Hz: {b.packet_bytes} B packets, '
            f'{b.needed:,.0f} of {b.capacity:,.0f} bytes/s ({b.share:.0%} of the line)')


def advice(stream: Stream, b: Budget, knob: str = 'data_rate') -> str:
    """
    Say why a stream does not fit and what does, for a refusal or a warning.

    What does: a lower ``knob`` for the same stream, or smaller streams that
    fit the rate asked for (else the fastest ones there are).
    """
    others = [(other, line_budget(other, b.rate_hz, b.baud, b.wireless))
              for other in STREAMS if other.code != stream.code]
    faster = [(o, ob) for o, ob in others if (ob.max_rate_hz or 0) > (b.max_rate_hz or 0)]
    fitting = [(o, ob) for o, ob in faster if ob.fits]
    if not fitting and faster:
        best = max(ob.max_rate_hz for _, ob in faster)
        fitting = [(o, ob) for o, ob in faster if ob.max_rate_hz == best]
    text = (f'{stream.label} at {_hz(b.rate_hz)} Hz needs {b.needed:,.0f} bytes/s; '
            f'{b.baud} baud carries {b.capacity:,.0f} ({b.usable:,.0f} with the '
            f'{1 - b.usable / b.capacity:.0%} margin kept free): ')
    text += f'choose {knob} \u2264 {_limit(b)}' if b.max_rate_hz else 'no data rate fits'
    if fitting:
        text += ', or stream ' + ', '.join(f"'{o.name}' (\u2264 {_limit(ob)})"
                                           for o, ob in fitting)
    return text


def shared_line_fits(chosen: Sequence[tuple[Stream, float]], baud: int, wireless: bool) -> bool:
    """Tell whether several sensors' (stream, rate) fit one line together, margin kept."""
    return shared_fits([(stream.code, rate_of_divider(divider_for_rate(rate)))
                        for stream, rate in chosen], baud, wireless)


def shared_advice(chosen: Sequence[tuple[int, Stream, float]], baud: int, wireless: bool) -> str:
    """
    Say why several sensors' streams do not fit one line together, and what fits per sensor.

    ``chosen``: (address, stream, rate) of each sensor. What fits: the same
    streams at a lower common rate, or every sensor on one stream at the
    highest rate that fits for that many (fastest first).
    """
    n = len(chosen)
    parts = []
    total = 0.0
    for address, stream, asked in chosen:
        rate = rate_of_divider(divider_for_rate(asked))
        needed = bytes_per_second(stream.code, rate, wireless)
        total += needed
        parts.append(f'{address}: {stream.label} at {_hz(rate)} Hz, {needed:,.0f}')
    capacity, usable = line_bytes_per_second(baud), usable_bytes_per_second(baud)
    text = (f'{n} sensors need {total:,.0f} bytes/s together ({"; ".join(parts)}); {baud} baud '
            f'carries {capacity:,.0f} ({usable:,.0f} with the {1 - usable / capacity:.0%} '
            f'margin kept free): what fits per sensor: ')
    options = []
    same = max_shared_rate([stream.code for _, stream, _ in chosen], baud, wireless)
    if same and len({stream.code for _, stream, _ in chosen}) > 1:
        options.append(f'these streams at \u2264 {math.floor(same)} Hz each')
    each = sorted(((max_shared_rate([stream.code] * n, baud, wireless) or 0.0, stream)
                   for stream in STREAMS), key=lambda pair: -pair[0])
    options += [f"{n} x '{stream.name}' at \u2264 {math.floor(rate)} Hz"
                for rate, stream in each if rate]
    return text + (', or '.join(options) if options else 'nothing, even at 1 Hz')
