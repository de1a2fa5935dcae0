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
Several sensors behind one simulated base station, seen from the host side.

Each sensor streams its own records (its own serial number, clock and
motion), their packets interleave whole on the line, commands and pings go
to the sensor they name, and the faults hit one sensor while the others
stream on.
"""

from itertools import pairwise
import time

from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.records import DeviceIdentifier, PingReply
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from test_simulator import Host

pytestmark = pytest.mark.slow

ADDRESSES = (17, 95)


def by_address(host: Host) -> dict[int, list]:
    out: dict[int, list] = {}
    for packet in host.packets:
        out.setdefault(packet.address, []).append(packet.record)
    return out


def test_each_sensor_streams_its_own_records_interleaved_with_the_others():
    # 2 x 0xCC at 50 Hz: 8,800 bytes/s, within the line's 11,520.
    config = SimulatorConfig(addresses=ADDRESSES, streaming_at_start=True, seed=3,
                             divider=1024)
    with PtySimulator(config) as sim, Host(sim, address=None) as host:
        host.pump(2.0)
        seen = by_address(host)
        assert set(seen) == set(ADDRESSES)
        for address in ADDRESSES:
            truth = [t.record for t in sim.truth if t.address == address and t.valid]
            assert len(seen[address]) >= 80
            # What the host got from each address is exactly what that sensor sent.
            assert all(record in truth for record in seen[address])
        # Two clocks, two motions: no record of one sensor is another's.
        assert not {r.timer for r in seen[17]} & {r.timer for r in seen[95]}
        order = [p.address for p in host.packets]
        assert sum(1 for a, b in pairwise(order) if a != b) > 50  # interleaved


def test_sensors_that_together_overload_the_line_lose_packets_at_the_base_station():
    # 2 x 0xCC at 100 Hz: 17,600 bytes/s for a line of 11,520.
    config = SimulatorConfig(addresses=ADDRESSES, streaming_at_start=True, seed=6)
    with PtySimulator(config) as sim, Host(sim, address=None) as host:
        host.pump(0.5)
        start = time.time()
        before = len(host.packets)
        host.pump(2.0)
        bytes_per_second = 88 * (len(host.packets) - before) / (time.time() - start)
        assert 9000 < bytes_per_second < 11520 * 1.05
        assert sim.stats.line_rate_skipped > 100
        lost = {t.address for t in sim.truth if t.fault == 'line_rate'}
        assert lost == set(ADDRESSES)


def test_commands_and_pings_reach_the_sensor_they_name():
    with PtySimulator(SimulatorConfig(addresses=(17, 95, 40), seed=4)) as sim, \
            Host(sim, address=None) as host:
        serials = {}
        for address in sim.addresses:
            host.send(cmd.device_identifier(1), address=address)
            assert host.pump_until(lambda a=address: any(
                p.address == a and isinstance(p.record, DeviceIdentifier)
                for p in host.packets), 3.0)
            serials[address] = next(p.record.text for p in host.packets
                                    if p.address == address
                                    and isinstance(p.record, DeviceIdentifier))
        assert len(set(serials.values())) == 3
        host.parser.expect_ping()
        host.serial.write(cmd.ping(40))
        assert host.pump_until(lambda: host.count(PingReply), 2.0)
        assert [e for _, e in host.events if isinstance(e, PingReply)][-1].ok
        host.parser.expect_ping()
        host.serial.write(cmd.ping(41))
        assert host.pump_until(lambda: host.count(PingReply) == 2, 2.0)
        assert not [e for _, e in host.events if isinstance(e, PingReply)][-1].ok


def test_one_sensor_stalled_and_one_switched_off_while_the_third_streams():
    # 3 x 0xCC at 40 Hz: 10,560 bytes/s, within the line.
    config = SimulatorConfig(addresses=(17, 95, 40), streaming_at_start=True, seed=5,
                             divider=1280)
    with PtySimulator(config) as sim, Host(sim, address=None) as host:
        host.pump(0.3)
        sim.stall(1.0, address=17)
        sim.power_cycle(off_seconds=1.0, address=95)
        start = len(host.packets)
        host.pump(0.8)
        quiet = [p.address for p in host.packets[start:]]
        # At most what was on its way when the fault came.
        assert quiet.count(17) <= 3 and quiet.count(95) <= 3
        assert quiet.count(40) >= 25
        host.pump(1.0)
        back = {p.address for p in host.packets[start + len(quiet):]}
        assert 17 in back  # the stall is over; the power-cycled one polls until asked
        host.send(cmd.set_continuous(lay.ACCEL_ANG_RATE), address=95)
        assert host.pump_until(lambda: any(
            p.address == 95 for p in host.packets[start + len(quiet):]), 3.0)


def test_several_sensors_need_a_base_station_and_distinct_addresses():
    with pytest.raises(ValueError, match='base station'):
        SimulatorConfig(addresses=(17, 95), wireless=False)
    with pytest.raises(ValueError, match='differ'):
        SimulatorConfig(addresses=(17, 17))
    with pytest.raises(ValueError, match='fault_address'):
        SimulatorConfig(addresses=(17, 95), fault_address=3)
