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
What a sensor says it is: its identifier strings (0xEA) and firmware (0xE9).

One dialogue for everyone who asks (the supervisor at start-up and on a
reconnect, discovery when it probes a port), so that they cannot disagree on
how a reply is read. A reply to 0xEA echoes its selector: over the radio a
late reply to the previous selector can arrive while the next is asked, and it
must not pass for this one's.
"""

from collections.abc import Callable
from typing import NamedTuple

from .link import DeviceError, DeviceLink, EchoMismatch
from ..codec import commands, layouts

IDENTIFIER_NAMES = ('model_number', 'serial_number', 'model_name', 'options')
#: Device identifier selector of the serial number (0xEA).
SERIAL_NUMBER_SELECTOR = IDENTIFIER_NAMES.index('serial_number')


class DeviceInfo(NamedTuple):
    """What the device says it is."""

    model_number: str
    serial_number: str
    model_name: str
    options: str
    firmware: str


def read_identifier(link: DeviceLink, selector: int, timeout: float, retries: int) -> str:
    """
    Return identifier ``selector`` (0xEA), its padding stripped.

    Raises DeviceTimeout when the device does not answer it, or answers only
    for another selector.
    """
    for _ in range(retries):
        reply = link.request(commands.device_identifier(selector), layouts.DEVICE_IDENTIFIER,
                             timeout, retries)
        if reply.selector == selector:
            return reply.text.strip(' \x00')
    raise EchoMismatch(f'device identifier {selector}: only replies for other selectors')


def read_firmware(link: DeviceLink, timeout: float, retries: int) -> str:
    """Return the firmware version as the manual writes it; DeviceTimeout if unanswered."""
    return link.request(bytes((layouts.FIRMWARE_VERSION,)), layouts.FIRMWARE_VERSION,
                        timeout, retries).text


def read_identity(link: DeviceLink, timeout: float, retries: int) -> DeviceInfo:
    """Ask every identifier and the firmware; what goes unanswered is ''."""
    def answer(read: Callable[[], str]) -> str:
        try:
            return read()
        except DeviceError:
            return ''
    return DeviceInfo(*(answer(lambda s=s: read_identifier(link, s, timeout, retries))
                        for s in range(len(IDENTIFIER_NAMES))),
                      answer(lambda: read_firmware(link, timeout, retries)))
