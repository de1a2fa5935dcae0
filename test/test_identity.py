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

"""The identity dialogue (0xEA, 0xE9) shared by the supervisor and discovery."""

from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.codec.records import DeviceIdentifier, FirmwareVersion
from i3dmgx2_driver.device.identity import (
    DeviceInfo, read_firmware, read_identifier, read_identity, SERIAL_NUMBER_SELECTOR,
)
from i3dmgx2_driver.device.link import DeviceTimeout, EchoMismatch
import pytest


class ScriptedLink:
    """Answers each request with the next reply of a script (an exception is raised)."""

    def __init__(self, replies: list) -> None:
        self.replies = list(replies)
        self.sent: list[bytes] = []

    def request(self, command: bytes, code: int, timeout: float, retries: int):
        self.sent.append(command)
        reply = self.replies.pop(0)
        if isinstance(reply, Exception):
            raise reply
        return reply


def ident(selector: int, text: str) -> DeviceIdentifier:
    return DeviceIdentifier(selector, text.ljust(16))


def test_a_late_reply_for_another_selector_is_not_taken_for_this_one():
    link = ScriptedLink([ident(0, '3DM-GX2'), ident(1, '3095')])
    assert read_identifier(link, SERIAL_NUMBER_SELECTOR, 0.1, 3) == '3095'
    assert link.sent == [bytes((layouts.DEVICE_IDENTIFIER, 1))] * 2


def test_only_replies_for_other_selectors_is_no_answer():
    link = ScriptedLink([ident(0, 'x')] * 3)
    with pytest.raises(EchoMismatch, match='other selectors'):
        read_identifier(link, 1, 0.1, 3)


def test_identity_leaves_what_goes_unanswered_empty():
    link = ScriptedLink([ident(0, '3DM-GX2'), DeviceTimeout('lost'), ident(2, 'GX2 Wireless\x00'),
                         ident(3, '5g'), FirmwareVersion(2103)])
    assert read_identity(link, 0.1, 1) == DeviceInfo('3DM-GX2', '', 'GX2 Wireless', '5g',
                                                     '2.1.03')


def test_firmware_unanswered_raises():
    with pytest.raises(DeviceTimeout):
        read_firmware(ScriptedLink([DeviceTimeout('lost')]), 0.1, 1)
