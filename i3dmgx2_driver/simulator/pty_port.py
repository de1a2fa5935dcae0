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
The pseudo-terminal a driver opens as its serial port, behind a stable symlink.

Design points, each for a reason:

* The pty slave is put in raw mode at once and kept open by the simulator:
  the data are binary (no echo, no CR/LF translation), reads on the master do
  not fail with EIO whenever the driver closes the port, and the line settings
  persist between the driver's opens.
* The port path is a symlink in a private directory, so the path stays the
  same when an unplug replaces the pty (the real ``/dev/ttyUSB0`` comes back
  under the same name too). It points to ``/proc/<pid>/fd/<slave>``, not to
  ``/dev/pts/N``: if the simulator is killed before it removes the link, the
  link dangles, where a link to ``/dev/pts/N`` would lead a still-running
  driver into whichever new pseudo-terminal reuses the number (seen in practice
  on a shared machine).
* The master runs in packet mode (TIOCPKT), which reports the input flush that
  pyserial does on every open: that is how the simulator knows the host has
  (re)opened the port, for the "poll before streaming" quirk.
* Writes are non-blocking: when nobody reads and the pty buffer is full the
  bytes are lost, as on a real line, and the caller counts them.
"""

import contextlib
import fcntl
import os
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty

from ..lifetime import close_quietly

#: Name of the port symlink inside the simulator's private directory.
PORT_NAME = 'ttyGX2'
#: Leading byte of a packet-mode read: data follow (anything else is a status).
TIOCPKT_DATA = 0
#: Status bit of a packet-mode read: the other end flushed its input (an open).
TIOCPKT_FLUSHREAD = getattr(termios, 'TIOCPKT_FLUSHREAD', 0x01)

_TIOCPKT = getattr(termios, 'TIOCPKT', 0x5420)


class PtyPort:
    """
    One pseudo-terminal at a time behind the symlink ``path``; unplugging closes it.

    ``io_lock`` guards the descriptors and every write. Lock order: a caller
    may hold the simulator's lock while taking ``io_lock``, never the reverse.
    ``prefix`` names the private directory of a symlink not asked for (a
    replay's says so).
    """

    def __init__(self, symlink: str | None = None, link_via_proc: bool = True,
                 prefix: str = 'i3dmgx2-sim-') -> None:
        self._symlink, self._prefix, self._link_via_proc = symlink, prefix, link_via_proc
        self._dir: str | None = None
        self.io_lock = threading.Lock()
        #: Set while the pty exists (cleared between unplug and replug).
        self.plugged = threading.Event()
        #: Path to open: a symlink that survives unplug and replug.
        self.path: str | None = None
        #: The pseudo-terminal the symlink points to now (None while unplugged).
        self.device: str | None = None
        #: What the symlink points to now (None while unplugged).
        self.link_target: str | None = None
        self.master: int | None = None
        self.slave: int | None = None

    def create(self) -> str:
        """Choose the path: the fixed symlink asked for, or one in a private directory."""
        if self._symlink:
            self.path = os.path.abspath(self._symlink)
            if os.path.lexists(self.path) and not os.path.islink(self.path):
                raise FileExistsError(f'{self.path} exists and is not a symlink')
        else:
            self._dir = tempfile.mkdtemp(prefix=self._prefix)
            self.path = os.path.join(self._dir, PORT_NAME)
        return self.path

    def remove(self) -> None:
        """Remove the private directory, if any (after :meth:`pull_out`)."""
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    def plug_in(self) -> None:
        """Make a new raw pty in packet mode and point the symlink at it."""
        master, slave = os.openpty()
        tty.setraw(slave)
        fcntl.ioctl(master, _TIOCPKT, struct.pack('i', 1))
        os.set_blocking(master, False)
        device = os.ttyname(slave)
        # Through /proc, the link dangles once this process is gone, even if it
        # was killed before it could remove it: a stale link never leads a
        # driver to whatever pseudo-terminal reuses the number later.
        target = f'/proc/{os.getpid()}/fd/{slave}'
        if not self._link_via_proc or not os.path.exists(target):
            target = device
        temporary = f'{self.path}.{os.getpid()}.new'
        if os.path.lexists(temporary):
            os.unlink(temporary)
        os.symlink(target, temporary)
        os.replace(temporary, self.path)
        with self.io_lock:
            self.master, self.slave, self.device, self.link_target = master, slave, device, target
        self.plugged.set()

    def pull_out(self) -> None:
        """Close the pty (the host's reads and writes fail) and remove our symlink."""
        with self.io_lock:
            close_quietly(self.master, self.slave)
            target = self.link_target
            self.master = self.slave = self.device = self.link_target = None
        self.plugged.clear()
        if self.path and os.path.islink(self.path) and os.readlink(self.path) == target:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.path)

    def write_chunks(self, chunks: list[bytes],
                     gap: float) -> tuple[int, float | None, float | None]:
        """
        Write chunks ``gap`` seconds apart; return (bytes written, first and last write's time).

        Each time is read just *before* its write: before the one that hands
        the first byte to the pty, and before the one that hands the last. No
        reader can have the whole frame before the last, so a host's read time
        is never earlier. A time read after that write could be late by
        however long this thread was descheduled in between (milliseconds on
        a loaded machine), and a reader would then seem to have the bytes
        before they were written. None when the port is unplugged. Fewer
        bytes than given means the buffer was full (nobody reads): the rest
        is lost.
        """
        written = 0
        with self.io_lock:
            if (master := self.master) is None:
                return 0, None, None
            first_write = last_write = time.time()
            # The buffer is full (nobody reads): the rest is lost.
            with contextlib.suppress(OSError):
                for index, chunk in enumerate(chunks):
                    if index and gap:
                        time.sleep(gap)
                    view = memoryview(chunk)
                    while view:
                        last_write = time.time()
                        count = os.write(master, view)
                        written += count
                        view = view[count:]
            return written, first_write, last_write

    def write(self, data: bytes) -> int | None:
        """Write a few bytes at once; return how many (None: unplugged)."""
        with self.io_lock:
            if self.master is None:
                return None
            try:
                return os.write(self.master, data)
            except OSError:
                return 0
