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
What a hostile base station sends instead of the real bytes, attack mode by attack mode.

Bit flips, truncations, lengths that lie, checksums made to match, bursts,
answer bytes where an answer is awaited, other addresses, wrong echo bytes,
replies never asked for, packets stopped mid-way. Kept apart from the
forwarding (``hostile.py``) so that a new way to lie is one method here;
every draw comes from the station's own seeded generator, so that a seed
replays the same attack.
"""

import random

from i3dmgx2_driver.codec.checksum import checksum16
from i3dmgx2_driver.codec.framing import DATA_TRAILER_SIZE, HEADER_SIZE

#: The bytes a dialogue waits for alone: ACK/start of packet, NACK, ping answer, data flags.
ANSWER_BYTES = bytes((0xAA, 0x21, 0x02, 0x07))


def reseal(packet: bytearray) -> bytes:
    """Recompute a data packet's checksum (over flags .. record), as a base station does."""
    end = len(packet) - DATA_TRAILER_SIZE
    packet[-2:] = checksum16(packet[1:end]).to_bytes(2, 'big')
    return bytes(packet)


class PacketMutator:
    """
    Turn a real piece (a whole data packet, or one other byte) into what an attack sends.

    Holds what ``stop_mid_packet`` keeps back (let go when the attack ends)
    and the last reply by echo byte (what ``unsolicited`` replays).
    """

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        #: Bytes held back by ``stop_mid_packet``, in order.
        self.held: list[bytes] = []
        #: The last replies seen (by echo byte), to replay unasked.
        self.replies: dict[int, bytes] = {}
        self._any_piece = {'noise': self._noise, 'stop_mid_packet': self._stop_mid_packet,
                           'answer_bytes': self._answer_bytes}
        self._packet_only = {'bitflip': self._bitflip, 'truncate': self._truncate,
                             'lying_length': self._lying_length,
                             'chance_checksum': self._chance_checksum, 'burst': self._burst,
                             'foreign': self._foreign, 'wrong_echo': self._wrong_echo,
                             'unsolicited': self._unsolicited}

    def remember_reply(self, packet: bytes) -> None:
        """Keep a real reply of the station's address, by its echo byte."""
        self.replies[packet[HEADER_SIZE]] = packet

    def release(self) -> list[bytes]:
        """Return (and forget) what was held back."""
        held, self.held = self.held, []
        return held

    def mutate(self, piece: bytes, is_packet: bool, mode: str) -> bytes:
        """Return what the hostile station sends instead of ``piece`` in attack ``mode``."""
        any_piece = self._any_piece.get(mode)
        if any_piece is not None:
            return any_piece(piece, is_packet)
        if not is_packet:
            rng = self.rng
            return piece if rng.random() < 0.5 else bytes((rng.choice(ANSWER_BYTES),))
        packet_only = self._packet_only.get(mode)
        return packet_only(bytearray(piece)) if packet_only is not None else piece

    # -- any piece ---------------------------------------------------------------------------

    def _noise(self, piece: bytes, is_packet: bool) -> bytes:
        return b''  # nothing real gets through, only the station's noise between reads

    def _stop_mid_packet(self, piece: bytes, is_packet: bool) -> bytes:
        if self.held or not is_packet:
            self.held.append(piece)
            return b''
        cut = self.rng.randint(1, len(piece) - 1)
        self.held.append(piece[cut:])
        return piece[:cut]

    def _answer_bytes(self, piece: bytes, is_packet: bool) -> bytes:
        rng = self.rng
        out = bytearray()
        for byte in piece:
            if rng.random() < 0.1:
                out += rng.choice(ANSWER_BYTES).to_bytes(1, 'big')
            out.append(byte)
        return bytes(out) + bytes(rng.choices(ANSWER_BYTES, k=rng.randint(0, 3)))

    # -- whole data packets ------------------------------------------------------------------

    def _bitflip(self, packet: bytearray) -> bytes:
        rng = self.rng
        for _ in range(rng.randint(1, 3)):
            i = rng.randrange(len(packet))
            packet[i] ^= 1 << rng.randrange(8)
        return bytes(packet)

    def _truncate(self, packet: bytearray) -> bytes:
        return bytes(packet[:self.rng.randint(1, len(packet) - 1)])

    def _lying_length(self, packet: bytearray) -> bytes:
        rng = self.rng
        packet[5] = rng.choice([0, 1, 2, 255, rng.randrange(256)])
        return reseal(packet) if rng.random() < 0.5 else bytes(packet)

    def _chance_checksum(self, packet: bytearray) -> bytes:
        rng = self.rng
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(HEADER_SIZE + 1, len(packet) - DATA_TRAILER_SIZE)
            packet[i] = rng.randrange(256)
        return reseal(packet)

    def _burst(self, packet: bytearray) -> bytes:
        rng = self.rng
        extra = bytearray()
        for _ in range(rng.randint(2, 10)):
            other = bytearray(packet)
            other[3:5] = rng.randrange(1, 65535).to_bytes(2, 'big')
            extra += reseal(other)
        return bytes(packet) + bytes(extra) + rng.randbytes(rng.randint(0, 32))

    def _foreign(self, packet: bytearray) -> bytes:
        packet[3:5] = self.rng.randrange(1, 65535).to_bytes(2, 'big')
        return reseal(packet)

    def _wrong_echo(self, packet: bytearray) -> bytes:
        rng = self.rng
        echoes = (0xC2, 0xC8, 0xCC, 0xCB, 0xD1, 0xEA, 0xE5, 0xC4, rng.randrange(256))
        packet[HEADER_SIZE] = rng.choice(echoes)
        return reseal(packet)

    def _unsolicited(self, packet: bytearray) -> bytes:
        replies = list(self.replies.values())
        extra = self.rng.choice(replies) if replies else b''
        return bytes(packet) + extra
