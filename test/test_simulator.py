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
The simulated 3DM-GX2 driven over its pseudo-terminal, exactly as a driver would.

The host side uses pyserial and the codec (command packets out, SensorStreamParser in),
and every observation is checked against the simulator's ground truth. Timing is only
ever used with generous margins: the CI machine has two cores and may be loaded.
Helpers shared with the other test_simulator_*.py files live here (Host, stream).
"""

from itertools import pairwise
import math
import os
import stat
import subprocess
import sys
import time

from i3dmgx2_driver.codec import (
    Ack, DataPacket, encode_command_packet, encode_record, Nack, SensorStreamParser,
)
from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.codec.parser import PingReply
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.simulator import FaultConfig, MotionConfig, PtySimulator, SimulatorConfig
import pytest
import serial

TPS = rec.TICKS_PER_SECOND
ADDRESS = 95


def ticks_per_cycle(divider: int = 512, ppm: float = 40.0) -> float:
    """Timer ticks between two cycles of the simulator: 384 * divider * (1 + ppm)."""
    return 384 * divider * (1.0 + ppm * 1e-6)


def code_of(record) -> int:
    """Echo byte of a decoded record."""
    return encode_record(record)[0]


class Host:
    """
    The host end of the line: a pyserial port, the codec's parser, a log of events.

    ``wireless`` (default: what the simulator is) selects the framing the host
    speaks: command packets and the wireless parser, or raw commands and the
    wired parser.
    """

    def __init__(self, sim: PtySimulator, address: int = ADDRESS,
                 timeout: float = 0.02, wireless: bool | None = None) -> None:
        self.sim = sim
        self.address = address
        if wireless is None:  # a bare port (test_simulator_cli.py's) is a base station's
            wireless = sim.config.wireless if isinstance(sim, PtySimulator) else True
        self.wireless = wireless
        self.serial = serial.Serial(sim.port, 115200, timeout=timeout)
        #: After the open, which flushed whatever the port held before.
        self.opened = time.time()
        self.parser = SensorStreamParser(address if self.wireless else None,
                                         wireless=self.wireless)
        #: (receive time, event) of everything parsed so far.
        self.events = []
        #: Every byte received, for a second look with another parser.
        self.raw = bytearray()

    def close(self) -> None:
        self.serial.close()

    def __enter__(self) -> 'Host':
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def send(self, command: bytes, address: int | None = None) -> None:
        """Send a command packet (built by the codec), or the bare command when wired."""
        if not self.wireless:
            self.serial.write(command)
            return
        packet = encode_command_packet(self.address if address is None else address, command)
        self.serial.write(packet)

    def read_once(self) -> list:
        """One read from the port (waits up to the serial timeout); return new events."""
        data = self.serial.read(max(1, self.serial.in_waiting))
        now = time.time()
        self.raw += data
        new = self.parser.feed(data) if data else self.parser.idle()
        self.events.extend((now, event) for event in new)
        return new

    def pump(self, seconds: float) -> None:
        """Read for ``seconds``."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.read_once()

    def pump_until(self, predicate, timeout: float = 5.0) -> bool:
        """Read until ``predicate()`` holds or ``timeout`` passes; return whether it held."""
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return False
            self.read_once()
        return True

    def drain(self, quiet: float = 0.15, timeout: float = 5.0) -> None:
        """Read until nothing arrived for ``quiet`` seconds."""
        deadline = time.monotonic() + timeout
        last = time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - last < quiet:
            if self.read_once():
                last = time.monotonic()

    @property
    def packets(self) -> list:
        return [e for _, e in self.events if isinstance(e, DataPacket)]

    def records(self, code: int | None = None) -> list:
        return [p.record for p in self.packets if code is None or code_of(p.record) == code]

    def count(self, kind) -> int:
        return sum(1 for _, e in self.events if isinstance(e, kind))

    def request(self, command: bytes, timeout: float = 3.0, code: int | None = None):
        """Send a command and wait for its reply record (echo = command byte)."""
        code = command[0] if code is None else code
        before = len(self.records(code))
        self.send(command)
        assert self.pump_until(lambda: len(self.records(code)) > before, timeout), \
            f'no reply to 0x{command[0]:02X}'
        return self.records(code)[before]


