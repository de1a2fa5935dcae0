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
The hostile station's oracle: which records the node may publish, and which it must.

Decided by the bytes the node was given, not by what the station meant: every
data packet a fresh codec parser finds in them (reset whenever the node opens
the port) is allowed; every real record of the node's stream from the
station's address, forwarded whole while the station behaved, is owed. Not a
polled reply (the node takes those as replies and never publishes them), nor
a packet the pty took only in part (the station lost that one itself). Kept
apart from the forwarding (``hostile.py``) so that what counts as a finding
is read in one place.
"""

from harness.campaign_truth import imu_values
from i3dmgx2_driver.codec.framing import DataPacket, HEADER_SIZE
from i3dmgx2_driver.codec.parser import SensorStreamParser


class PublishOracle:
    """The keys (a record's values) allowed, owed and attacked, as the station forwards."""

    def __init__(self, address: int, stream: int) -> None:
        self.address = address
        #: The command byte of the record the node streams and publishes.
        self.stream = stream
        self._reference = SensorStreamParser(address=address)
        #: Keys a fresh parser found in the bytes the node was given: allowed to be published.
        self.allowed: set[bytes] = set()
        #: (time, key) of real records of the node's stream from our address, forwarded
        #: whole while behaving: each must be published.
        self.intact: list[tuple[float, bytes]] = []
        self.intact_keys: set[bytes] = set()
        #: Keys of real packets from our address that were attacked (never sent intact).
        self.attacked_keys: dict[bytes, str] = {}

    def port_opened(self) -> None:
        """Start the reference parser afresh: the node (re)opened the port, so did its parser."""
        self._reference = SensorStreamParser(address=self.address)

    def expect_ping(self) -> None:
        """Tell the reference parser a ping went out: its one-byte answer starts no packet."""
        self._reference.expect_ping()

    def given(self, data: bytes) -> None:
        """Note what the node was given: every record of our address in it is allowed."""
        for event in self._reference.feed(data):
            if isinstance(event, DataPacket) and event.address == self.address:
                values = imu_values(event.record)
                if values is not None:
                    self.allowed.add(values[0])

    def sent_whole(self, key: bytes) -> None:
        """Allow a real packet of ours sent whole (now, delayed or surrounded)."""
        self.intact_keys.add(key)

    def attacked(self, key: bytes, mode: str) -> None:
        """Note a real packet of ours that attack ``mode`` mutated: it never went out intact."""
        self.attacked_keys[key] = mode

    def owed(self, packet: bytes, key: bytes, written: int, now: float) -> None:
        """
        Owe a real packet of ours forwarded while behaving; ``written``: the bytes the pty took.

        Only a record of the stream is a sample to the node (a polled reply is
        not), and only one the pty took whole reached it.
        """
        if packet[HEADER_SIZE] == self.stream and written == len(packet):
            self.intact.append((now, key))
