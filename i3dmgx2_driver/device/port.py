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
The serial port: open it exclusively, make it fast, read what has arrived.

Errors are sorted into what a user can act on (the port does not exist, is
not theirs to open, is in use, is no serial port at all), because "could not
open port" alone sends people to the wrong fix. Two kinds differ in what the
driver does next: what may come back (an unplugged adapter, a port another
process holds) is retried, while a path that exists but is no terminal device
(a regular file, a directory, ``/dev/null``) can never work and is a
:class:`PortUnusable`, which ends the driver. :func:`check_port_path` tells
the two apart without opening anything, so that every entry point can refuse
such a path before it starts. Reads return whatever bytes are waiting as soon
as any arrive, so the last byte of a packet reaches the parser without
waiting for a fixed read size or a polling interval.
"""

import array
import contextlib
import errno
import fcntl
import glob
import grp
import os
import pwd
import select
import stat
import termios
from typing import Any

import serial


#: Readable-but-empty reads in a row (with no flag saying hang-up) taken as one.
EMPTY_READS_OF_A_HANGUP = 3


class PortError(Exception):
    """The port could not be opened or used; the message says what to do."""


class PortMissing(PortError):
    """No device at the path (unplugged, or a wrong path)."""


class PortPermissionDenied(PortError):
    """
    The user may not open the device (usually: not in ``dialout``).

    The message never advises joining a group that gives more than serial
    ports (``root``, ``wheel``, ``sudo``...): for such a port it recommends
    the package's udev rule instead (:func:`serial_group`).
    """


class PortBusy(PortError):
    """Another process holds the port."""


class PortDisconnected(PortError):
    """The device went away while open (unplugged, or the pty closed)."""


class PortUnusable(PortError):
    """
    The port can never work for this process: say so once and stop.

    Retrying cannot help (nothing the user plugs in turns a regular file
    into a serial port), so entry points end with exit code 2, as for a bad
    parameter value, instead of retrying every second forever.
    """


class PortNotSerial(PortUnusable):
    """The path exists but is no terminal device (a file, a directory, /dev/null)."""


#: The udev rule the package installs under share/i3dmgx2_driver/udev/ (udev/ in the source).
UDEV_RULE_NAME = '99-i3dmgx2.rules'
#: The commands that install it, on one line.
UDEV_RULE_INSTALL = (
    f'sudo cp "$(ros2 pkg prefix i3dmgx2_driver)/share/i3dmgx2_driver/udev/{UDEV_RULE_NAME}" '
    '/etc/udev/rules.d/ && sudo udevadm control --reload-rules && sudo udevadm trigger')
#: What the rule does, and how to install it.
UDEV_RULE_ADVICE = (
    "install the udev rule that comes with the driver, which gives the base station's port "
    'to the dialout group with mode 0660, a stable link /dev/i3dmgx2 and a 1 ms latency '
    f'timer: {UDEV_RULE_INSTALL} (from a source checkout: udev/{UDEV_RULE_NAME}); then, if '
    'you are not in dialout yet, sudo usermod -aG dialout $USER and log in again')
#: Groups that exist to give serial ports to their members (Debian, Arch, Fedora, SUSE...).
SERIAL_GROUPS = frozenset({'dialout', 'uucp', 'tty', 'serial'})
#: Words that name a group made for this one device.
DEVICE_GROUP_WORDS = ('i3dmgx2', 'gx2', 'microstrain', '3dm')
#: The low-latency bit of struct serial_struct's flags (linux/tty_flags.h).
ASYNC_LOW_LATENCY = 1 << 13
#: How much one read takes at most; a few packets' worth.
READ_SIZE = 4096
#: The most a read of a terminal returns while VMIN is above it (:meth:`SerialPort.read_some`).
TTY_READ_CHUNK = 64
#: The kernel's list of terminal drivers: name, node, major, minors, type.
TTY_DRIVERS = '/proc/tty/drivers'
#: Where Linux lists serial adapters by a stable name, and the usual nodes.
_BY_ID = '/dev/serial/by-id/*'
_USUAL_PORTS = ('/dev/ttyUSB*', '/dev/ttyACM*')


def port_hint() -> str:
    """Say how to find the right port: what is present now, and the tools."""
    found = sorted(glob.glob(_BY_ID)) or sorted(
        path for pattern in _USUAL_PORTS for path in glob.glob(pattern))
    present = (f'Serial ports present now: {", ".join(found[:4])}'
               + (', ...' if len(found) > 4 else '')) if found \
        else 'No USB serial port is present now'
    return (f'{present} (ls /dev/serial/by-id/ names them; ros2 run i3dmgx2_driver discover '
            f'finds the base station and the sensor address); set -p port:=<path>')


def terminal_majors(drivers: str | None = None) -> list[tuple[int, int, int]] | None:
    """
    Return (major, first minor, last minor) of every terminal driver.

    None when the kernel's list cannot be read (not Linux, or /proc hidden):
    then nothing is concluded from a character device's numbers.
    """
    try:
        with open(drivers or TTY_DRIVERS) as handle:
            lines = handle.read().splitlines()
    except OSError:
        return None
    ranges = []
    for fields in (line.split() for line in lines):
        if len(fields) >= 5:
            with contextlib.suppress(ValueError):
                low, _, high = fields[-2].partition('-')
                ranges.append((int(fields[-3]), int(low), int(high or low)))
    return ranges


#: What a file is, by its ``st_mode``, when it is surely no terminal whatever its numbers.
_NOT_TERMINALS = ((stat.S_ISREG, 'a regular file'), (stat.S_ISDIR, 'a directory'),
                  (stat.S_ISFIFO, 'a named pipe (FIFO)'), (stat.S_ISSOCK, 'a socket'))


def describe_non_terminal(mode: int, rdev: int = 0,
                          ranges: list[tuple[int, int, int]] | None = None) -> str | None:
    """
    Say what a file of this ``st_mode`` is, if it surely is no terminal; else None.

    A character device counts as a terminal when the kernel lists its major
    and minor among the terminal drivers (``ranges``, from
    :func:`terminal_majors`), so that no other device (``/dev/null``, a
    watchdog, whose mere opening has effects) is ever opened to find out.
    Without the list a character device is given the benefit of the doubt.
    """
    what = next((what for test, what in _NOT_TERMINALS if test(mode)), None)
    major, minor = os.major(rdev), os.minor(rdev)
    if stat.S_ISBLK(mode):
        what = f'a block device ({major}:{minor}, a disk)'
    elif stat.S_ISCHR(mode) and ranges is not None and not any(
            m == major and low <= minor <= high for m, low, high in ranges):
        what = f'a character device ({major}:{minor}) that is not a terminal'
    return what


def check_port_path(path: str, drivers: str | None = None) -> None:
    """
    Raise :class:`PortNotSerial` if ``path`` exists and is surely no serial port.

    Returns quietly for a terminal device, and for a path that does not
    exist or cannot be examined: an adapter may be plugged in later, and
    opening it says what is wrong. Opens nothing. Every entry point that
    opens the port calls this first (the node, the managed node's configure
    transition), and :class:`SerialPort` does too.
    """
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return
    ranges = terminal_majors(drivers) if stat.S_ISCHR(info.st_mode) else None
    what = describe_non_terminal(info.st_mode, info.st_rdev, ranges)
    if what is not None:
        raise PortNotSerial(_not_serial_message(path, what))


def _not_serial_message(path: str, what: str) -> str:
    real = os.path.realpath(path)
    shown = path if real == os.path.abspath(path) else f'{path} (a link to {real})'
    return (f"parameter 'port': {shown} is {what}, not a serial port, so it can never work. "
            f'{port_hint()}')


def _owning_group(path: str) -> tuple[str, int] | None:
    """Return the name and mode of the group that owns ``path``, if it can be read."""
    try:
        info = os.stat(path)
    except OSError:
        return None
    with contextlib.suppress(KeyError):
        return grp.getgrgid(info.st_gid).gr_name, info.st_mode
    return str(info.st_gid), info.st_mode


def _in_group_database(group: str) -> bool:
    """Whether this user is a member of ``group`` by the group database."""
    try:
        user = pwd.getpwuid(os.getuid())
        entry = grp.getgrnam(group)
    except KeyError:
        return False
    return user.pw_gid == entry.gr_gid or user.pw_name in entry.gr_mem


def serial_group(group: str, path: str = '') -> bool:
    """
    Whether joining ``group`` gives a user serial ports and nothing more.

    True for the groups distributions give serial ports to (``dialout``,
    ``uucp``, ``tty``, ``serial``...) and for a group named for this device
    alone (after the sensor, or after the port's own name); False for
    ``root``, ``wheel``, ``sudo``, ``adm``, ``disk`` and any other group,
    whose members may do far more than open a serial port.
    """
    name = group.lower()
    names = {os.path.basename(p).lower() for p in (path, os.path.realpath(path)) if p}
    return (name in SERIAL_GROUPS or any(word in name for word in DEVICE_GROUP_WORDS)
            or any(len(n) >= 4 and n in name for n in names))


def _permission_message(path: str) -> str:
    owner = _owning_group(path)
    text = f'permission denied opening {path}: '
    if owner is None:
        return text + ('add your user to the dialout group (sudo usermod -aG dialout $USER, '
                       'then log in again)')
    group, mode = owner
    if not mode & stat.S_IRGRP:
        return text + (f'only its owner may open it (mode {stat.S_IMODE(mode):04o}); '
                       f'{UDEV_RULE_ADVICE}')
    if not serial_group(group, path):
        return text + (f'it belongs to the {group} group, and joining {group} would give '
                       f'your user far more than this port, so do not; {UDEV_RULE_ADVICE}')
    if _in_group_database(group):
        return text + (f'you are in the {group} group that owns it, but this session is '
                       f'not yet: log out and in again (or run newgrp {group})')
    return text + (f'add your user to the {group} group that owns it '
                   f'(sudo usermod -aG {group} $USER, then log in again)')


def _classify(path: str, exc: Exception) -> PortError:
    code, text = getattr(exc, 'errno', None), str(exc)
    if code == errno.ENOENT or 'No such file' in text:
        return PortMissing(f'serial port {path} does not exist: is the base station '
                           f'plugged in, and is the path right? {port_hint()}')
    if code == errno.EACCES or 'Permission denied' in text:
        return PortPermissionDenied(_permission_message(path))
    if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or 'lock' in text:
        return PortBusy(f'serial port {path} is in use by another process')
    if code in (errno.ENOTTY, errno.EISDIR) or 'Inappropriate ioctl' in text:
        # What check_port_path could not tell (no list of terminal drivers).
        what = None
        with contextlib.suppress(OSError):
            info = os.stat(path)
            what = describe_non_terminal(info.st_mode, info.st_rdev, ranges=[])
        return PortNotSerial(_not_serial_message(path, what or 'no terminal device'))
    return PortError(f'cannot open serial port {path}: {text}')


class SerialPort:
    """
    One open serial port, with exclusive access and low-latency reads.

    ``low_latency`` asks Linux to put the port in ASYNC_LOW_LATENCY mode,
    which makes USB-serial adapters (FTDI's latency timer, 16 ms by default)
    hand over bytes at once; ports that cannot (a pseudo-terminal) are left
    as they are. ``low_latency_state`` records what the port accepted.
    """

    def __init__(self, path: str, baud: int = 115200, low_latency: bool = True,
                 serial_factory: Any = serial.Serial) -> None:
        self.path = path
        check_port_path(path)
        try:
            # 8N1 without flow control, pyserial's defaults; reads never block.
            self._serial = serial_factory(port=path, baudrate=baud, timeout=0,
                                          write_timeout=1.0, exclusive=True)
        except (serial.SerialException, OSError) as exc:
            raise _classify(path, exc) from exc
        self.low_latency_state = 'off'
        if low_latency:
            self.enable_low_latency()
        self._fd: int | None = None
        with contextlib.suppress(AttributeError, OSError, serial.SerialException):
            self._fd = self._serial.fileno()
            os.set_blocking(self._fd, False)  # pyserial's is already; read_some() needs it
        #: Bytes a wait for data waits for (:meth:`wake_for`): 1, any byte.
        self.wakes_for = 1

    def low_latency_flag(self) -> bool | None:
        """
        Whether the port is in low-latency mode now (ASYNC_LOW_LATENCY).

        None when the port cannot tell (a pseudo-terminal, not Linux): what
        ``bringup`` reports as found, before it asks for the mode itself.
        """
        if self._fd is None or not hasattr(termios, 'TIOCGSERIAL'):
            return None
        settings = array.array('i', [0] * 32)  # struct serial_struct; flags is the 5th int
        try:
            fcntl.ioctl(self._fd, termios.TIOCGSERIAL, settings)
        except OSError:
            return None
        return bool(settings[4] & ASYNC_LOW_LATENCY)

    def enable_low_latency(self) -> str:
        """Ask for low-latency mode now; return and keep 'on' or why it is not."""
        try:
            self._serial.set_low_latency_mode(True)
            self.low_latency_state = 'on'
        except (NotImplementedError, AttributeError):
            self.low_latency_state = 'not supported on this platform'
        except (OSError, ValueError, serial.SerialException) as exc:
            self.low_latency_state = f'refused by the port ({exc.__class__.__name__})'
        return self.low_latency_state

    def read_some(self, timeout: float) -> bytes:
        """
        Wait up to ``timeout`` s for bytes; return all that are there.

        Returns b'' on a timeout. Raises PortDisconnected when the device is
        gone: an I/O error, or a descriptor that is readable, gives no data
        and says it was hung up.

        A readable descriptor that gives nothing is not enough: a flush from
        another thread (the dialogue's ``quiet`` while the reader runs) can
        empty the queue between select and read, and reading that as an
        unplug made a reconnect out of nothing (found by the stateful
        dialogue test on a CI machine). The descriptor does not block, so
        an emptied queue says EAGAIN: nothing there. A hung-up terminal says
        so in poll's flags; an empty read that repeats at once is taken as
        one too.
        """
        if self._fd is None:
            return self._read_portable(timeout)
        try:
            ready, _, _ = select.select([self._fd], [], [], timeout)
            if not ready:
                return b''
            try:
                data = os.read(self._fd, READ_SIZE)
            except BlockingIOError:
                return b''  # flushed between the select and the read
            if not data:
                data = self._after_empty_read()
            elif len(data) == TTY_READ_CHUNK and self.wakes_for > 1:
                # While VMIN is above 64, Linux hands a read at most 64 bytes (the tty
                # layer copies through a buffer of that size and ends the read once
                # VMIN is met): the rest of a packet is read at once, not after a wake.
                more = data
                while len(more) == TTY_READ_CHUNK:
                    try:
                        more = os.read(self._fd, READ_SIZE)
                    except BlockingIOError:
                        break
                    data += more
        except (OSError, ValueError) as exc:
            raise PortDisconnected(f'{self.path}: {exc}') from exc
        return data

    def wake_for(self, nbytes: int) -> None:
        """
        Let :meth:`read_some` wait until ``nbytes`` bytes are in (1: any byte), where it can.

        A port hands a packet over in pieces: a USB-serial adapter each of its
        transfers (a millisecond apart in low-latency mode), a pty each write.
        Woken for each, the reader thread runs the parser's Python on a cold
        cache every time (docs/cpu.md). Set as the terminal's VMIN (VTIME 0),
        ``select()`` reports the port readable only once ``nbytes`` are queued
        (Linux's n_tty poll counts VMIN), so the reader wakes once a packet and
        the pieces are joined by the kernel. The caller sets it back to 1
        whenever an answer shorter than a packet may come. A port without a
        file descriptor (not POSIX) keeps waking for any byte.
        """
        if nbytes == self.wakes_for or self._fd is None:
            return
        try:
            attributes = termios.tcgetattr(self._fd)
            attributes[6][termios.VMIN] = nbytes
            attributes[6][termios.VTIME] = 0
            termios.tcsetattr(self._fd, termios.TCSANOW, attributes)
        except (termios.error, OSError):
            return  # the port is going: the read says so
        self.wakes_for = nbytes

    def _after_empty_read(self) -> bytes:
        """Tell a hang-up from a queue another thread flushed: raise, or return bytes."""
        for _ in range(EMPTY_READS_OF_A_HANGUP):
            poller = select.poll()
            poller.register(self._fd, select.POLLIN)
            events = poller.poll(0)
            flags = events[0][1] if events else 0
            if flags & (select.POLLHUP | select.POLLERR | select.POLLNVAL):
                break
            if not flags & select.POLLIN:
                return b''  # flushed: nothing there, nothing wrong
            try:
                data = os.read(self._fd, READ_SIZE)
            except BlockingIOError:
                return b''  # flushed between the poll and the read
            if data:
                return data
        raise PortDisconnected(f'{self.path}: device disconnected')

    def _read_portable(self, timeout: float) -> bytes:
        try:
            self._serial.timeout = timeout
            data = self._serial.read(1)
            waiting = self._serial.in_waiting
            if waiting:
                data += self._serial.read(waiting)
            return data
        except (OSError, serial.SerialException) as exc:
            raise PortDisconnected(f'{self.path}: {exc}') from exc

    def write(self, data: bytes) -> None:
        """Write all of ``data``; raise PortDisconnected if the device is gone."""
        try:
            self._serial.write(data)
        except (OSError, serial.SerialException) as exc:
            raise PortDisconnected(f'{self.path}: {exc}') from exc

    def flush_input(self) -> None:
        """Discard what the OS holds (stale records from before we asked)."""
        try:
            self._serial.reset_input_buffer()
        except (OSError, serial.SerialException, termios.error) as exc:
            raise PortDisconnected(f'{self.path}: {exc}') from exc

    def close(self) -> None:
        """Close the port; closing twice or after an unplug is harmless."""
        with contextlib.suppress(OSError, serial.SerialException):
            self._serial.close()
