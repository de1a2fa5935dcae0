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
The wired simulator (``SimulatorConfig(wireless=False)``), and the wrong framing both ways.

A wired 3DM-GX2 takes raw command bytes and answers ``echo | data | checksum``; it
sends no ACK, answers no ping, and ignores (counts) every byte that is not part of a
command it knows. The wireless base station takes only packets and pings. Each test
reads the port with pyserial and the codec, and checks the bytes against the ground
truth and against values worked out by hand from docs/protocol.md §2.
"""

from itertools import pairwise
import os
import time

from harness.decoders import decode_wired_record
from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import (
    DataPacket, encode_command_packet, encode_record, SensorStreamParser,
)
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.codec.framing import encode_wired_record
from i3dmgx2_driver.codec.parser import CommandStreamParser, RawCommand
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.sensor import STREAMABLE, WIRED_COMMANDS
import pytest
from test_simulator import ADDRESS, code_of, Host, same_record, ticks_per_cycle

CC = lay.ACCEL_ANG_RATE_MAG_ORIENTATION


def wired(seed: int = 31, **config) -> PtySimulator:
    faults = config.pop('faults', None) or FaultConfig()
    return PtySimulator(SimulatorConfig(wireless=False, seed=seed, faults=faults, **config))


def assert_wired_host_saw_exactly_valid_truth(host: Host, sim: PtySimulator) -> None:
    """
    Every valid truth entry, and nothing else, reached the wired parser, in order.

    Records written before the host opened the port (a sensor streaming from
    power-up) may have been flushed by the open: those, and only those, may be
    missing. Begun before is enough: the open may flush a record's first chunks
    and leave its tail, when the writer was descheduled between them.
    """
    valid = [t for t in sim.truth if t.valid]
    got = host.packets
    if got and valid:
        first = encode_record(got[0].record)
        start = next(i for i, t in enumerate(valid) if encode_record(t.record) == first)
        assert all(t.first_write_time < host.opened for t in valid[:start])
        valid = valid[start:]
    assert len(got) == len(valid), (len(got), len(valid))
    for packet, truth in zip(got, valid, strict=True):
        assert packet.address is None and packet.lqi is None
        assert same_record(packet.record, truth.record)
        assert truth.packet == encode_wired_record(encode_record(truth.record))


def stop_wired_stream(host: Host) -> None:
    host.send(cmd.stop_continuous())
    assert host.sim.wait_until(lambda: not host.sim.streaming, 3.0)
    host.drain()


def test_the_wired_sensor_reader_knows_every_command_but_the_ping():
    assert set(lay.LAYOUTS) - {lay.PING} == WIRED_COMMANDS
    reader = CommandStreamParser(wireless=False, codes=WIRED_COMMANDS)
    # A packet for 0xE5 whose length byte (0x02 stands in for it) would start a false
    # ping in a reader that knew 0x02, swallowing the 0xE5 behind it.
    stream = bytes.fromhex('AA0B00005F 02 00 E500FCA2 0203') + cmd.ping(95)
    assert reader.feed(stream) == [RawCommand(cmd.read_eeprom(0xFCA2))]
    assert reader.stats.bytes_skipped == len(stream) - 4
    assert CommandStreamParser(wireless=False).feed(stream)[0] == RawCommand(b'\x02\x00\xe5')


# -- the wired framing, byte for byte ------------------------------------------------------

@pytest.mark.slow
def test_wired_polled_replies_are_byte_exact():
    with wired() as sim, Host(sim) as host:
        assert not host.wireless
        # Worked out by hand from docs/protocol.md §2: echo, data, then the sum of all of them.
        host.send(cmd.encode_command(lay.FIRMWARE_VERSION))
        assert host.pump_until(lambda: len(host.raw) >= 7)
        assert bytes(host.raw) == bytes.fromhex('E9 00000841 0132')   # 2113, 0xE9+0x08+0x41
        host.send(cmd.read_eeprom(0xFCA2))
        assert host.pump_until(lambda: len(host.raw) >= 12)
        assert bytes(host.raw[7:]) == bytes.fromhex('E5 0200 00E7')    # divider 512
        host.drain()
        # Every other command with a reply: the table's wired size, a correct checksum,
        # and exactly the bytes the ground truth says were written.
        requests = [cmd.encode_command(code) for code in sorted(STREAMABLE)] + [
            cmd.device_identifier(s) for s in range(4)] + [
            cmd.write_eeprom(0x0D0A, 0x1311), cmd.read_eeprom(0x0D0A), cmd.built_in_test(0x14),
            cmd.write_accel_bias((0.01, 0.0, -0.01)), cmd.transfer_to_non_volatile(1),
            cmd.set_continuous(0)]
        for request in requests:
            start = len(host.raw)
            record = host.request(request, code=request[0])
            host.drain(quiet=0.05)
            reply = bytes(host.raw[start:])
            assert len(reply) == lay.LAYOUTS[request[0]].wired_size, hex(request[0])
            assert sum(reply[:-2]) & 0xFFFF == int.from_bytes(reply[-2:], 'big')
            assert same_record(decode_wired_record(reply), record)
            assert reply == sim.truth[-1].packet and sim.truth[-1].valid
        assert host.parser.stats.bytes_skipped == 0 and host.parser.stats.checksum_failures == 0
        assert sim.stats.acks == sim.stats.nacks == 0
        log = sim.host_log
        assert {entry.kind for entry in log} == {'wired'}
        assert all(entry.outcome == 'delivered' and entry.address is None for entry in log)
        assert [entry.command for entry in log] == [
            cmd.decode_command(raw) for raw in [
                cmd.encode_command(lay.FIRMWARE_VERSION), cmd.read_eeprom(0xFCA2), *requests]]
        assert sim.commands_of(lay.WRITE_EEPROM) == sim.eeprom_writes()
        assert [c.args for _, c in sim.eeprom_writes()] == [(0x0D0A, 0x1311)]


@pytest.mark.slow
@pytest.mark.parametrize('code', sorted(STREAMABLE), ids=lambda c: f'0x{c:02X}')
def test_wired_stream_of_every_streamable_record(code):
    with wired(divider=256, streaming_at_start=code) as sim, Host(sim) as host:
        assert sim.streaming == code
        assert host.pump_until(lambda: len(host.records(code)) >= 6)
        stop_wired_stream(host)
        records = host.records(code)
        assert all(code_of(p.record) == code for p in host.packets)
        assert_wired_host_saw_exactly_valid_truth(host, sim)
        assert all(len(t.packet) == lay.LAYOUTS[code].wired_size for t in sim.truth)
        step = ticks_per_cycle(256)
        assert all(abs((b.timer - a.timer) % 2**32 - step) <= 1 for a, b in pairwise(records))
        assert sim.eeprom[0xFCA6] == code, 'wired auto-start word: MSB 0x00'


@pytest.mark.slow
def test_wired_stream_on_request_and_the_record_of_it():
    with wired() as sim, Host(sim) as host:
        reply = host.request(cmd.set_continuous(lay.ACCEL_ANG_RATE), code=lay.SET_CONTINUOUS)
        assert reply.command == lay.ACCEL_ANG_RATE
        assert host.pump_until(lambda: len(host.records(lay.ACCEL_ANG_RATE)) >= 5)
        stop_wired_stream(host)
        host.request(cmd.set_continuous(lay.ACCEL_ANG_RATE), code=lay.SET_CONTINUOUS)
        assert host.pump_until(lambda: len(host.records(lay.ACCEL_ANG_RATE)) >= 8)
        stop_wired_stream(host)
        assert_wired_host_saw_exactly_valid_truth(host, sim)
        # The record of the host's doing: stream started, stopped, restarted, stopped.
        assert [code for _, code in sim.stream_changes] == [0, 0xC2, 0, 0xC2, 0]
        assert [c.code for _, c in sim.commands] == [0xC4, 0xFA, 0xC4, 0xFA]
        assert sim.eeprom_writes() == []
        times = [t for t, _ in sim.stream_changes[1:]]
        assert times == [t for t, _ in sim.commands]


@pytest.mark.slow
def test_wired_sensor_sends_no_ack_and_answers_no_ping():
    with wired() as sim, Host(sim) as host:
        host.serial.write(cmd.ping(ADDRESS))
        host.parser.expect_ping()
        host.drain(quiet=0.3)
        assert host.raw == b'' and host.events == []
        assert sim.host_log == [] and sim.commands == []
        assert sim.stats.pings == sim.stats.acks == 0
        assert sim.wait_until(lambda: sim.stats.host_bytes_ignored == 3, 2.0)


@pytest.mark.slow
def test_packets_to_a_wired_sensor_get_wired_answers_to_the_commands_inside():
    """A driver set to wireless:=true on a wired sensor: no ACK, wired replies only."""
    with wired() as sim, Host(sim, wireless=True) as host:
        polled = encode_command_packet(ADDRESS, cmd.encode_command(lay.ACCEL_ANG_RATE))
        assert polled.hex() == 'aa0b00005f0200c2012e'
        host.serial.write(polled)
        assert sim.wait_until(lambda: sim.stats.replies_sent == 1, 3.0)
        host.drain(quiet=0.2)
        # The sensor found the byte 0xC2 among the packet's ten and answered it, wired.
        assert bytes(host.raw) == sim.truth[0].packet
        assert len(host.raw) == lay.LAYOUTS[lay.ACCEL_ANG_RATE].wired_size
        assert host.packets == [], 'a wireless parser finds no data packet in a wired reply'
        assert sim.stats.acks == 0
        assert sim.stats.host_bytes_ignored == len(polled) - 1
        entry, = sim.host_log
        assert (entry.kind, entry.raw, entry.outcome) == ('wired', b'\xc2', 'delivered')
        # Continuous mode inside a packet: its four bytes are whole, so the sensor streams,
        # wired; the wireless driver sees none of it as data packets.
        host.serial.write(encode_command_packet(ADDRESS, cmd.set_continuous(CC)))
        assert sim.wait_until(lambda: sim.streaming == CC, 3.0)
        host.pump(0.2)
        assert host.packets == []
        # 0xFA in a packet stops it.
        host.serial.write(encode_command_packet(ADDRESS, cmd.stop_continuous()))
        assert sim.wait_until(lambda: not sim.streaming, 3.0)
        # The 0xC4 packet's checksum is 02 E9, and 0xE9 is a command too: the sensor
        # answered a firmware-version request nobody meant to send.
        assert encode_command_packet(ADDRESS, cmd.set_continuous(CC))[-2:] == b'\x02\xe9'
        assert [c.code for _, c in sim.commands] == [0xC2, 0xC4, 0xE9, 0xFA]


@pytest.mark.slow
def test_raw_commands_to_the_wireless_base_station_are_ignored():
    """A driver set to wireless:=false on a base station: no answers at all."""
    with PtySimulator(SimulatorConfig(seed=32)) as sim, Host(sim, wireless=False) as host:
        sent = b''.join((cmd.encode_command(lay.FIRMWARE_VERSION), cmd.read_eeprom(0xFCA2),
                         cmd.set_continuous(CC), cmd.encode_command(CC)))
        host.serial.write(sent)
        assert sim.wait_until(lambda: sim.stats.host_bytes_ignored == len(sent), 3.0)
        host.drain(quiet=0.3)
        assert host.raw == b''
        assert sim.host_log == [] and sim.commands == [] and sim.streaming == 0
        assert sim.stats.acks == sim.stats.nacks == 0


@pytest.mark.slow
def test_a_raw_host_hears_a_base_station_that_already_streams_but_cannot_stop_it():
    config = SimulatorConfig(seed=33, streaming_at_start=lay.ACCEL_ANG_RATE)
    with PtySimulator(config) as sim, Host(sim, wireless=False) as host:
        host.send(cmd.stop_continuous())
        host.send(cmd.stop_continuous())
        host.pump(0.3)
        assert sim.streaming == lay.ACCEL_ANG_RATE
        assert sim.stats.host_bytes_ignored == 2 and sim.commands == []
        listener = SensorStreamParser(ADDRESS)
        heard = [e for e in listener.feed(bytes(host.raw)) if isinstance(e, DataPacket)]
        assert len(heard) >= 10
        assert all(code_of(e.record) == lay.ACCEL_ANG_RATE for e in heard)


# -- faults that make sense on a wire --------------------------------------------------------

@pytest.mark.slow
def test_wired_refuses_the_radio_faults():
    for name in ('nack_probability', 'foreign_probability', 'corrupt_length_probability',
                 'command_loss_probability'):
        with pytest.raises(ValueError, match=name):
            SimulatorConfig(wireless=False, faults=FaultConfig(**{name: 0.1}))
    with wired() as sim:
        with pytest.raises(ValueError, match='nack_probability'):
            sim.set_faults(nack_probability=0.5)
        assert sim.faults.nack_probability == 0.0


@pytest.mark.slow
def test_wired_drop_garbage_and_corrupt_checksum():
    faults = FaultConfig(drop_probability=0.15, garbage_probability=0.3,
                         corrupt_checksum_probability=0.15, garbage_max_bytes=10)
    with wired(faults=faults, divider=256, streaming_at_start=CC) as sim, Host(sim) as host:
        host.pump(0.6)
        stop_wired_stream(host)
        truth = sim.truth
        stats = sim.stats
        dropped = [t for t in truth if t.fault == 'dropped']
        corrupted = [t for t in truth if t.fault == 'checksum']
        assert len(dropped) >= 3 and len(corrupted) >= 3 and stats.garbage_bursts >= 3
        assert all(t.write_time is None for t in dropped)
        assert stats.corrupted_checksum == len(corrupted)
        # The wired framing has no start byte: after a bad record the parser tries each
        # following byte that looks like an echo byte, so it counts more failures than
        # there were bad records, yet every good record comes through, and nothing else.
        assert host.parser.stats.checksum_failures >= len(corrupted)
        assert host.parser.stats.bytes_skipped >= stats.garbage_bytes + len(corrupted)
        assert_wired_host_saw_exactly_valid_truth(host, sim)


@pytest.mark.slow
def test_safe_wired_garbage_is_skipped_byte_for_byte():
    faults = FaultConfig(garbage_probability=0.5, garbage_max_bytes=12)
    with wired(faults=faults, divider=256) as sim, Host(sim) as host:
        host.request(cmd.set_continuous(CC), code=lay.SET_CONTINUOUS)
        host.pump(0.4)
        stop_wired_stream(host)
        assert sim.stats.garbage_bursts > 10
        # Safe wired garbage holds no echo byte: the parser skips exactly it.
        assert host.parser.stats.bytes_skipped == sim.stats.garbage_bytes
        assert host.parser.stats.checksum_failures == 0
        assert_wired_host_saw_exactly_valid_truth(host, sim)


@pytest.mark.slow
def test_wired_stall_silences_the_sensor_both_ways():
    with wired(streaming_at_start=lay.ACCEL_ANG_RATE) as sim, Host(sim) as host:
        assert host.pump_until(lambda: len(host.packets) >= 3)
        sim.stall(0.5)
        host.send(cmd.encode_command(lay.FIRMWARE_VERSION))
        assert sim.wait_until(lambda: sim.stats.commands_lost == 1, 2.0)
        assert sim.host_log[-1].outcome == 'stalled'
        assert host.pump_until(lambda: any(t.fault == 'stall' for t in sim.truth))
        time.sleep(0.6)
        count = len(sim.truth)
        assert host.pump_until(lambda: len(sim.truth) > count + 3)
        stop_wired_stream(host)
        assert_wired_host_saw_exactly_valid_truth(host, sim)
        assert host.records(lay.FIRMWARE_VERSION) == []


@pytest.mark.slow
def test_unplugging_a_wired_sensor_powers_it_off_and_back_up():
    config = {'streaming_at_start': lay.ACCEL_ANG_RATE, 'timer_start': 1000}
    with wired(**config) as sim:
        with Host(sim) as host:
            assert host.pump_until(lambda: len(host.packets) >= 3)
        sim.unplug()
        assert not os.path.exists(sim.port)
        assert sim.streaming == 0
        time.sleep(0.2)
        unplugged = time.time()
        assert sim.replug()
        with Host(sim) as host:
            assert host.pump_until(lambda: len(host.packets) >= 3)
            stop_wired_stream(host)
            first = host.records(lay.ACCEL_ANG_RATE)[0]
        # Powered up again at the replug: the auto-start streams, the timer starts
        # from timer_start again.
        power_up = sim.sensor.clock.power_up_time
        assert power_up >= unplugged
        truth = next(t for t in reversed(sim.truth) if t.timer == first.timer)
        elapsed = truth.sample_time - power_up
        assert abs(first.timer - (1000 + elapsed * rec.TICKS_PER_SECOND * (1 + 40e-6))) <= 1
        assert [code for _, code in sim.stream_changes] == [0xC2, 0, 0xC2, 0]
        assert sim.stats.unplugs == 1
        # Off, so nothing is sent meanwhile (one record may have been on its way).
        assert len([t for t in sim.truth if t.fault == 'unplugged']) <= 1


@pytest.mark.slow
def test_wired_already_streaming_line_rate_and_wire_time():
    faults = FaultConfig(already_streaming=True)
    with wired(faults=faults, divider=170, limit_to_line_rate=True) as sim, Host(sim) as host:
        assert sim.streaming == CC
        host.pump(0.5)
        stop_wired_stream(host)
        truth = [t for t in sim.truth if t.source == 'stream']
        sent = [t for t in truth if t.fault is None]
        skipped = [t for t in truth if t.fault == 'line_rate']
        # 301 Hz of 79-byte records is 23.8 kB/s: about half do not fit 11.52 kB/s.
        assert sim.stats.line_rate_skipped == len(skipped) > 0.3 * len(truth)
        assert len(sent) > 0.3 * len(truth)
        wire_time = 79 * 10 / 115200
        assert all(t.write_time - t.sample_time >= wire_time for t in sent)
        assert_wired_host_saw_exactly_valid_truth(host, sim)


# -- side by side ----------------------------------------------------------------------------

@pytest.mark.slow
def test_two_simulators_side_by_side_one_wired():
    radio = PtySimulator(SimulatorConfig(address=95, seed=34,
                                         streaming_at_start=lay.ACCEL_ANG_RATE))
    cable = PtySimulator(SimulatorConfig(address=42, wireless=False, seed=35,
                                         streaming_at_start=lay.EULER_ANGLES_ANG_RATE))
    with radio, cable, Host(radio, address=95) as wireless_host, \
            Host(cable, address=42) as wired_host:
        assert radio.port != cable.port
        assert wireless_host.request(cmd.encode_command(lay.FIRMWARE_VERSION)).version == 2113
        assert wired_host.request(cmd.encode_command(lay.FIRMWARE_VERSION)).version == 2113
        wireless_host.pump(0.3)
        wired_host.pump(0.3)
        for host in (wireless_host, wired_host):
            host.send(cmd.stop_continuous())
        assert radio.wait_until(lambda: not radio.streaming, 3.0)
        assert cable.wait_until(lambda: not cable.streaming, 3.0)
        wireless_host.drain()
        wired_host.drain()
        assert {code_of(r) for r in wireless_host.records()} == {0xC2, 0xE9}
        assert {code_of(r) for r in wired_host.records()} == {0xCF, 0xE9}
        assert all(p.address == 95 for p in wireless_host.packets)
        assert radio.stats.acks == 2 and cable.stats.acks == 0
        assert_wired_host_saw_exactly_valid_truth(wired_host, cable)
