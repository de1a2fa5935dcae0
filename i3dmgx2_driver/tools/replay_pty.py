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
The pseudo-terminal a replay plays into, and the symlink that names it.

The pty, raw and behind its symlink, is the simulator's (:class:`PtyPort`):
the slave is kept open here, so that the driver may close and reopen the
port without the pty hanging up, and the link points at the pty itself. What
is the replay's own: a paced write that nobody reads drops the rest after
:data:`WRITE_STALL`, as a serial line does, and :meth:`ReplayPty.pending_output`
tells when the driver has read it all. The replay's playing and answering
(replay.py, replay_answers.py) write and read through :class:`ReplayPty` only.
"""

import contextlib
import fcntl
import os
import select
import struct
import termios
import threading
import time

from ..simulator.pty_port import PtyPort, TIOCPKT_DATA

#: How long a paced write waits for the reader to make room before dropping
#: the rest of the chunk, as a serial line does when the host stops reading.
WRITE_STALL = 0.25
#: Granularity of the threads' checks for a stop request.
POLL = 0.05


def unread_bytes(fd: int) -> int:
    """
    Return how many bytes wait to be read on the terminal ``fd`` (a pty slave): 0 only if none.

    FIONREAD alone counts only what the line discipline holds: bytes just
    written to the master sit in the tty's flip buffer until a kernel worker
    moves them, and meanwhile count as 0 (most of the time, right after a
    write), so a replay that waited for its reader by FIONREAD could close
    the pty under it. Polling ``fd`` first makes the kernel finish that move
    whenever the line discipline is empty: 0 then means that nothing written
    is left unread. A nonzero count may leave out bytes still on their way.
    """
    select.select([fd], [], [], 0)
    raw = fcntl.ioctl(fd, termios.FIONREAD, b'\0\0\0\0')
    return struct.unpack('i', raw)[0]


class ReplayPty:
    """
    A new pseudo-terminal, named by the symlink ``link`` if one was asked for.

    Else the symlink is in a private temporary directory (so the path is
    stable and says what it is); the pty itself is :attr:`pty_name`.
    ``stop``, once set, cuts a write short.
    """

    def __init__(self, link: str | None, stop: threading.Event) -> None:
        self._port = PtyPort(link, link_via_proc=False, prefix='gx2-replay-')
        self._stop = stop
        #: Path for the driver's ``port`` parameter (None before create).
        self.path: str | None = None
        self.pty_name: str | None = None

    def create(self) -> None:
        """Open the pty, raw, and make its link."""
        path = self._port.create()
        try:
            self._port.plug_in()
        except BaseException:
            self.close()
            raise
        self.path, self.pty_name = path, self._port.device

    def close(self) -> None:
        """Close the pty and remove the link; idempotent."""
        self._port.pull_out()
        self._port.remove()

    def pending_output(self) -> int:
        """Bytes written but not yet read by the driver (0 only if none; 0 after close)."""
        slave = self._port.slave
        with contextlib.suppress(OSError, ValueError):  # closed meanwhile
            return 0 if slave is None else unread_bytes(slave)
        return 0

    def write(self, data: bytes, paced: bool) -> int:
        """
        Write all of ``data`` unless stopped; return the bytes written.

        Paced, a full pty (nobody reading) drops the rest after WRITE_STALL, as
        a serial port nobody reads overruns; unpaced, the reader sets the pace.
        """
        master = self._port.master
        view = memoryview(data)
        written = 0
        stall_end = time.monotonic() + WRITE_STALL
        while written < len(data) and master is not None:
            with contextlib.suppress(BlockingIOError):  # full: wait for room, or give up
                written += os.write(master, view[written:])
                continue
            if self._stop.is_set() or (paced and time.monotonic() >= stall_end):
                break
            select.select([], [master], [], POLL)
        return written

    def read(self) -> bytes:
        """Return what the host wrote, waiting up to :data:`POLL` (b'' if nothing)."""
        master = self._port.master
        if master is None:
            raise OSError('the pty is closed')
        try:
            data = os.read(master, 4096) if select.select([master], [], [], POLL)[0] else b''
        except BlockingIOError:
            return b''
        # The master is in packet mode: a data read starts with TIOCPKT_DATA, a
        # status read (the host's flush as it opens the port) is nothing to answer.
        return data[1:] if data[:1] == bytes((TIOCPKT_DATA,)) else b''
