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
The wireless base station: the host end of a wireless sensor's line.

It reads what the host writes as command packets and unframed pings. It ACKs
every well-formed packet and sends it over the air, whoever it is for (the
radio may lose it: ``command_loss_probability``); it NACKs a malformed one,
or a good one when busy (``nack_probability``); it answers a ping for the
sensor in one byte. Raw commands are not packets: it skips them as garbage,
unanswered. The other way, it wraps each record the sensor sends in a data
packet with the link's LQI and RSSI.
"""

import collections.abc
import random
from typing import Any

from i3dmgx2_driver.codec import framing, layouts as lay
from i3dmgx2_driver.codec.parser import CommandStreamParser, HostEvent, RawCommand, RejectedPacket

from . import faults as flt
from .faults import FaultState
from .ground_truth import GroundTruth, HostCommand
from .pty_port import PtyPort
from .sensor import decoded, Reply, SimulatedSensor

_PING_FAILED = bytes((framing.NACK,))


class BaseStation:
    """
    A base station between the host and the wireless sensors; call with the lock held.

    ``units`` maps each sensor's address to its parts (``sensor``, ``faults``
    in effect for it, ``deliver``): a command packet or ping goes to the
    sensor it names, if that one is on the channel. ``faults`` is the base
    station's own (busy NACKs).
    """

    #: Bytes that "safe" garbage avoids on this line (see faults.SIGNIFICANT_BYTES).
    significant_bytes = flt.SIGNIFICANT_BYTES

    def __init__(self, units: collections.abc.Mapping[int, Any], record: GroundTruth,
                 port: PtyPort, faults: FaultState, rng: random.Random) -> None:
        self._units, self._record, self._port = units, record, port
        self._faults, self._rng = faults, rng

    #: Returns a reader of the host's bytes: command packets and pings.
    new_parser = CommandStreamParser

    def on_event(self, event: HostEvent, now: float) -> None:
        """Act on one thing the host sent."""
        if isinstance(event, framing.CommandPacket):
            self._on_command_packet(event, now)
        elif isinstance(event, RejectedPacket):
            self._record.log(HostCommand(now, 'rejected', None, None, b'',
                                         f'rejected: {event.reason}'), nacks=1)
            self._write(bytes((framing.NACK,)))
        elif isinstance(event, RawCommand):
            self._on_raw_command(event.command, now)

    def _on_raw_command(self, raw: bytes, now: float) -> None:
        """Answer a ping."""
        command = decoded(raw)
        if command is None or command.code != lay.PING:
            return
        address = command.args[0]
        unit = self._units.get(address)
        answer = (_PING_FAILED if unit is None or unit.faults.silent(now)
                  else unit.sensor.ping_reply(address))
        outcome = 'ping ok' if answer != _PING_FAILED else 'ping failed'
        self._record.log(HostCommand(now, 'ping', address, command, raw, outcome), pings=1)
        self._write(answer)

    def _on_command_packet(self, packet: framing.CommandPacket, now: float) -> None:
        """ACK a command packet and pass it on over the radio."""
        # The base station ACKs every well-formed packet: it only checks the
        # framing and sends it over the air, whoever it is for. The ACK goes out
        # first; the sensor's answer is queued behind it. A busy base station
        # (fault) NACKs a good packet instead and sends nothing.
        faults = self._faults.config
        if self._rng.random() < faults.nack_probability:
            self._write(bytes((framing.NACK,)))
            self._record.log(HostCommand(now, 'rejected', packet.address, None, packet.command,
                                         'rejected: busy'), nacks=1)
            return
        self._write(bytes((framing.ACK,)))
        command = decoded(packet.command)
        unit = self._units.get(packet.address)
        if unit is None:
            outcome, counter = 'other_address', 'commands_other_address'
        elif unit.faults.silent(now):
            outcome, counter = 'stalled', 'commands_lost'
        elif self._rng.random() < faults.command_loss_probability:
            outcome, counter = 'lost', 'commands_lost'
        else:
            outcome = unit.deliver(command, packet.command, now)
            counter = 'commands_received' if outcome == 'delivered' else 'commands_ignored'
        self._record.log(
            HostCommand(now, 'packet', packet.address, command, packet.command, outcome),
            acks=1, **{counter: 1})

    def _write(self, data: bytes) -> None:
        """Write a base-station byte (ACK, NACK, ping answer) between packets."""
        written = self._port.write(data)
        if written is not None:
            self._record.written(len(data), written)

    # -- the sensor's records, to the host --------------------------------------------------

    @staticmethod
    def frame(reply: Reply, address: int, link: SimulatedSensor) -> bytes:
        """Return the data packet of one record, with ``link``'s LQI and RSSI."""
        lqi, rssi = link.link_quality()
        return framing.encode_data_packet(address, reply.data, lqi, rssi)

    @staticmethod
    def checksum_positions(size: int) -> list[int]:
        """Where a bit flip makes a packet of ``size`` bytes fail only its checksum."""
        # The record's data (not its echo byte, which sets the expected length)
        # and the checksum itself; not LQI and RSSI, which the sum leaves out.
        return [*range(framing.HEADER_SIZE + 1, size - 4), size - 2, size - 1]
