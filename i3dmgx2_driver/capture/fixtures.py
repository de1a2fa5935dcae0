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
The real-records fixture: a real sensor's records, as the reads a host would have made.

The fixture is a text file of hex records, grouped in the captures it was
recorded as (``## set NAME: description``). Placed on one time line by
their device timer and wrapped as data packets, they let ``replay`` feed
the driver, and ``plot`` draw, what a real sensor sent, with no sensor.
"""

from collections.abc import Iterable, Iterator
import random
from typing import NamedTuple

from .file_format import Chunk, PathLike
from ..codec.commands import decode_record
from ..codec.framing import encode_data_packet
from ..codec.records import TICKS_PER_SECOND
from ..codec.timer import TIMER_MODULUS

#: Node address given to fixture records (the fixture did not record one).
FIXTURE_ADDRESS = 95
#: Where fixture-made captures start (2016-05-01 00:00 UTC, when it was recorded).
FIXTURE_EPOCH = 1462060800.0
#: Silence put between the fixture's captures, whose timers do not continue
#: (the sensor was re-posed by hand, and possibly power-cycled, in between).
FIXTURE_GAP = 30.0


class FixtureSet(NamedTuple):
    """One of the fixture's captures: a pose name and its records, as bytes."""

    name: str
    description: str
    records: list[bytes]


def load_fixture(path: PathLike) -> list[FixtureSet]:
    """
    Read the real-records fixture: ``## set NAME: description`` lines, hex records.

    Every record is decoded once here, so that a damaged fixture fails loudly
    rather than turning into a capture the parser silently skips.
    """
    sets = [FixtureSet('records', '', [])]  # for records before the first set line
    with open(path, encoding='utf-8') as f:
        for number, raw in enumerate(f, 1):
            line = raw.strip()
            if line.startswith('## set'):
                name, _, description = line[len('## set'):].partition(':')
                sets.append(FixtureSet(name.strip(), description.strip(), []))
                continue
            if not line or line.startswith('#'):
                continue
            try:
                record = bytes.fromhex(line)
                decode_record(record)
            except ValueError as exc:
                raise ValueError(f'{path}:{number}: not a record: {exc}') from None
            sets[-1].records.append(record)
    return [s for s in sets if s.records]


def record_timer(record: bytes) -> int:
    """Return the timer of a record: its last four bytes, big-endian."""
    return int.from_bytes(record[-4:], 'big')


def timeline(sets: Iterable[FixtureSet],
             gap: float = FIXTURE_GAP) -> list[tuple[float, int, bytes]]:
    """
    Place the fixture's records on one time line: ``(seconds, set index, record)``.

    Within a set the timer never restarts, so each step is taken forward
    modulo 2^32: that unwraps the rollover, and it also keeps the one pause in
    set1 that is longer than half the timer's period (168.5 s), which a
    general-purpose unwrapper must take for a reset. Between sets the timer
    jumps arbitrarily, so ``gap`` seconds of silence stand in for the time the
    sensor was being re-posed. The line starts at 0.
    """
    out: list[tuple[float, int, bytes]] = []
    offset = 0.0
    for index, fixture_set in enumerate(sets):
        ticks, last = 0, record_timer(fixture_set.records[0])
        for record in fixture_set.records:
            raw = record_timer(record)
            ticks += (raw - last) % TIMER_MODULUS
            last = raw
            out.append((offset + ticks / TICKS_PER_SECOND, index, record))
        if out:
            offset = out[-1][0] + gap
    return out


def fixture_chunks(path: PathLike, address: int = FIXTURE_ADDRESS,
                   start_time: float = FIXTURE_EPOCH, gap: float = FIXTURE_GAP,
                   seed: int = 2016) -> Iterator[Chunk]:
    """
    Turn the fixture into the chunks a host would have read from the base station.

    One data packet per read, as at the fixture's ~3 Hz polling, received at
    ``start_time`` plus the record's place on :func:`timeline`. LQI and RSSI
    were not recorded: they are drawn, reproducibly from ``seed``, from a
    good, steady link (the sensor sat still near the base station).
    """
    rng = random.Random(seed)
    for seconds, _, record in timeline(load_fixture(path), gap):
        lqi = min(255, max(0, round(rng.gauss(228, 6))))
        rssi = min(255, max(0, round(rng.gauss(190, 4))))
        yield start_time + seconds, encode_data_packet(address, record, lqi, rssi)
