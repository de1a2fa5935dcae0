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
Several sensors on one port, through the device layer alone (no ROS).

One supervisor per sensor, one shared port and reader: each sensor's
records reach its own consumer and no other's, its dialogue takes only its
own answers while the others stream, one sensor switched off is retried
while the others go on, and an unplug stops all and brings all back.
"""

import collections
import threading
import time

from i3dmgx2_driver.codec import commands, layouts
from i3dmgx2_driver.device.link import DeviceLink, LinkOptions, PortReader
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.device.sensor_steps import ping
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.device.shared_port import SharedPort
from i3dmgx2_driver.device.status import State
from i3dmgx2_driver.device.supervisor import DeviceSupervisor
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
import pytest

pytestmark = pytest.mark.slow


class Sink:
    """What the reader hands one sensor's consumer: the packets' addresses and timers."""

    def __init__(self) -> None:
        self.addresses: collections.Counter = collections.Counter()
        self.timers: list[int] = []
        self.lock = threading.Lock()

    def __call__(self, packet, read_time, read_mono) -> None:
        with self.lock:
            self.addresses[packet.address] += 1
            self.timers.append(packet.record.timer)

    @property
    def count(self) -> int:
        return sum(self.addresses.values())


def wait(predicate, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def supervisors(sim: PtySimulator, addresses, **config):
    base = DeviceConfig(port=sim.port, address=addresses[0], low_latency=False,
                        reconnect_interval=0.3, **config)
    shared = SharedPort(base, log=_Log())
    out = {}
    for address in addresses:
        sink = Sink()
        cfg = DeviceConfig(**{**base.__dict__, 'address': address})
        out[address] = (DeviceSupervisor(cfg, sink, log=_Log(), shared=shared), sink)
    return shared, out


class _Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def _say(self, text: str) -> None:
        self.lines.append(str(text))

    debug = info = warning = error = fatal = _say


def test_each_sensor_gets_its_own_records_from_one_port():
    config = SimulatorConfig(addresses=(17, 95, 40), seed=11,
                             faults=FaultConfig(already_streaming=True))
    with PtySimulator(config) as sim:
        shared, sups = supervisors(sim, (17, 95, 40))
        for sup, _ in sups.values():
            sup.start()
        try:
            assert wait(lambda: all(s.status().state is State.STREAMING for s, _ in sups.values()))
            assert wait(lambda: all(sink.count > 100 for _, sink in sups.values()))
            for address, (_, sink) in sups.items():
                assert set(sink.addresses) == {address}
                truth = {t.timer for t in sim.truth if t.address == address}
                assert set(sink.timers) <= truth
            serials = {sup.status().info.serial_number for sup, _ in sups.values()}
            assert len(serials) == 3  # each dialogue read its own sensor's identity
            assert shared.opens == 1
        finally:
            for sup, _ in sups.values():
                sup.stop()
        assert shared.reader is None  # the last one out closed the port


def test_one_sensor_off_is_retried_while_the_others_stream():
    with PtySimulator(SimulatorConfig(addresses=(17, 95), seed=12)) as sim:
        sim.power_cycle(off_seconds=4.0, address=17)
        _, sups = supervisors(sim, (17, 95))
        for sup, _ in sups.values():
            sup.start()
        try:
            off, on = sups[17], sups[95]
            assert wait(lambda: on[1].count > 50, 10.0)
            assert off[1].count == 0 and off[0].status().state is not State.STREAMING
            start = on[1].count
            time.sleep(1.0)
            assert on[1].count - start > 60  # 95 never paused for 17's retries
            assert wait(lambda: off[1].count > 20, 15.0)  # 17 back on: found and streaming
            assert set(off[1].addresses) == {17} and set(on[1].addresses) == {95}
        finally:
            for sup, _ in sups.values():
                sup.stop()


def test_an_unplug_stops_all_and_brings_all_back():
    config = SimulatorConfig(addresses=(17, 95), seed=13,
                             faults=FaultConfig(already_streaming=True))
    with PtySimulator(config) as sim:
        shared, sups = supervisors(sim, (17, 95))
        for sup, _ in sups.values():
            sup.start()
        try:
            assert wait(lambda: all(sink.count > 50 for _, sink in sups.values()))
            sim.unplug(1.0)
            counts = {a: sink.count for a, (_, sink) in sups.items()}
            assert sim.pty.plugged.wait(5.0)
            assert wait(lambda: all(sink.count > counts[a] + 50
                                    for a, (_, sink) in sups.items()), 15.0)
            assert shared.opens == 2
            assert all(sup.status().reconnects >= 1 for sup, _ in sups.values())
        finally:
            for sup, _ in sups.values():
                sup.stop()


def test_a_reply_is_taken_only_from_its_own_sensor():
    """A request to 95 while 17 streams the same record: 17's packets are no answer."""
    config = SimulatorConfig(addresses=(17, 95), seed=14)
    with PtySimulator(config) as sim:
        port = SerialPort(sim.port, low_latency=False)
        reader = PortReader(port, None)
        got = {17: [], 95: []}
        links = {a: DeviceLink(port, a, lambda p, t, m, a=a: got[a].append(p),
                               LinkOptions(), reader=reader) for a in (17, 95)}
        try:
            for link in links.values():
                link.start()
            links[17].set_streamed(layouts.ACCEL_ANG_RATE)
            links[17].request(commands.set_continuous(layouts.ACCEL_ANG_RATE),
                              layouts.SET_CONTINUOUS)
            assert wait(lambda: len(got[17]) > 20)
            sim.stall(2.0, address=95)
            before = len(got[17])
            with pytest.raises(Exception, match='no reply'):
                links[95].request(bytes((layouts.ACCEL_ANG_RATE,)), layouts.ACCEL_ANG_RATE,
                                  timeout=0.3, retries=2)
            assert len(got[17]) > before + 30
            assert not links[95].heard and not got[95]
            assert ping(links[95], timeout=0.3, retries=1) is False
        finally:
            for link in links.values():
                link.stop()
            reader.stop()
            port.close()
