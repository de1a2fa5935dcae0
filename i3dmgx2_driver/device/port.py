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
not theirs to open, is in use), because "could not open port" alone sends
people to the wrong fix. Reads return whatever bytes are waiting as soon as
any arrive, so the last byte of a packet reaches the parser without waiting
for a fixed read size or a polling interval.
"""

import errno
import os
import select
import termios
from typing import Any

import serial


class PortError(Exception):
    """The port could not be opened or used; the message says what to do."""


class PortMissing(PortError):
    """No device at the path (unplugged, or a wrong path)."""


class PortPermissionDenied(PortError):
    """The user may not open the device (usually: not in ``dialout``)."""


class PortBusy(PortError):
    """Another process holds the port."""


class PortDisconnected(PortError):
    """The device went away while open (unplugged, or the pty closed)."""


#: How much one read takes at most; a few packets' worth.
READ_SIZE = 4096


def _classify(path: str, exc: Exception) -> PortError:
    code = getattr(exc, 'errno', None)
    text = str(exc)
    if code == errno.ENOENT or 'No such file' in text:
        return PortMissing(f'serial port {path} does not exist: is the base station '
                           f'plugged in, and is the path right?')
    if code == errno.EACCES or 'Permission denied' in text:
        return PortPermissionDenied(
            f'permission denied opening {path}: add your user to the dialout group '
            f'(sudo usermod -aG dialout $USER, then log in again)')
    if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or 'lock' in text:
        return PortBusy(f'serial port {path} is in use by another process')
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
        try:
            self._serial = serial_factory(
                port=path, baudrate=baud, bytesize=serial.EIGHTBITS,
                parity=serial.PARITY_NONE, stopbits=serial.STOPBITS_ONE,
                xonxoff=False, rtscts=False, dsrdtr=False, timeout=0,
                write_timeout=1.0, exclusive=True)
        except (serial.SerialException, OSError) as exc:
            raise _classify(path, exc) from exc
        self.low_latency_state = 'off'
        if low_latency:
            self.low_latency_state = self._enable_low_latency()
        try:
            self._fd: int | None = self._serial.fileno()
        except (AttributeError, OSError, serial.SerialException):
            self._fd = None

    def _enable_low_latency(self) -> str:
        """Ask for low-latency mode; return 'on' or why it is not."""
        try:
            self._serial.set_low_latency_mode(True)
        except (NotImplementedError, AttributeError):
            return 'not supported on this platform'
        except (OSError, ValueError, serial.SerialException) as exc:
            return f'refused by the port ({exc.__class__.__name__})'
        return 'on'

    def read_some(self, timeout: float) -> bytes:
        """
        Wait up to ``timeout`` s for bytes; return all that are there.

        Returns b'' on a timeout. Raises PortDisconnected when the device is
        gone: a descriptor that is readable but gives no data, or an I/O error.
        """
        if self._fd is None:
            return self._read_portable(timeout)
        try:
            ready, _, _ = select.select([self._fd], [], [], timeout)
            if not ready:
                return b''
            data = os.read(self._fd, READ_SIZE)
        except (OSError, ValueError) as exc:
            raise PortDisconnected(f'{self.path}: {exc}') from exc
        if not data:
            raise PortDisconnected(f'{self.path}: device disconnected')
        return data

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
        try:
            self._serial.close()
        except (OSError, serial.SerialException):
            pass
