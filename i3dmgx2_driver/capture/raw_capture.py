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
The node's raw capture: every byte the reader reads, with its receive time.

The device layer calls :meth:`RawCapture.on_bytes` from the reader thread
right after each read, before parsing, so the capture holds exactly what
came off the port, garbage and all, and can be replayed into a
pseudo-terminal or decoded by a later parser (``tools``). A capture is a
convenience, never a reason to stop the driver: if the file cannot be
opened or written (disk full, permission, a size limit), that is logged
once and capture turns itself off while the stream goes on.
"""

from collections.abc import Callable
import contextlib
import os
import threading
from typing import Any

from .file_format import CaptureWriter, default_header
from .. import __version__


class _Writer(CaptureWriter):
    """
    A CaptureWriter whose background flush keeps its error instead of dying with it.

    The base class flushes from its own thread; an I/O error there would end
    that thread with a traceback and leave the reader to find out only when
    the buffer fills. Here the error is kept, and the next write reports it.
    """

    error: Exception | None = None

    def _flush_loop(self) -> None:
        try:
            super()._flush_loop()
        except (OSError, ValueError) as exc:
            self.error = exc


class RawCapture:
    """
    Write what the reader reads to ``path`` ('' or None: do nothing).

    ``log`` is any logger with ``info``/``error``. ``header`` values are
    added to the capture's header (port, address, baud, wireless...).
    """

    def __init__(self, path: str | None, log: Any, **header: Any) -> None:
        self.path = os.path.expanduser(path) if path else ''
        self._log = log
        self._writer: _Writer | None = None
        self._lock = threading.Lock()
        #: '' while fine (or off), else why capture stopped.
        self.error = ''
        if not self.path:
            return
        existed = os.path.exists(self.path)
        try:
            self._writer = _Writer(self.path, default_header(
                driver_version=__version__,
                notes='raw capture by the i3dmgx2_driver node: every read, as read', **header))
        except (OSError, ValueError) as exc:
            self._fail(f'cannot write the raw capture {self.path}: {exc}')
            return
        self._log.info(f'raw capture to {self.path}'
                       + (' (the existing file was overwritten)' if existed else ''))

    @property
    def active(self) -> bool:
        """Whether bytes are being written now."""
        return self._writer is not None

    def describe(self) -> str:
        """One line for diagnostics: off, the file and its size, or why it stopped."""
        writer = self._writer
        if writer is not None:
            return f'{self.path}: {writer.chunks} reads, {writer.bytes} bytes'
        return f'stopped: {self.error}' if self.error else 'off'

    def on_bytes(self, data: bytes, receive_time: float) -> None:
        """Store one read (called from the reader thread; never raises)."""
        writer = self._writer
        if writer is None:
            return
        try:
            if writer.error is not None:
                raise writer.error
            writer.write(data, receive_time)
        except (OSError, ValueError) as exc:
            self._fail(f'raw capture to {self.path} failed, capture is off: {exc}')

    def _fail(self, message: str) -> None:
        """Log once, stop writing, and let the file go (away from the reader thread)."""
        with self._lock:
            if self.error:
                return
            self.error = message
            writer, self._writer = self._writer, None
        self._log.error(message + '; the driver keeps running without it')
        if writer is not None:
            threading.Thread(target=self._close_quietly, args=(writer,),
                             name='gx2-capture-close', daemon=True).start()

    @staticmethod
    def _close_quietly(writer: CaptureWriter) -> None:
        with contextlib.suppress(OSError, ValueError):  # why it stopped was logged already
            writer.close()

    def close(self) -> None:
        """Flush and close the file (at shutdown, after the reader stopped)."""
        with self._lock:
            writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            if writer.error is not None:
                raise writer.error
            writer.close()
        except (OSError, ValueError) as exc:
            self.error = str(exc)
            self._log.error(f'raw capture to {self.path}: closing failed: {exc}')
            self._close_quietly(writer)


def bytes_sink(*sinks: Callable[[bytes, float], None] | None
               ) -> Callable[[bytes, float], None] | None:
    """
    Return one ``on_bytes`` callback that hands each read to every sink given.

    None when no sink is given (the reader then does nothing per read), the
    one sink itself when only one is, so that a single capture costs what it
    always did.
    """
    live = [sink for sink in sinks if sink is not None]
    if len(live) < 2:
        return live[0] if live else None

    def every(data: bytes, receive_time: float) -> None:
        for sink in live:
            sink(data, receive_time)
    return every
