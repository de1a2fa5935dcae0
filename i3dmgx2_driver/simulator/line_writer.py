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
The last step of a frame: written to the pty in random chunks, and counted.

A real serial port hands a reader a packet in pieces; the simulator writes
each frame in a random number of chunks (``SimulatorConfig.chunks``), a
pause apart (``chunk_gap_s``), so that a host parser meets every split. What
a full line could not take is lost, as on a real line, and counted.
"""

import itertools
import random

from . import faults as flt
from .ground_truth import GroundTruth
from .pty_port import PtyPort


class LineWriter:
    """Writes frames to the port in random chunks; call with the simulator's lock held."""

    def __init__(self, port: PtyPort, record: GroundTruth, chunks: tuple[int, int],
                 gap_s: float, rng: random.Random) -> None:
        self._port = port
        self._record = record
        self._chunks = chunks
        self._gap_s = gap_s
        self._rng = rng

    def write(self, data: bytes) -> tuple[str | None, float | None, float | None]:
        """Write one frame in chunks; return (fault or None, time of its first and last write)."""
        written, first_write, write_time = self._port.write_chunks(self._split(data),
                                                                   self._gap_s)
        if write_time is None:
            return flt.FAULT_UNPLUGGED, None, None
        self._record.written(len(data), written)
        if written < len(data):
            return flt.FAULT_OVERFLOW, None, None
        return None, first_write, write_time

    def _split(self, data: bytes) -> list[bytes]:
        low, high = self._chunks
        count = min(self._rng.randint(low, high), len(data))
        if count <= 1:
            return [data]
        cuts = sorted(self._rng.sample(range(1, len(data)), count - 1))
        return [data[a:b] for a, b in itertools.pairwise([0, *cuts, len(data)])]
