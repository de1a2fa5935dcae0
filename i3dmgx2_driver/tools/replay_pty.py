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

The driver opens the pty's slave path as if it were the base station's
port. The slave is put in raw mode at once (no echo, no line editing: the
bytes are binary) and kept open here, so that the driver may close and
reopen the port without the pty hanging up. A paced write that nobody reads
drops the rest after :data:`WRITE_STALL`, as a serial line does. The
replay's playing and answering (replay.py, replay_answers.py) write and read
through :class:`ReplayPty` only.
"""

import fcntl
import os
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty

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
        self._link_request = link
        self._link: str | None = None
        self._tmpdir: str | None = None
        self._master = -1
        self._slave = -1
        self.pty_name: str | None = None
        self._stop = stop

    @property
    def path(self) -> str | None:
        """Path for the driver's ``port`` parameter (None before create)."""
        return self._link or self.pty_name

    def create(self) -> None:
        """Open the pty, raw, and make its link."""
        self._master, self._slave = os.openpty()
        try:
            # Raw at once: no echo of the driver's commands back into the stream, no
            # CR/LF translation, no signal characters in binary data.
            tty.setraw(self._slave)
            os.set_blocking(self._master, False)
            self.pty_name = os.ttyname(self._slave)
            self._make_link()
        except BaseException:
            self._close_fds()
            raise

    def close(self) -> None:
        """Close the pty and remove the link; idempotent."""
        self._close_fds()
        self._remove_link()

    def pending_output(self) -> int:
        """Bytes written but not yet read by the driver (0 only if none; 0 after close)."""
        if self._slave < 0:
            return 0
        try:
            return unread_bytes(self._slave)
        except (OSError, ValueError):
            return 0

    def _make_link(self) -> None:
        link = self._link_request
        if link is None:
            self._tmpdir = tempfile.mkdtemp(prefix='gx2-replay-')
            link = os.path.join(self._tmpdir, 'ttyGX2')
        elif os.path.islink(link):
            os.unlink(link)  # a stale link of an earlier replay
        elif os.path.exists(link):
            raise FileExistsError(f'{link} exists and is not a symlink; not replacing it')
        os.symlink(self.pty_name, link)
        self._link = link

    def _remove_link(self) -> None:
        link, self._link = self._link, None
        if link and os.path.islink(link) and os.readlink(link) == self.pty_name:
            os.unlink(link)
        if self._tmpdir:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None

    def _close_fds(self) -> None:
        for name in ('_master', '_slave'):
            fd = getattr(self, name)
            if fd >= 0:
                setattr(self, name, -1)
                try:
                    os.close(fd)
                except OSError:
                    pass

    def write(self, data: bytes, paced: bool) -> int:
        """
        Write all of ``data`` unless stopped; return the bytes written.

        Paced, a full pty (nobody reading) drops the rest after WRITE_STALL, as
        a serial port nobody reads overruns; unpaced, the reader sets the pace.
        """
        view = memoryview(data)
        written = 0
        stall_end = time.monotonic() + WRITE_STALL
        while written < len(data):
            try:
                written += os.write(self._master, view[written:])
                continue
            except BlockingIOError:
                pass
            if self._stop.is_set() or (paced and time.monotonic() >= stall_end):
                break
            select.select([], [self._master], [], POLL)
        return written

    def read(self) -> bytes:
        """Return what the host wrote, waiting up to :data:`POLL` (b'' if nothing)."""
        try:
            ready, _, _ = select.select([self._master], [], [], POLL)
            if not ready:
                return b''
            return os.read(self._master, 4096)
        except BlockingIOError:
            return b''
