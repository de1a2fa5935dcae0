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
What can go wrong between a 3DM-GX2, its radio, the base station and the host.

Each fault is off by default and switched on by a probability (per packet or
per command) or a flag, so that a test turns on exactly the trouble it is
about and the ground truth can say which packet suffered which fault. The
faults mirror what the thesis and the manual report from the field: a noisy
line, a lossy radio in both directions, a sensor that was left streaming, and
the quirks of the firmware when it is asked to stream too early.
"""

import dataclasses

from i3dmgx2_driver.codec import layouts as lay

#: Bytes that a parser of the host side takes for an answer of the base
#: station (ACK / start of packet, NACK, ping OK), and the data flags, which
#: right after an ACK look like a packet header; "safe" garbage avoids them.
SIGNIFICANT_BYTES = frozenset((0xAA, 0x21, 0x02, 0x07))

#: The same for a wired line, where the host parser takes any echo byte for the
#: start of a record (and 0x02/0x21 for a ping answer when it expects one).
WIRED_SIGNIFICANT_BYTES = frozenset(lay.RECORD_SIZES) | frozenset((0x02, 0x21))

#: Faults of the radio and the base station: a wired sensor has neither, and no
#: length byte to corrupt.
WIRELESS_ONLY = ('command_loss_probability', 'nack_probability', 'foreign_probability',
                 'corrupt_length_probability')

#: Fault labels of SentRecord.fault, one per way a data packet can fail.
FAULT_CHECKSUM = 'checksum'
FAULT_LENGTH = 'length'
FAULT_FOREIGN = 'foreign'
FAULT_DROPPED = 'dropped'
FAULT_STALL = 'stall'
FAULT_UNPLUGGED = 'unplugged'
FAULT_OVERFLOW = 'overflow'
FAULT_LINE_RATE = 'line_rate'


@dataclasses.dataclass
class FaultConfig:
    """
    The faults to inject; probabilities are per data packet unless noted.

    Corruptions are exclusive per packet and checked in the order listed:
    a dropped packet is not also corrupted. Scheduled faults (``stall_at``,
    ``unplug_at``, ``power_cycle_at``) count seconds from when the configuration takes effect:
    ``PtySimulator.start()`` or ``set_faults()``.
    """

    #: Chance of a burst of 1..``garbage_max_bytes`` random bytes before a packet.
    garbage_probability: float = 0.0
    #: Longest garbage burst.
    garbage_max_bytes: int = 8
    #: Garbage never contains 0xAA, 0x21, 0x02 or 0x07, which a host parser would
    #: take for an ACK or the start of a packet, a NACK, a ping answer, or (after
    #: an ACK) a packet header: then the parser skips exactly the garbage bytes.
    #: Set False for the nastiest line, where spurious ACK/NACK events and lost
    #: ACKs are to be expected.
    garbage_safe: bool = True
    #: Chance that a bit of a packet's record or checksum flips (checksum mismatch).
    corrupt_checksum_probability: float = 0.0
    #: Chance that a packet's length byte is wrong.
    corrupt_length_probability: float = 0.0
    #: Chance of a well-formed packet from another sensor before a packet.
    foreign_probability: float = 0.0
    #: Address of that other sensor (None: ours + 1, wrapping inside 1..65534).
    foreign_address: int | None = None
    #: Chance that a data packet is lost on the radio (never written).
    drop_probability: float = 0.0
    #: Chance, per command, that the base station ACKs but the sensor never hears it.
    command_loss_probability: float = 0.0
    #: Chance, per command packet, that the base station rejects a good packet
    #: with a NACK (busy radio) and sends nothing over the air.
    nack_probability: float = 0.0
    #: The sensor ignores the first request to stream (0xC4 with a command).
    ignore_first_continuous: bool = False
    #: Thesis quirk: a request to stream is ignored unless a polled request came
    #: first since the host opened the port (or flushed its input).
    needs_polled_first: bool = False
    #: The sensor streams 0xCC from power-up (EEPROM auto-start), before any command.
    already_streaming: bool = False
    #: Extra delay (0..N ms, uniform) between a sample's time and the write of its packet.
    jitter_ms: float = 0.0
    #: Radio silence: no packet in either direction, starting this many seconds in.
    stall_at: float | None = None
    #: Length of that stall (s).
    stall_seconds: float = 2.0
    #: Unplug the base station (the port disappears) this many seconds in.
    unplug_at: float | None = None
    #: How long it stays unplugged (s).
    unplug_seconds: float = 2.0
    #: The sensor loses power this many seconds in (a brown-out, a battery swap).
    power_cycle_at: float | None = None
    #: How long it stays dark (s): nothing is sampled, sent or answered.
    power_off_seconds: float = 1.0
    #: Its timer when power returns (None: the sensor's ``timer_start``).
    power_up_timer: int | None = None

    def __post_init__(self) -> None:
        """Reject settings that cannot mean anything, naming the field."""
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if item.name.endswith('_probability') and not 0.0 <= value <= 1.0:
                raise ValueError(f'{item.name} is a probability in 0..1, got {value!r}')
        if self.garbage_max_bytes < 1:
            raise ValueError('garbage_max_bytes must be at least 1')
        for name in ('jitter_ms', 'stall_seconds', 'unplug_seconds', 'power_off_seconds'):
            if getattr(self, name) < 0:
                raise ValueError(f'{name} must not be negative')

    def check_wired(self) -> None:
        """Reject the faults a wired sensor cannot have, naming the field."""
        for name in WIRELESS_ONLY:
            if getattr(self, name):
                raise ValueError(f'{name} is a fault of the radio or the base station; '
                                 f'a wired sensor has neither (got {getattr(self, name)!r})')


class FaultState:
    """
    The faults in effect now, and the window of silence.

    A stall silences everything: wireless, the radio; wired, the sensor
    hangs. Not locked itself: the simulator's lock guards it.
    """

    def __init__(self, config: FaultConfig) -> None:
        #: The fault configuration in effect.
        self.config = config
        self._stall_start = self._stall_end = 0.0

    def stall(self, start: float, seconds: float) -> None:
        """Be silent from ``start`` for ``seconds``."""
        self._stall_start, self._stall_end = start, start + seconds

    def silent(self, t: float) -> bool:
        """Whether time ``t`` falls in the silence."""
        return self._stall_start <= t < self._stall_end
