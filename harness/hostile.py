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
A hostile base station: a pseudo-terminal between the node and the simulator.

The node opens this station's port; the station forwards the host's bytes to
the simulated base station and its answers back, and, when armed, turns
hostile in one phase of the dialogue for a while: it mutates the real packets
(bit flips, truncations, lengths that lie, checksums made to match), bursts
at the line rate, answers bytes (0xAA, 0x21, 0x02, 0x07) where an ACK, NACK
or ping answer is awaited, replies from other addresses or with the wrong
echo byte, replies to commands never sent, stops mid-packet for seconds, or
sends nothing but noise. The phase is read from what the host sends (a
stop is *quiet*, 0xEA/0xE9 *identity*, 0xE5/0xE4 *data rate*, 0xC4
*continuous*, then *streaming* once a record was forwarded). Every draw
comes from the station's own seeded generator, so that a seed replays the
same attacks; a new way to lie is one method of :class:`PacketMutator`.

What may be published is decided by the bytes the node was given, not by
what the station meant (:class:`PublishOracle`): every data packet a fresh
codec parser finds in them (reset whenever the node opens the port) is
allowed; every real packet of the node's stream forwarded whole while the
station behaved is a packet that must be published. Not other records from
its address: those are the replies to its own polled requests (the
dialogue's 0xC2 polls, its identity), which the node takes as replies and
never publishes. Not a packet the pty took only in part either (its buffer
full after a held-back stretch is let go at once): the station lost that one
itself. Used by ``benchmarks/fuzz_node.py`` and the
stateful dialogue test.
"""

import os
import random
import select
import threading
import time
import tty
from typing import NamedTuple

from harness.campaign import imu_values
from harness.decoders import decode_data_packet
from i3dmgx2_driver.codec import streams
from i3dmgx2_driver.codec.checksum import checksum16
from i3dmgx2_driver.codec.framing import (
    CommandPacket, DATA_FLAGS, DATA_TRAILER_SIZE, DataPacket, HEADER_SIZE, SOP)
from i3dmgx2_driver.codec.parser import CommandStreamParser, RawCommand, SensorStreamParser
from i3dmgx2_driver.simulator.pty_port import PtyPort, TIOCPKT_DATA, TIOCPKT_FLUSHREAD

#: The phases of the dialogue the station can attack in.
PHASES = ('quiet', 'identity', 'data_rate', 'continuous', 'streaming', 'shutdown')
#: What it can do, once hostile.
MODES = ('bitflip', 'truncate', 'lying_length', 'chance_checksum', 'burst', 'answer_bytes',
         'foreign', 'wrong_echo', 'unsolicited', 'stop_mid_packet', 'noise')
#: The modes that send the real packet whole (held back, or with bytes around it): the
#: node may publish it.
KEEPS_PACKET = frozenset(('stop_mid_packet', 'unsolicited', 'burst'))
#: Phase of each command byte the host sends (others leave the phase as it is).
_PHASE_OF = {0xFA: 'quiet', 0x02: 'quiet', 0xEA: 'identity', 0xE9: 'identity',
             0xE5: 'data_rate', 0xE4: 'data_rate', 0xC4: 'continuous'}


class Attack(NamedTuple):
    """One armed attack: in which phase, what, for how long (s)."""

    phase: str
    mode: str
    seconds: float


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

    def remember_reply(self, packet: bytes) -> None:
        """Keep a real reply of the station's address, by its echo byte."""
        self.replies[packet[HEADER_SIZE]] = packet

    def release(self) -> list[bytes]:
        """Return (and forget) what was held back."""
        held, self.held = self.held, []
        return held

    def mutate(self, piece: bytes, is_packet: bool, mode: str) -> bytes:
        """
        Return what the hostile station sends instead of ``piece`` in attack ``mode``.

        A mode of :data:`MODES` is the method of its name; an unknown one passes the piece.
        """
        if mode == 'noise':
            return b''  # nothing real gets through, only the station's noise between reads
        if mode in ('stop_mid_packet', 'answer_bytes'):
            return getattr(self, '_' + mode)(piece, is_packet)
        if not is_packet:
            rng = self.rng
            return piece if rng.random() < 0.5 else bytes((rng.choice(ANSWER_BYTES),))
        packet_only = getattr(self, '_' + mode, None) if mode in MODES else None
        return packet_only(bytearray(piece)) if packet_only is not None else piece

    # -- any piece ---------------------------------------------------------------------------

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


class PublishOracle:
    """
    The keys (a record's values) allowed, owed and attacked, as the station forwards.

    Kept apart from the forwarding so that what counts as a finding is read
    in one place.
    """

    def __init__(self, address: int, stream: int) -> None:
        self.address = address
        #: The command byte of the record the node streams and publishes.
        self.stream = stream
        #: Finds the packets in what the node is given; afresh whenever the node (re)opens the
        #: port, as the node's own parser; told of its pings (their answer starts no packet).
        self.reference = SensorStreamParser(address=address)
        #: Keys a fresh parser found in the bytes the node was given: allowed to be published.
        self.allowed: set[bytes] = set()
        #: (time, key) of real records of the node's stream from our address, forwarded
        #: whole while behaving: each must be published.
        self.intact: list[tuple[float, bytes]] = []
        #: Keys of real packets of ours sent whole (now, delayed or surrounded).
        self.intact_keys: set[bytes] = set()
        #: Keys of real packets from our address that were attacked (never sent intact).
        self.attacked_keys: dict[bytes, str] = {}

    def port_opened(self) -> None:
        """Start the reference parser afresh: the node (re)opened the port, so did its parser."""
        self.reference = SensorStreamParser(address=self.address)

    def given(self, data: bytes) -> None:
        """Note what the node was given: every record of our address in it is allowed."""
        for event in self.reference.feed(data):
            if isinstance(event, DataPacket) and event.address == self.address:
                values = imu_values(event.record)
                if values is not None:
                    self.allowed.add(values[0])

    def attacked(self, key: bytes, mode: str) -> None:
        """Note a real packet of ours that attack ``mode`` mutated: it never went out intact."""
        self.attacked_keys[key] = mode

    def owed(self, packet: bytes, key: bytes, written: int, now: float) -> None:
        """
        Owe a real packet of ours forwarded while behaving; ``written``: the bytes the pty took.

        Only a record of the stream is a sample to the node (a polled reply is
        not), and only one the pty took whole reached it.
        """
        if packet[HEADER_SIZE] == self.stream and written == len(packet):
            self.intact.append((now, key))


class Split:
    """Cut the simulator's byte stream into whole data packets and single other bytes."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        """Return the complete pieces: data packets whole, anything else byte by byte."""
        buf = self._buf
        buf += data
        out = []
        i = 0
        n = len(buf)
        while i < n:
            if buf[i] == SOP and i + 1 < n and buf[i + 1] == DATA_FLAGS:
                if i + 6 > n:
                    break
                size = HEADER_SIZE + buf[i + 5] - 1 + DATA_TRAILER_SIZE
                if i + size > n:
                    break
                out.append(bytes(buf[i:i + size]))
                i += size
            elif buf[i] == SOP and i + 1 == n:
                break  # an ACK, or the start of a packet: wait for the next byte
            else:
                out.append(bytes(buf[i:i + 1]))
                i += 1
        del buf[:i]
        return out


class HostileStation(threading.Thread):
    """
    The station: forwards, watches the phase, attacks when armed; keeps the oracle.

    ``stream`` is the command byte of the record the node streams and
    publishes (its ``stream`` parameter): only those records must be published.
    """

    def __init__(self, upstream: str, address: int, seed: int,
                 stream: int = streams.DEFAULT.code) -> None:
        super().__init__(name='hostile-station', daemon=True)
        self.address = address
        self.rng = random.Random(seed)
        self.port = PtyPort()
        self.path = self.port.create()
        self.port.plug_in()
        self._upstream_path = upstream
        self._up = self._open_upstream()
        self._host = CommandStreamParser(wireless=True)
        self._split = Split()
        #: What may and what must be published.
        self.oracle = PublishOracle(address, stream)
        #: The attacks' bytes; the same generator as the noise, so that a seed replays a run.
        self._mutator = PacketMutator(self.rng)
        self._lock = threading.Lock()
        self._halt = threading.Event()
        self.phase = 'quiet'
        self.armed: Attack | None = None
        self.hostile_until = 0.0
        self.attack: Attack | None = None
        self.attacks: list[Attack] = []
        self.packets_in = 0
        self.packets_mutated = 0
        self.bytes_out = 0
        #: Recent bytes given to the node (time, bytes), for a finding's evidence.
        self.recent: list[tuple[float, bytes]] = []

    def _open_upstream(self) -> int | None:
        try:
            fd = os.open(self._upstream_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return None
        tty.setraw(fd)
        return fd

    # -- control ---------------------------------------------------------------------------

    def arm(self, attack: Attack) -> None:
        """Turn hostile the next time the dialogue is in ``attack.phase``."""
        with self._lock:
            self.armed = attack
            if attack.phase in (self.phase, 'shutdown'):
                self._start(attack)

    def _start(self, attack: Attack) -> None:
        self.attack = attack
        self.armed = None
        self.hostile_until = time.time() + attack.seconds
        self.attacks.append(attack)

    @property
    def hostile(self) -> bool:
        """Whether an attack is under way."""
        return self.attack is not None and time.time() < self.hostile_until

    def unplug(self, seconds: float) -> None:
        """Pull the node's port out for ``seconds`` (the node reconnects)."""
        self.port.pull_out()
        time.sleep(seconds)
        self.port.plug_in()

    def stop(self) -> None:
        """Stop forwarding; close both ends."""
        self._halt.set()
        self.join(5.0)
        self.port.pull_out()
        self.port.remove()
        if self._up is not None:
            os.close(self._up)

    # -- the loop --------------------------------------------------------------------------

    def run(self) -> None:
        """Forward both ways until stopped, attacking when due."""
        while not self._halt.is_set():
            master = self.port.master
            fds = [fd for fd in (master, self._up) if fd is not None]
            if self._up is None:
                self._up = self._open_upstream()
            try:
                ready, _, _ = select.select(fds, [], [], 0.02)
            except (OSError, ValueError):
                time.sleep(0.01)
                continue
            now = time.time()
            if master is not None and master in ready:
                self._from_host(master)
            if self._up is not None and self._up in ready:
                try:
                    data = os.read(self._up, 4096)
                except OSError:
                    data = b''
                for piece in self._split.feed(data):
                    self._piece(piece, now)
            self._tick(now)

    def _from_host(self, master: int) -> None:
        try:
            data = os.read(master, 4096)
        except OSError:
            return
        if not data:
            return
        if data[0] != TIOCPKT_DATA:
            if data[0] & TIOCPKT_FLUSHREAD:
                # The node (re)opened the port: its parser starts afresh, so does ours.
                self.oracle.port_opened()
            return
        payload = data[1:]
        for event in self._host.feed(payload):
            code = None
            if isinstance(event, (CommandPacket, RawCommand)) and event.command:
                code = event.command[0]
            if code == 0x02:
                self.oracle.reference.expect_ping()
            phase = _PHASE_OF.get(code)
            if phase is not None:
                self._enter(phase)
        if self._up is not None:
            try:
                os.write(self._up, payload)
            except OSError:
                pass

    def _enter(self, phase: str) -> None:
        with self._lock:
            self.phase = phase
            if self.armed is not None and self.armed.phase == phase:
                self._start(self.armed)

    def _tick(self, now: float) -> None:
        """Between reads: noise while that attack lasts, the held bytes once it ends."""
        attack = self.attack
        if attack is None:
            return
        if now >= self.hostile_until:
            self.attack = None
            for piece in self._mutator.release():
                self._give(piece, now)
            return
        if attack.mode == 'noise':
            self._give(self.rng.randbytes(self.rng.randint(1, 48)), now)

    def _piece(self, piece: bytes, now: float) -> None:
        is_packet = len(piece) > 1
        mine = None  # the key of a real record from our address
        if is_packet:
            self.packets_in += 1
            ours = (piece[3] << 8) | piece[4] == self.address
            try:
                values = imu_values(decode_data_packet(piece).record)
                if ours:
                    self._mutator.remember_reply(piece)
            except Exception:  # noqa: B902 - the simulator's own faults: a damaged packet
                values = None
            mine = values[0] if ours and values is not None else None
            if mine is not None and self.phase == 'continuous':
                self._enter('streaming')
        if not self.hostile:
            if mine is not None:
                self.oracle.intact_keys.add(mine)
            written = self._give(piece, now)
            if mine is not None:
                self.oracle.owed(piece, mine, written, now)
            return
        if mine is not None and self.attack.mode in KEEPS_PACKET:
            self.oracle.intact_keys.add(mine)  # delayed or surrounded, but sent whole
        elif mine is not None:
            self.oracle.attacked(mine, self.attack.mode)
        self.packets_mutated += is_packet
        self._give(self._mutator.mutate(piece, is_packet, self.attack.mode), now)

    def _give(self, data: bytes, now: float) -> int:
        """
        Hand bytes to the node; let the reference parser say what they allow.

        Return how many the pty took (fewer when its buffer is full: the rest is lost).
        """
        if not data:
            return 0
        written = self.port.write(data)
        if not written:
            return 0
        data = data[:written]
        self.bytes_out += written
        self.oracle.given(data)
        self.recent.append((now, data))
        if len(self.recent) > 4000:
            del self.recent[:2000]
        return written

    def evidence(self, t: float) -> bytes:
        """Return the bytes given to the node in the half second up to ``t``."""
        return b''.join(d for when, d in list(self.recent) if t - 0.5 <= when <= t)
