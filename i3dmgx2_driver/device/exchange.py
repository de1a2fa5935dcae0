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
Request and reply with one sensor: a command written, its answer awaited.

Requests (polled records, EEPROM, identity, continuous mode, a ping) are
made from a thread other than the reader's: they write a command packet and
wait for the reader to see the reply, the base station's ACK or NACK, or
nothing, with a timeout and bounded retries, because the radio loses
commands both ways. On a port several sensors share, the port is held only
while the base station's answer (which carries no address) is due.
"""

import contextlib
import threading
import time
from typing import Any

from . import timeouts
from .port import PortDisconnected, SerialPort
from .port_reader import PortReader
from ..codec import commands, layouts
from ..codec.framing import encode_command_packet
from ..codec.parser import Ack, Nack
from ..codec.records import PingReply


class DeviceTimeout(Exception):
    """A request got no reply after every retry."""


class DeviceNack(DeviceTimeout):
    """The base station rejected a request on every try."""


class Pending:
    """A request waiting for its reply, filled in by the reader thread."""

    def __init__(self, code: int | None) -> None:
        self.code = code
        self.done = threading.Event()
        self.reply: Any = None
        self.acked = threading.Event()
        self.nacked = threading.Event()

    def fulfil(self, reply: Any) -> None:
        """Hand the waiting request its reply (reader thread)."""
        self.reply = reply
        self.done.set()


class Exchange:
    """
    The requests to the sensor at ``address``, one at a time, over ``reader``'s port.

    ``shared`` says the reader serves several sensors: then this sensor's
    requests are serialised by a lock of its own, and the port's lock is
    held only while the base station's answer is due. ``cancel`` set makes
    every request give up within tens of milliseconds.
    """

    def __init__(self, port: SerialPort, address: int | None, reader: PortReader,
                 cancel: threading.Event, shared: bool) -> None:
        self.port = port
        self.address = address
        self.wireless = reader.wireless
        self._reader = reader
        self._parser = reader.parser
        #: The request waiting for its reply (read by the reader thread's stream watch).
        self.pending: Pending | None = None
        #: One exchange at a time with this sensor; on a shared port, the port's
        #: lock is held only while the base station's answer (no address) is due.
        self._lock = reader.request_lock if not shared else threading.Lock()
        self._port_lock = reader.request_lock if shared else None
        self._write_lock = reader.write_lock
        #: Set when the link stops: every request gives up.
        self.stopped = threading.Event()
        self._cancel = cancel

    # -- the reader thread's side ------------------------------------------

    def answer(self, event: Any) -> None:
        """Take the base station's answer to this exchange (ACK, NACK, ping)."""
        pending = self.pending
        if pending is None:
            return
        if isinstance(event, Ack):
            pending.acked.set()
        elif isinstance(event, Nack):
            pending.nacked.set()
        elif isinstance(event, PingReply) and pending.code == layouts.PING:
            pending.fulfil(event)

    def wake(self) -> None:
        """Make a waiting request look again (the port is gone or the link stops)."""
        pending = self.pending
        if pending is not None:
            pending.done.set()

    # -- requests ------------------------------------------------------------

    def send(self, command: bytes) -> None:
        """Write one command, framed for the link; no waiting."""
        data = encode_command_packet(self.address, command) if self.wireless else command
        with self._write_lock:
            self.port.write(data)

    def request(self, command: bytes, reply_code: int | None, timeout: float = 0.5,
                retries: int = 3) -> Any:
        """
        Send ``command`` until its reply (a record of ``reply_code``) arrives.

        Returns the reply record. A NACK resends at once; silence resends
        after ``timeout``. Raises DeviceTimeout (DeviceNack if every try was
        rejected) after ``retries`` tries, PortDisconnected if the port died.
        """
        with self._lock:
            nacks = 0
            for _ in range(retries):
                self._check_cancelled()
                pending = Pending(reply_code)
                self.pending = pending
                try:
                    if self._port_lock is None:
                        self._reader.requester = self
                        self.send(command)
                        self._wait(pending, timeout)
                    else:
                        self._exchange_shared(command, pending, timeout)
                finally:
                    self.pending = None
                    if self._reader.requester is self:
                        self._reader.requester = None
                self._check_port()
                self._check_cancelled()
                if pending.done.is_set():
                    return pending.reply
                if pending.nacked.is_set():
                    nacks += 1
            name = layouts.LAYOUTS[command[0]].name
            if nacks == retries:
                raise DeviceNack(f'{name}: the base station rejected it {retries} times')
            raise DeviceTimeout(f'{name}: no reply after {retries} tries')

    def _exchange_shared(self, command: bytes, pending: Pending, timeout: float) -> None:
        """
        Send on a shared port: hold it until the ACK or NACK, then wait for the reply alone.

        The reply is a data packet with this sensor's address, routed to this
        link whoever else streams or asks meanwhile; only the base station's
        one-byte answer must not be mistaken for another sensor's.
        """
        deadline = time.monotonic() + timeout
        with self._port_lock:
            self._reader.requester = self
            try:
                self.send(command)
                ack_deadline = time.monotonic() + min(timeouts.ACK_TIMEOUT, timeout)
                while not (pending.acked.is_set() or pending.nacked.is_set()
                           or pending.done.is_set() or self._cancel.is_set()):
                    left = ack_deadline - time.monotonic()
                    if left <= 0:
                        break
                    pending.acked.wait(min(left, 0.01))
            finally:
                self._reader.requester = None
        if not pending.nacked.is_set():
            self._wait(pending, deadline - time.monotonic())

    def _wait(self, pending: Pending, timeout: float, nack_ends: bool = True) -> None:
        """Wait for a reply, a NACK (if ``nack_ends``), a cancel or the timeout."""
        deadline = time.monotonic() + timeout
        while not (nack_ends and pending.nacked.is_set()) and not self._cancel.is_set():
            left = deadline - time.monotonic()
            if left <= 0 or pending.done.wait(min(left, 0.02)):
                break

    def _check_port(self) -> None:
        if self._reader.disconnected.is_set():
            raise PortDisconnected(self._reader.error or 'device disconnected')

    def _check_cancelled(self) -> None:
        if self.stopped.is_set() or self._reader.stopping:
            raise DeviceTimeout('the link is shutting down')
        if self._cancel.is_set():
            raise DeviceTimeout('cancelled: the stream is being stopped')

    def ping(self, timeout: float = 0.5, retries: int = 3) -> bool:
        """Ask the base station whether the sensor answers over the radio."""
        for _ in range(retries):
            answer = self.ping_once(self.address, timeout)
            if answer is not None:
                return answer
        return False

    def ping_once(self, address: int, timeout: float) -> bool | None:
        """
        Ping ``address`` once: True (link OK), False (0x21: no such node).

        None means no answer at all, which a base station never gives: a
        wired sensor, or nothing, is on the port (what discovery needs to
        tell apart from a node that is not there).
        """
        with self._lock, self._port_lock or contextlib.nullcontext():
            for _ in range(2):
                skipped = self._parser.stats.bytes_skipped
                pending = Pending(layouts.PING)
                self.pending = pending
                self._reader.requester = self
                try:
                    self._parser.expect_ping()
                    with self._write_lock:
                        self.port.write(commands.ping(address))
                    self._wait(pending, timeout, nack_ends=False)
                finally:
                    self.pending = None
                    self._reader.requester = None
                self._check_port()
                self._check_cancelled()
                # The answer is one byte, 0x02 or 0x21, found between frames. While
                # the parser skips garbage (the tail of another node's packet cut by
                # a flush) a byte of that garbage can pass for it; the parser is in
                # step with the stream after it, so a second ping is trustworthy.
                if pending.reply is None or self._parser.stats.bytes_skipped == skipped:
                    break
            return None if pending.reply is None else bool(pending.reply.ok)

    def stop_streaming(self, repeats: int = 3, gap: float = 0.02) -> None:
        """Send 0xFA several times: it has no reply and the radio may drop it."""
        for _ in range(repeats):
            self.send(commands.stop_continuous())
            time.sleep(gap)