def start_stream(host: Host, code: int = lay.ACCEL_ANG_RATE_MAG_ORIENTATION) -> None:
    """Ask for continuous mode and wait for its reply."""
    reply = host.request(cmd.set_continuous(code), code=lay.SET_CONTINUOUS)
    assert reply.command == code


def stop_stream(host: Host) -> None:
    """Stop with 0xFA (twice, as the manual advises) and wait until the line is quiet."""
    host.send(cmd.stop_continuous())
    host.send(cmd.stop_continuous())
    assert host.sim.wait_until(lambda: not host.sim.streaming, 3.0)
    host.drain()


def same_record(a, b) -> bool:
    """Compare two records bit for bit (NaN magnetometer readings included)."""
    return encode_record(a) == encode_record(b)


def assert_host_saw_exactly_valid_truth(host: Host, sim: PtySimulator, since: int = 0) -> None:
    """
    Check that the parser accepted exactly the truth entries marked valid.

    Records written before the host opened the port (a sensor streaming from
    power-up) may have been flushed by the open, however soon after the
    simulator's start it came: those, and only those, may be missing. Begun
    before is enough: the open may flush a record's first chunks and leave its
    tail, when the writer was descheduled between them.
    """
    valid = [t for t in sim.truth if t.valid and t.index >= since]
    got = host.packets
    if got and valid:
        first = encode_record(got[0].record)
        start = next((i for i, t in enumerate(valid) if encode_record(t.record) == first),
                     None)
        assert start is not None, 'the first packet the host got matches no valid record'
        assert all(t.first_write_time < host.opened for t in valid[:start])
        valid = valid[start:]
    assert len(got) == len(valid), (len(got), len(valid))
    for packet, truth in zip(got, valid, strict=True):
        assert packet.address == truth.address
        assert same_record(packet.record, truth.record)
        lqi, rssi = truth.packet[-4], truth.packet[-3]
        assert (packet.lqi, packet.rssi) == (lqi, rssi)


@pytest.fixture
def sim():
    with PtySimulator(SimulatorConfig(seed=7)) as simulator:
        yield simulator


@pytest.fixture
def host(sim):
    with Host(sim) as port:
        yield port


@pytest.mark.slow
def test_port_is_a_stable_symlink_to_a_raw_pty(sim):
    assert os.path.islink(sim.port)
    assert os.path.basename(sim.port) == 'ttyGX2'
    assert os.path.realpath(sim.port) == sim.pty.device
    assert stat.S_ISCHR(os.stat(sim.port).st_mode)
    # Through /proc/<pid>/fd: a link left by a killed simulator dangles instead of
    # leading to whatever pseudo-terminal reuses the number.
    assert os.readlink(sim.port) == sim.pty.link_target
    assert sim.pty.link_target.startswith(f'/proc/{os.getpid()}/fd/')


@pytest.mark.slow
def test_a_killed_simulator_leaves_no_usable_port(tmp_path):
    link = tmp_path / 'port'
    code = ('import os, time; from i3dmgx2_driver.simulator import PtySimulator, '
            f'SimulatorConfig; s = PtySimulator(SimulatorConfig(symlink={str(link)!r})); '
            's.start(); print(s.pty.device, flush=True); time.sleep(60)')
    child = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True,
                             cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    try:
        assert child.stdout.readline().startswith('/dev/pts/')
        assert link.is_symlink() and link.exists()
    finally:
        child.kill()
        child.wait()
    assert link.is_symlink() and not link.exists(), 'the stale link dangles'
    with pytest.raises(serial.SerialException):
        serial.Serial(str(link), 115200)


@pytest.mark.slow
def test_every_good_command_packet_is_acked_and_a_bad_one_nacked(sim, host):
    version = host.request(cmd.encode_command(lay.FIRMWARE_VERSION))
    assert version == rec.FirmwareVersion(2113)
    assert version.text == '2.1.13'
    assert host.count(Ack) == 1
    bad = bytearray(encode_command_packet(ADDRESS, cmd.encode_command(lay.FIRMWARE_VERSION)))
    bad[-1] ^= 0x01
    host.serial.write(bytes(bad))
    assert host.pump_until(lambda: host.count(Nack) == 1)
    host.drain()
    assert len(host.records(lay.FIRMWARE_VERSION)) == 1, 'a NACKed command has no reply'
    kinds = [(entry.kind, entry.outcome) for entry in sim.host_log]
    assert kinds[0] == ('packet', 'delivered')
    assert kinds[1][0] == 'rejected'
    assert sim.stats.acks == 1 and sim.stats.nacks == 1


