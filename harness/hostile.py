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
*continuous*, then *streaming* once a record was forwarded).

What may be published is decided by the bytes the node was given: every
data packet a fresh codec parser finds in them (reset whenever the node
opens the port) is allowed; every real packet of the node's stream forwarded
whole while the station behaved is a packet that must be published. Not
other records from its address: those are the replies to its own polled
requests (the dialogue's 0xC2 polls, its identity), which the node takes as
replies and never publishes. Not a packet the pty took only in part either
(its buffer full after a held-back stretch is let go at once): the station
lost that one itself (``hostile_oracle.py``; the attacks' bytes:
``packet_mutation.py``). Used by ``benchmarks/fuzz_node.py`` and the stateful
dialogue test.
"""

import os
import random
import select
import threading
import time
import tty
from typing import NamedTuple

from harness.campaign_truth import imu_values
from harness.hostile_oracle import PublishOracle
from harness.packet_mutation import PacketMutator
from i3dmgx2_driver.codec import streams
from i3dmgx2_driver.codec.framing import (
    CommandPacket, DATA_FLAGS, DATA_TRAILER_SIZE, decode_data_packet, HEADER_SIZE, SOP)
from i3dmgx2_driver.codec.parser import CommandStreamParser, RawCommand
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
_LINE_BYTES_PER_S = 11520.0


class Attack(NamedTuple):
    """One armed attack: in which phase, what, for how long (s)."""

    phase: str
    mode: str
    seconds: float


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

    def flush(self) -> bytes:
        """Return what is buffered (a lone 0xAA after a quiet spell is an ACK)."""
        rest, self._buf = bytes(self._buf), bytearray()
        return rest


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
        self.stream = stream
        self.rng = random.Random(seed)
        self.port = PtyPort()
        self.path = self.port.create()
        self.port.plug_in()
        self._upstream_path = upstream
        self._up = self._open_upstream()
        self._host = CommandStreamParser(wireless=True)
        self._split = Split()
        #: What may and what must be published (see ``hostile_oracle.py``).
        self.oracle = PublishOracle(address, stream)
        #: The attacks' bytes; the same generator as the noise, so that a seed replays a run.
        self._mutator = PacketMutator(self.rng)
        self._lock = threading.Lock()
        self._halt = threading.Event()
        self.phase = 'quiet'
        self.armed: Attack | None = None
        self.hostile_until = 0.0
        self.attack: Attack | None = None
        self.attacks: list[tuple[float, Attack]] = []
        self.packets_in = 0
        self.packets_mutated = 0
        self.bytes_out = 0
        self.opens = 0
        #: Recent bytes given to the node (time, bytes), for a finding's evidence.
        self.recent: list[tuple[float, bytes]] = []
        self._resume_at = 0.0

    # -- the oracle, as the fuzz and the tests read it -----------------------------------------

    @property
    def allowed(self) -> set[bytes]:
        """Keys allowed to be published (found by a fresh parser in what the node was given)."""
        return self.oracle.allowed

    @property
    def intact(self) -> list[tuple[float, bytes]]:
        """(time, key) of the records that must be published."""
        return self.oracle.intact

    @property
    def intact_keys(self) -> set[bytes]:
        """Keys of real packets of ours sent whole: they may be published."""
        return self.oracle.intact_keys

    @property
    def attacked_keys(self) -> dict[bytes, str]:
        """Keys of real packets of ours that were attacked, with the attack's mode."""
        return self.oracle.attacked_keys

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
        self.attacks.append((time.time(), attack))
        if attack.mode == 'stop_mid_packet':
            self._resume_at = self.hostile_until

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
                if data:
                    self._from_device(data, now)
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
                self.opens += 1
            return
        payload = data[1:]
        for event in self._host.feed(payload):
            code = None
            if isinstance(event, (CommandPacket, RawCommand)) and event.command:
                code = event.command[0]
            if code == 0x02:
                self.oracle.expect_ping()
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

    def _from_device(self, data: bytes, now: float) -> None:
        for piece in self._split.feed(data):
            self._piece(piece, now)

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
        ours = False
        key = None
        if is_packet:
            self.packets_in += 1
            address = (piece[3] << 8) | piece[4]
            ours = address == self.address
            try:
                record = decode_data_packet(piece).record
                values = imu_values(record)
                key = values[0] if values is not None else None
                if ours and record is not None:
                    self._mutator.remember_reply(piece)
            except Exception:  # noqa: B902 - the simulator's own faults: a damaged packet
                record = None
            if ours and self.phase == 'continuous' and key is not None:
                with self._lock:
                    self.phase = 'streaming'
                    if self.armed is not None and self.armed.phase == 'streaming':
                        self._start(self.armed)
        if not self.hostile:
            if key is not None and ours:
                self.oracle.sent_whole(key)
            written = self._give(piece, now)
            if key is not None and ours:
                self.oracle.owed(piece, key, written, now)
            return
        if key is not None and ours:
            if self.attack.mode in KEEPS_PACKET:
                self.oracle.sent_whole(key)  # delayed or surrounded, but sent whole
            else:
                self.oracle.attacked(key, self.attack.mode)
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

    def evidence(self, t: float, before: float = 0.5) -> bytes:
        """Return the bytes given to the node in the ``before`` s up to ``t``."""
        return b''.join(d for when, d in list(self.recent) if t - before <= when <= t)
