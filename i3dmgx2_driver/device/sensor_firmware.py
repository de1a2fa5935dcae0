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
One sensor's firmware as the node holds it: read with the identity, asked before a gated command.

Which firmware answers which command is the codec's (codec/command_firmware.py
reads the layout table). The dialogue reads the firmware (0xE9) with the
identity, before anything that depends on it is sent, and keeps it here
for each sensor: the stream is checked at once (:func:`check_stream`), the
temperature poller and the bias store ask :meth:`SensorFirmware.refusal`
before they send. Where 0xE9 goes unanswered the driver goes on as it did
before it read the firmware at all, and says once that it could not check.
"""

from .port import PortUnusable
from ..codec import command_firmware as fw
from ..codec import streams


class FirmwareLacksStream(PortUnusable):
    """
    The sensor's firmware cannot stream the record asked for: say so once and stop.

    A PortUnusable, since retrying cannot help (the sensor would answer the
    request for that stream never): the plain node exits with code 2, as for
    a bad parameter, and a managed node's configure fails with the words.
    """


class SensorFirmware:
    """One sensor's firmware as 0xE9 reported it: ``version`` None while unknown."""

    def __init__(self) -> None:
        self.version: int | None = None

    def learn(self, written: str) -> None:
        """Keep the firmware the identity read (``''``: unanswered)."""
        self.version = fw.version_of(written)

    def refusal(self, what: str, code: int) -> str:
        """Say why ``what`` (command ``code``) cannot be asked of this sensor; '' when it can."""
        return fw.refusal(what, code, self.version)


def check_stream(version: int | None, code: int, address: int) -> None:
    """Raise FirmwareLacksStream when firmware ``version`` cannot stream record ``code``."""
    why = fw.stream_refusal(streams.BY_CODE[code], version)
    if why:
        raise FirmwareLacksStream(f'node {address}: stream {why} (the stream parameter chooses)')