@pytest.mark.slow
def test_binary_bytes_pass_untranslated(sim, host):
    # CR, LF, XON, XOFF and ^C inside a packet: a cooked tty would eat or translate them.
    word = host.request(cmd.write_eeprom(0x0D0A, 0x1311), code=lay.WRITE_EEPROM)
    assert word == rec.EepromWritten(0x1311)
    assert host.request(cmd.read_eeprom(0x0D0A)) == rec.EepromWord(0x1311)
    assert sim.commands[0][1] == cmd.decode_command(cmd.write_eeprom(0x0D0A, 0x1311))


@pytest.mark.slow
def test_ping_answers_for_our_address_only(sim, host):
    host.parser.expect_ping()
    host.serial.write(cmd.ping(ADDRESS))
    assert host.pump_until(lambda: host.count(PingReply) == 1)
    host.parser.expect_ping()
    host.serial.write(cmd.ping(12))
    assert host.pump_until(lambda: host.count(PingReply) == 2)
    replies = [e for _, e in host.events if isinstance(e, PingReply)]
    assert replies == [PingReply(True), PingReply(False)]
    assert [e.outcome for e in sim.host_log] == ['ping ok', 'ping failed']
    assert sim.commands == [], 'a ping is answered by the base station'


@pytest.mark.slow
def test_identifiers():
    config = SimulatorConfig(address=42, serial_number='4242', seed=1)
    with PtySimulator(config) as sim, Host(sim, address=42) as host:
        texts = [host.request(cmd.device_identifier(s)) for s in range(4)]
    assert [t.selector for t in texts] == [0, 1, 2, 3]
    assert texts[0].text == '3DM-GX2'.ljust(16)
    assert texts[1].text == '4242'.ljust(16)
    assert all(len(t.text) == 16 for t in texts)


@pytest.mark.slow
def test_commands_for_another_address_are_acked_but_unanswered(sim, host):
    host.send(cmd.encode_command(lay.FIRMWARE_VERSION), address=ADDRESS + 1)
    assert host.pump_until(lambda: host.count(Ack) == 1)
    host.drain()
    assert host.packets == []
    assert sim.host_log[0].outcome == 'other_address'


@pytest.mark.slow
def test_eeprom_rate_divider_read_write(sim, host):
    assert host.request(cmd.read_eeprom(0xFCA2)) == rec.EepromWord(512)
    assert host.request(cmd.read_eeprom(0xFCA6)) == rec.EepromWord(0)
    assert host.request(cmd.write_eeprom(0xFCA2, 256)) == rec.EepromWritten(256)
    assert host.request(cmd.read_eeprom(0xFCA2)) == rec.EepromWord(256)
    assert sim.sensor.rate_hz == 200.0
    # Out of 170..51200: not stored, and the reply shows the word that was kept.
    assert host.request(cmd.write_eeprom(0xFCA2, 100)) == rec.EepromWritten(256)
    assert host.request(cmd.read_eeprom(0x1234)) == rec.EepromWord(0xFFFF)


@pytest.mark.slow
def test_continuous_0xcc_at_100_hz_with_exact_timer_spacing(sim, host):
    start_stream(host)
    started = time.monotonic()
    host.pump(1.0)
    elapsed = time.monotonic() - started
    stop_stream(host)
    records = host.records(lay.ACCEL_ANG_RATE_MAG_ORIENTATION)
    # ~100 Hz: tolerant of a loaded machine, but not of a wrong rate.
    assert 0.6 * 100 * elapsed <= len(records) <= 100 * (elapsed + 0.6)
    step = ticks_per_cycle(512, 40.0)
    diffs = [(b.timer - a.timer) % 2**32 for a, b in pairwise(records)]
    assert diffs and all(abs(d - step) <= 1 for d in diffs), sorted(set(diffs))
    assert_host_saw_exactly_valid_truth(host, sim)
    truth = [t for t in sim.truth if t.source == 'stream']
    assert all(t.write_time >= t.sample_time for t in truth)
    spacing = [b.sample_time - a.sample_time for a, b in pairwise(truth)]
    assert all(abs(s - 0.01) < 1e-6 for s in spacing)


