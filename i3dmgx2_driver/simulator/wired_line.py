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
A wired sensor's own serial line: the host end of a wired 3DM-GX2.

No base station: the sensor reads the host's bytes as a plain stream and
picks out the command bytes it knows (every command of the table but the
wireless ping) with their confirmation and argument bytes; every other byte
is ignored (counted as ``host_bytes_ignored``). It sends no ACK or NACK and
answers no ping. Its records go out wired: echo, data, uint16 checksum.

So a host that sends packets to a wired sensor gets no ACK, and wired
answers to the commands that happen to sit whole inside its packets (a
packet for 0xC2 holds the byte 0xC2; a header or checksum byte that happens
to be a command byte is taken for one too). docs/protocol.md §3 says wired sensors
accept packets as well; this model is the stricter firmware, so that a driver
set up for the wrong framing shows it at once.
"""

import collections.abc
import functools
from typing import Any

from i3dmgx2_driver.codec import framing
from i3dmgx2_driver.codec.parser import CommandStreamParser, HostEvent, RawCommand

from . import faults as flt
from .ground_truth import GroundTruth, HostCommand
from .sensor import decoded, Reply, SimulatedSensor, WIRED_COMMANDS


class WiredLine:
    """
    The serial line of one wired sensor; call with the lock held.

    ``units`` holds that sensor's parts (``sensor_unit``) by its address.
    """

    #: Bytes that "safe" garbage avoids on this line (any echo byte, ping answers).
    significant_bytes = flt.WIRED_SIGNIFICANT_BYTES

    def __init__(self, units: collections.abc.Mapping[int, Any], record: GroundTruth) -> None:
        self._units = units
        self._record = record

    #: Returns the sensor's reader of the host's bytes: bare commands it knows.
    new_parser = functools.partial(CommandStreamParser, wireless=False, codes=WIRED_COMMANDS)

    def on_event(self, event: HostEvent, now: float) -> None:
        """Act on a command the sensor read from the line; there is nothing to ACK."""
        if not isinstance(event, RawCommand):  # pragma: no cover - a wired reader has no other
            return
        raw = event.command
        command = decoded(raw)
        unit = next(iter(self._units.values()))  # the one sensor on the line
        if unit.faults.silent(now):
            outcome, counter = 'stalled', 'commands_lost'
        else:
            outcome = unit.deliver(command, raw, now)
            counter = 'commands_received' if outcome == 'delivered' else 'commands_ignored'
        self._record.log(HostCommand(now, 'wired', None, command, raw, outcome), **{counter: 1})

    # -- the sensor's records, to the host --------------------------------------------------

    @staticmethod
    def frame(reply: Reply, address: int, link: SimulatedSensor) -> bytes:
        """Return the wired record: echo, data, checksum (no address, no LQI/RSSI)."""
        return framing.encode_wired_record(reply.data)

    @staticmethod
    def checksum_positions(size: int) -> list[int]:
        """Where a bit flip makes a record of ``size`` bytes fail only its checksum."""
        # All but the echo byte, which tells a wired parser the record's size.
        return list(range(1, size))
