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
Who answers on the link: the ping, the first polled requests, the identity.

The first words to a sensor after it was quieted: whether the base station
reaches it, a couple of polled requests (which make continuous mode
dependable later), and what it says it is. A silent sensor is told apart
here, with what the line carried instead, so that a configure transition
fails soon with the reason.
"""

from collections.abc import Callable

from . import timeouts
from .dialogue_parts import DialogueParts
from .identity import DeviceInfo, read_identity
from .link import DeviceLink, DeviceTimeout
from ..codec import layouts


def first_poll_code(stream: int) -> int:
    """
    Return what the first polled requests ask for: never the record being streamed.

    A sensor may still stream while the dialogue starts it in full (its stop
    lost on the radio, or streaming from power-up); a record of the stream
    that arrives while a poll of the same code waits is taken for its reply,
    so it is neither published nor the answer, and the real reply, coming
    next, is published in its place (found by the hour-long soak, stream
    ``inertial``). 0xC2, or the magnetometer alone (0xC7, no stream's
    record) when 0xC2 is the stream.
    """
    return layouts.MAGNETOMETER if stream == layouts.ACCEL_ANG_RATE else layouts.ACCEL_ANG_RATE


class Identification:
    """
    What the sensor at ``config.address`` answered and said it is.

    ``cancel`` set means the driver is stopping (an identity not read is
    then no reason to warn).
    """

    def __init__(self, parts: DialogueParts) -> None:
        self.config, self._log, self._warn, self._cancel = parts
        self.info: DeviceInfo | None = None
        self.ping_ok: bool | None = None
        self._info_logged: DeviceInfo | None = None

    def introduce(self, link: DeviceLink, require_answer: bool = False,
                  observed: Callable[[], str] = str) -> None:
        """Ping, make the polled requests, read the identity (see SensorDialogue.initialise)."""
        cfg = self.config
        if link.wireless:
            self.ping_ok = link.ping(timeout=timeouts.PING_TIMEOUT,
                                     retries=timeouts.PING_RETRIES)
            if not self.ping_ok:
                self._warn('ping', f'node {cfg.address} does not answer the base station '
                                   f'ping: check it is powered, its address (ros2 run '
                                   f'i3dmgx2_driver discover lists the nodes on the air) and '
                                   f'the radio channel', None)
        # The thesis author found continuous mode unreliable as the very first
        # command: a couple of polled requests first make it dependable.
        code = first_poll_code(cfg.stream)
        for _ in range(2):
            try:
                link.request(bytes((code,)), code, timeout=cfg.request_timeout, retries=2)
            except DeviceTimeout:
                pass
        if require_answer and not self.ping_ok and not link.heard:
            silent = (f'node {cfg.address} is silent: no answer to the base station '
                      f'ping or to polled requests (check it is powered, its address and the '
                      f'radio channel)' if link.wireless else
                      f'the sensor on {cfg.port} is silent: no answer to polled '
                      f'requests (check it is powered and the baud rate)')
            # What the line carried instead says what to change (address, framing, baud).
            seen = observed()
            raise DeviceTimeout(silent + (f'; observed on the line: {seen}' if seen else ''))
        self._identify(link)

    def _identify(self, link: DeviceLink) -> None:
        cfg = self.config
        info = read_identity(link, cfg.request_timeout, cfg.request_retries)
        if self._cancel.is_set():
            return
        if not any(info):
            self._warn('identity', 'the device did not tell its identity (0xEA, 0xE9): right '
                                   'port? ros2 run i3dmgx2_driver discover finds sensors', None)
            return
        self.info = info
        if info != self._info_logged:
            self._info_logged = info
            self._log.info(f'device: model {info.model_name or "?"} '
                           f'({info.model_number or "?"}), serial {info.serial_number or "?"}, '
                           f'firmware {info.firmware or "?"}, options {info.options or "-"}, '
                           f'node {cfg.address}')

    @property
    def serial_number(self) -> str:
        """Return the known sensor's serial number ('' while none is known)."""
        return self.info.serial_number if self.info is not None else ''

    def forget(self) -> None:
        """Drop the identity: another sensor answers as this node."""
        self.info = None