@pytest.mark.slow
def test_rate_follows_the_divider_and_the_override(sim, host):
    host.request(cmd.write_eeprom(0xFCA2, 1024))          # 50 Hz
    start_stream(host, lay.ACCEL_ANG_RATE)
    host.pump(0.4)
    stop_stream(host)
    records = host.records(lay.ACCEL_ANG_RATE)
    diffs = {(b.timer - a.timer) % 2**32 for a, b in pairwise(records)}
    assert diffs and all(abs(d - ticks_per_cycle(1024)) <= 1 for d in diffs)


@pytest.mark.slow
def test_high_rate_override_for_benchmarks():
    with PtySimulator(SimulatorConfig(rate_hz=1000.0, seed=3)) as sim, Host(sim) as host:
        start_stream(host, lay.ACCEL_ANG_RATE)
        host.pump(0.5)
        stop_stream(host)
        records = host.records(lay.ACCEL_ANG_RATE)
        assert len(records) > 150
        step = TPS * (1 + 40e-6) / 1000.0
        assert all(abs((b.timer - a.timer) % 2**32 - step) <= 1
                   for a, b in pairwise(records))
        assert sim.stats.late_skipped == 0 or len(records) > 150
        assert_host_saw_exactly_valid_truth(host, sim)


@pytest.mark.slow
def test_timer_crosses_the_rollover():
    config = SimulatorConfig(timer_start=2**32 - int(0.3 * TPS), rate_hz=200.0, seed=2)
    with PtySimulator(config) as sim, Host(sim) as host:
        start_stream(host, lay.ACCEL_ANG_RATE)
        assert host.pump_until(
            lambda: any(r.timer < 2**31 for r in host.records(lay.ACCEL_ANG_RATE)), 5.0)
        host.pump(0.1)
        stop_stream(host)
        timers = [r.timer for r in host.records(lay.ACCEL_ANG_RATE)]
    steps = [(b - a) % TIMER_MODULUS for a, b in pairwise(timers)]
    assert all(0 < step < TPS for step in steps), 'each record a little after the one before'
    assert sum(b < a for a, b in pairwise(timers)) == 1, 'one rollover'


@pytest.mark.slow
def test_default_timer_starts_five_seconds_before_the_rollover(sim, host):
    record = host.request(cmd.encode_command(lay.ACCEL_ANG_RATE))
    age = time.time() - sim.start_time
    expected = (2**32 - 5 * TPS + round(age * TPS)) % 2**32
    assert abs(((record.timer - expected + 2**31) % 2**32) - 2**31) < 2 * TPS


@pytest.mark.slow
def test_stop_with_0xfa_has_no_reply_and_0xc4_0_has_one(sim, host):
    start_stream(host, lay.ACCEL_ANG_RATE)
    host.pump(0.2)
    stop_stream(host)
    count = len(host.packets)
    host.pump(0.3)
    assert len(host.packets) == count, 'records after 0xFA'
    assert host.records(lay.SET_CONTINUOUS) == [rec.ContinuousModeReply(
        lay.ACCEL_ANG_RATE, host.records(lay.SET_CONTINUOUS)[0].timer)]
    start_stream(host, lay.ACCEL_ANG_RATE)
    reply = host.request(cmd.set_continuous(0), code=lay.SET_CONTINUOUS)
    assert reply.command == 0
    assert sim.wait_until(lambda: not sim.streaming, 2.0)


