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
How a sensor's port is opened, the same for a port of its own and a shared one.

A connection that opens its own port and the port several sensors share
(shared_port.py) open it the same way: the configured path, baud rate and
low-latency mode, the low-latency mode logged when it changes, and the
reader made with the same raw capture and scheduling. :class:`PortOpener` does it, once for both.
"""

from collections.abc import Callable
import threading
from typing import Any

from .link import BytesCallback, LinkOptions
from .observer import LineObserver
from .port import SerialPort
from .settings import DeviceConfig


class PortOpener:
    """
    Open the port at ``config.port``; log a change of its low-latency mode.

    ``on_bytes``, if given, receives every read's raw bytes (a raw capture)
    from the reader of each port opened.
    """

    def __init__(self, config: DeviceConfig, log: Any,
                 on_bytes: BytesCallback | None = None) -> None:
        self.config = config
        self._on_bytes = on_bytes
        self._log = log
        #: What the last port opened granted of low-latency mode ('' before one).
        self.low_latency_state = ''

    def open_port(self) -> SerialPort:
        """Open the port (raises PortError); tell the observer; log a new low-latency mode."""
        cfg = self.config
        port = SerialPort(cfg.port, cfg.baud, low_latency=cfg.low_latency)
        if port.low_latency_state != self.low_latency_state:
            self.low_latency_state = port.low_latency_state
            self._log.info(f'{cfg.port}: low-latency mode {port.low_latency_state}')
        return port

    def reader_options(self, observer: LineObserver | None = None,
                       cancel: threading.Event | None = None,
                       records_of: int | None = None,
                       on_lost: Callable[[], None] | None = None) -> LinkOptions:
        """Return how the port's reader reads, whom it tells, what its link's consumer takes."""
        return LinkOptions(wireless=self.config.wireless, on_bytes=self._on_bytes,
                           observer=observer, cancel=cancel, records_of=records_of,
                           thread_policy=self.config.thread_policy, on_lost=on_lost)
