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
What discovery needs of DeviceLink: one ping of any address, and retargeting.

A link moves from node to node (or listens to all) over one open port.

Against the simulated base station on its pseudo-terminal, and a bare
pseudo-terminal with nothing behind it.
"""

import os
import threading
import tty

from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.device.link import DeviceLink, DeviceTimeout, LinkOptions
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.device.sensor_steps import ping
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
import pytest

pytestmark = pytest.mark.slow


class Collected:
    """Every data packet the link hands over, by node address."""

    def __init__(self) -> None:
        self.by_address: dict[int | None, int] = {}
        self.lock = threading.Lock()

    def __call__(self, packet, now, mono) -> None:
        with self.lock:
            self.by_address[packet.address] = self.by_address.get(packet.address, 0) + 1


def open_link(path: str, address: int | None, on_record=None) -> DeviceLink:
    link = DeviceLink(SerialPort(path), address, on_record or (lambda p, t, m: None),
                      LinkOptions(select_timeout=0.05))
    link.start()
    return link


def close_link(link: DeviceLink) -> None:
    link.stop()
    link.port.close()


def test_ping_once_tells_present_absent_and_no_base_station():
    with PtySimulator(SimulatorConfig(address=42, seed=61)) as sim:
        link = open_link(sim.port, 1)
        try:
            assert link.ping_once(42, 0.5) is True
            assert link.ping_once(43, 0.5) is False
            assert ping(link) is False  # the link's own address, 1, is not there
        finally:
            close_link(link)
        pings = [(entry.address, entry.outcome) for entry in sim.host_log
                 if entry.kind == 'ping']
        assert pings == [(42, 'ping ok'), (43, 'ping failed'), (1, 'ping failed')]
    master, slave = os.openpty()
    tty.setraw(slave)
    link = open_link(os.ttyname(slave), 1)
    try:
        assert link.ping_once(42, 0.2) is None  # silence: no base station at all
        assert ping(link, timeout=0.1, retries=2) is False
    finally:
        close_link(link)
        os.close(slave)
        os.close(master)


def test_a_ping_answer_found_in_garbage_is_asked_again():
    # Another node streams and a flush cut one of its packets: the tail (0x02 among its
    # bytes) comes before the base station's real answer, 0x21, "node 12 is not there".
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    ping = cmd.ping(12)
    answers = [b'\x10\x02\x33\x21', b'\x21']
    asked = []

    def base_station() -> None:
        heard = b''
        while answers:
            heard += os.read(master, 64)
            while ping in heard:
                heard = heard.replace(ping, b'', 1)
                asked.append(ping)
                os.write(master, answers.pop(0))

    responder = threading.Thread(target=base_station, daemon=True)
    responder.start()
    link = open_link(os.ttyname(slave), 12)
    try:
        assert link.ping_once(12, 0.5) is False
        assert len(asked) == 2
    finally:
        close_link(link)
        responder.join(1.0)
        os.close(slave)
        os.close(master)


def test_retarget_moves_requests_to_another_node():
    with PtySimulator(SimulatorConfig(address=42, seed=62)) as sim:
        link = open_link(sim.port, 7)
        try:
            with pytest.raises(DeviceTimeout):
                link.request(bytes((lay.FIRMWARE_VERSION,)), lay.FIRMWARE_VERSION, 0.2, 1)
            link.retarget(42)
            assert link.request(bytes((lay.FIRMWARE_VERSION,)), lay.FIRMWARE_VERSION,
                                0.5, 3).version == 2113
            assert ping(link) is True
        finally:
            close_link(link)
        assert [(e.address, e.outcome) for e in sim.host_log if e.kind == 'packet'] == \
            [(7, 'other_address'), (42, 'delivered')]


def test_a_listening_link_takes_every_node_and_retarget_filters_again():
    # The sensor streams, and a second sensor's packets come in between.
    faults = FaultConfig(foreign_probability=0.5, foreign_address=1234)
    with PtySimulator(SimulatorConfig(address=42, seed=63, streaming_at_start=0xC2,
                                      faults=faults)) as sim:
        collected = Collected()
        link = open_link(sim.port, None, collected)
        try:
            assert sim.wait_until(lambda: sim.stats.foreign >= 5 and
                                  sim.stats.records_sent >= 5, timeout=10)
            assert link.parser.stats.foreign_frames == 0
            with collected.lock:
                assert set(collected.by_address) == {42, 1234}
            link.retarget(42)
            foreign_before = link.parser.stats.foreign_frames
            assert sim.wait_until(lambda: sim.stats.foreign >= 15, timeout=10)
            assert link.parser.stats.foreign_frames > foreign_before
            assert link.request(cmd.device_identifier(1), lay.DEVICE_IDENTIFIER,
                                0.5, 3).text.strip() == '3095'
        finally:
            close_link(link)
        assert sim.streaming == 0xC2