@pytest.mark.slow
def test_power_cycle_restarts_the_timer_and_the_auto_start(sim, host):
    host.request(cmd.write_eeprom(0xFCA6, 0x8000 | lay.ACCEL_ANG_RATE))
    host.pump(0.2)
    before = host.request(cmd.encode_command(lay.ACCEL_ANG_RATE)).timer
    assert sim.streaming == 0, 'auto-start acts at the next power-up'
    sim.power_cycle()
    assert host.pump_until(lambda: len(host.records(lay.ACCEL_ANG_RATE)) >= 4)
    stop_stream(host)
    timers = [record.timer for record in host.records(lay.ACCEL_ANG_RATE)]
    jumps = [(a, b) for a, b in pairwise(timers) if not 0 < (b - a) % TIMER_MODULUS < TPS]
    assert len(jumps) == 1, 'the timer starts again from timer_start'
    assert host.records(lay.ACCEL_ANG_RATE)[1].timer != before


@pytest.mark.slow
def test_rate_override_at_run_time(sim, host):
    sim.set_rate(400.0)
    start_stream(host, lay.ACCEL_ANG_RATE)
    host.pump(0.3)
    stop_stream(host)
    records = host.records(lay.ACCEL_ANG_RATE)
    step = TPS * (1 + 40e-6) / 400.0
    assert len(records) > 40
    assert all(abs((b.timer - a.timer) % 2**32 - step) <= 1 for a, b in pairwise(records))


@pytest.mark.slow
def test_polled_commands_interleave_with_the_stream(sim, host):
    start_stream(host, lay.ACCEL_ANG_RATE)
    assert host.request(cmd.read_eeprom(0xFCA2)) == rec.EepromWord(512)
    assert host.request(cmd.encode_command(lay.FIRMWARE_VERSION)).version == 2113
    stop_stream(host)
    assert_host_saw_exactly_valid_truth(host, sim)


@pytest.mark.slow
def test_every_data_record_can_be_polled(sim, host):
    codes = sorted(c for c, layout in lay.LAYOUTS.items()
                   if layout.reply and layout.reply[-1].name == 'timer'
                   and not layout.request and not layout.confirm)
    assert codes == [0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC8, 0xCB, 0xCC, 0xCE, 0xCF,
                     0xD1, 0xD2, 0xD3]
    for code in codes:
        record = host.request(cmd.encode_command(code))
        assert code_of(record) == code
    assert_host_saw_exactly_valid_truth(host, sim)


@pytest.mark.slow
def test_bias_writes_are_echoed_and_stored(sim, host):
    accel = host.request(cmd.write_accel_bias((0.01, -0.02, 0.03)))
    assert accel.bias == pytest.approx((0.01, -0.02, 0.03), abs=1e-7)
    gyro = host.request(cmd.write_gyro_bias((0.001, 0.002, -0.003)))
    assert isinstance(gyro, rec.GyroBias)
    assert gyro.bias == pytest.approx((0.001, 0.002, -0.003), abs=1e-9)
    assert host.request(cmd.transfer_to_non_volatile(2)).quantity == 2
    assert host.request(cmd.transfer_to_non_volatile(7)).quantity == 0xFFFF


@pytest.mark.slow
def test_gyro_bias_capture_arrives_after_the_sampling_time():
    motion = MotionConfig(static=True)
    with PtySimulator(SimulatorConfig(motion=motion, seed=11)) as sim, Host(sim) as host:
        sent = time.time()
        captured = host.request(cmd.capture_gyro_bias(200), timeout=5.0)
        arrived = [t for t, e in host.events if isinstance(e, DataPacket)][-1]
        assert arrived - sent >= 0.2
        assert host.count(Ack) == 1
        truth = [t for t in sim.truth if t.source == 'reply'][-1]
        assert truth.sample_time - sent >= 0.19
        assert captured.bias == pytest.approx(motion.gyro_bias, abs=0.002)
        # The sensor now subtracts the captured bias: a still gyro reads about zero.
        rate = host.request(cmd.encode_command(lay.ACCEL_ANG_RATE)).angular_rate
        assert all(abs(w) < 0.008 for w in rate)

        sim.set_moving(True)
        moving = host.request(cmd.capture_gyro_bias(300), timeout=5.0)
        error = math.dist(moving.bias, motion.gyro_bias)
        assert error > 0.01, 'a capture while moving must be off'


@pytest.mark.slow
def test_built_in_test_and_temperatures(sim, host):
    assert host.request(cmd.built_in_test(0x14)) == rec.BuiltInTest(0x14)
    temps = host.request(cmd.encode_command(lay.TEMPERATURES))
    assert 22.0 < temps.accel_celsius < 30.0
    assert all(22.0 < rec.code_to_celsius(code) < 31.0 for code in temps.gyro_codes)


@pytest.mark.slow
def test_static_sensor_flat_reads_minus_one_g_on_z():
    motion = MotionConfig(static=True, initial_attitude_deg=(0.0, 0.0, 0.0))
    with PtySimulator(SimulatorConfig(motion=motion, seed=5)) as sim, Host(sim) as host:
        record = host.request(cmd.encode_command(lay.ACCEL_ANG_RATE_MAG_ORIENTATION))
    assert record.accel == pytest.approx((0.0, 0.0, -1.0), abs=0.005)
    assert record.matrix == pytest.approx((1, 0, 0, 0, 1, 0, 0, 0, 1), abs=1e-6)
    assert math.hypot(*record.mag) == pytest.approx(0.5, abs=0.02)
    assert record.mag[2] > 0, 'the field dips downwards in the north hemisphere'


@pytest.mark.slow
def test_packets_are_written_in_chunks():
    config = SimulatorConfig(chunks=(3, 3), chunk_gap_s=0.03, seed=4)
    with PtySimulator(config) as sim, Host(sim) as host:
        host.send(cmd.encode_command(lay.ACCEL_ANG_RATE_MAG_ORIENTATION))
        sizes = []
        deadline = time.monotonic() + 3.0
        while not host.packets and time.monotonic() < deadline:
            data = host.serial.read(max(1, host.serial.in_waiting))
            if data:
                sizes.append(len(data))
                host.events.extend((time.time(), e) for e in host.parser.feed(data))
        assert host.packets and sim.truth[0].valid
    # 88 bytes in three chunks 30 ms apart: no single read gets the whole packet.
    assert sum(sizes) == 1 + 88
    assert max(sizes) < 88
    # The truth spans the packet's writes: two pauses of at least 30 ms between
    # the first chunk's write and the last one's.
    entry = sim.truth[0]
    assert entry.write_time - entry.first_write_time >= 2 * 0.03


@pytest.mark.slow
def test_reopening_the_port_keeps_the_line_settings(sim):
    for _ in range(2):
        with Host(sim) as host:
            assert host.request(cmd.encode_command(lay.FIRMWARE_VERSION)).version == 2113
    assert sim.wait_until(lambda: sim.stats.port_opens >= 2, 2.0)


def test_fault_config_and_simulator_config_validate():
    with pytest.raises(ValueError, match='drop_probability'):
        FaultConfig(drop_probability=1.5)
    with pytest.raises(ValueError, match='address'):
        SimulatorConfig(address=0)
    with pytest.raises(ValueError, match='chunks'):
        SimulatorConfig(chunks=(0, 2))


@pytest.mark.slow
def test_symlink_option_and_cleanup(tmp_path):
    path = tmp_path / 'imu'
    with PtySimulator(SimulatorConfig(symlink=str(path), seed=1)) as sim:
        assert sim.port == str(path) and path.is_symlink()
        with Host(sim) as host:
            assert host.request(cmd.encode_command(lay.FIRMWARE_VERSION)).version == 2113
    assert not os.path.lexists(path)


def test_the_public_names_are_importable_from_the_package():
    """Each name lives in one module, and the package exports the public ones."""
    import i3dmgx2_driver.simulator as package
    from i3dmgx2_driver.simulator import config, ground_truth, pty_link, pty_port, transmitter
    assert package.PtySimulator is pty_link.PtySimulator
    assert package.SimulatorConfig is config.SimulatorConfig
    for name in ('SentRecord', 'HostCommand', 'SimulatorStats'):
        assert getattr(package, name) is getattr(ground_truth, name)
    assert transmitter.LINE_BYTES_PER_SECOND == 11520
    assert pty_port.PORT_NAME == 'ttyGX2'
    assert config.DEFAULT_STREAM == lay.ACCEL_ANG_RATE_MAG_ORIENTATION
    assert set(package.__all__) >= {'FaultConfig', 'Motion', 'MotionConfig', 'Reply',
                                    'SimulatedSensor'}
