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
Every fault of the simulator, seen from the host side and matched with the ground truth.

Uses the Host helper of test_simulator.py. Each test turns on one fault, streams or polls
through the pseudo-terminal, and checks that what the codec's parser reports agrees with
what the simulator says it did: no fault goes unnoticed, none is invented.
"""

from itertools import pairwise
import math
import os
import time

from i3dmgx2_driver.codec import Ack, DataPacket, SensorStreamParser
from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.codec.parser import PingReply
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
import pytest
import serial
from test_simulator import (
    ADDRESS, assert_host_saw_exactly_valid_truth, Host, start_stream, stop_stream,
)

pytestmark = pytest.mark.slow

CC = lay.ACCEL_ANG_RATE_MAG_ORIENTATION


def simulator(seed: int = 21, **faults) -> PtySimulator:
    return PtySimulator(SimulatorConfig(seed=seed, faults=FaultConfig(**faults)))


def stream_for(host: Host, seconds: float, code: int = CC) -> None:
    start_stream(host, code)
    host.pump(seconds)
    stop_stream(host)


def faulty(sim: PtySimulator, fault: str) -> list:
    return [t for t in sim.truth if t.fault == fault]


def test_garbage_between_packets_is_skipped_byte_for_byte():
    with simulator(garbage_probability=0.5, garbage_max_bytes=12) as sim, Host(sim) as host:
        stream_for(host, 0.5)
        stats = sim.stats
        assert stats.garbage_bursts > 10
        # Safe garbage: the parser skips exactly the garbage bytes, nothing else.
        assert host.parser.stats.bytes_skipped == stats.garbage_bytes
        assert_host_saw_exactly_valid_truth(host, sim)


def test_any_garbage_still_leaves_every_valid_packet_intact():
    with simulator(garbage_probability=0.5, garbage_safe=False) as sim, Host(sim) as host:
        stream_for(host, 0.5)
        assert host.parser.stats.bytes_skipped >= sim.stats.garbage_bytes - sim.stats.acks
        assert_host_saw_exactly_valid_truth(host, sim)


def test_corrupted_checksums_are_rejected_and_counted():
    with simulator(corrupt_checksum_probability=0.3) as sim, Host(sim) as host:
        stream_for(host, 0.6)
        bad = faulty(sim, 'checksum')
        assert len(bad) >= 5 and all(not t.valid for t in bad)
        assert sim.stats.corrupted_checksum == len(bad)
        assert host.parser.stats.checksum_failures == len(bad)
        assert_host_saw_exactly_valid_truth(host, sim)


def test_corrupted_length_bytes_do_not_swallow_the_next_packet():
    with simulator(corrupt_length_probability=0.3) as sim, Host(sim) as host:
        stream_for(host, 0.6)
        bad = faulty(sim, 'length')
        assert len(bad) >= 5
        assert host.parser.stats.length_failures >= len(bad)
        assert_host_saw_exactly_valid_truth(host, sim)


def test_foreign_frames_are_filtered_by_address():
    with simulator(foreign_probability=0.5, foreign_address=7) as sim, Host(sim) as host:
        start_stream(host)
        host.pump(0.4)
        stop_stream(host)
        foreign = faulty(sim, 'foreign')
        assert len(foreign) >= 5
        assert all(t.address == 7 and not t.valid for t in foreign)
        assert host.parser.stats.foreign_frames == len(foreign)
        assert_host_saw_exactly_valid_truth(host, sim)
        # A parser that does not filter sees the other sensor's packets too.
        everyone = SensorStreamParser(None).feed(bytes(host.raw))
        assert sum(1 for p in everyone if getattr(p, 'address', None) == 7) == len(foreign)


def test_dropped_packets_leave_gaps_in_the_timer():
    with simulator(drop_probability=0.3) as sim, Host(sim) as host:
        stream_for(host, 0.6)
        dropped = faulty(sim, 'dropped')
        assert len(dropped) >= 5
        assert all(t.write_time is None for t in dropped)
        got = {r.timer for r in host.records(CC)}
        assert got.isdisjoint(t.timer for t in dropped)
        assert got == {t.timer for t in sim.truth if t.valid and t.source == 'stream'}
        assert_host_saw_exactly_valid_truth(host, sim)


def test_a_stall_silences_the_radio_both_ways():
    with simulator() as sim, Host(sim) as host:
        start_stream(host, lay.ACCEL_ANG_RATE)
        host.pump(0.2)
        sim.stall(0.6)
        stalled_at = time.time()
        host.parser.expect_ping()
        host.serial.write(cmd.ping(ADDRESS))
        host.send(cmd.encode_command(lay.FIRMWARE_VERSION))
        host.pump(0.3)
        assert [e for _, e in host.events if isinstance(e, PingReply)] == [PingReply(False)]
        host.pump_until(lambda: any(t > stalled_at + 0.6 for t, e in host.events
                                    if isinstance(e, DataPacket)), 5.0)
        stop_stream(host)
        times = [t for t, e in host.events if isinstance(e, DataPacket)]
        assert max(b - a for a, b in pairwise(times)) >= 0.5
        assert len(faulty(sim, 'stall')) >= 30
        outcomes = [e.outcome for e in sim.host_log]
        assert 'stalled' in outcomes and 'ping failed' in outcomes
        assert host.records(lay.FIRMWARE_VERSION) == []
        assert_host_saw_exactly_valid_truth(host, sim)


def test_a_scheduled_stall_from_the_fault_config():
    with simulator(stall_at=0.0, stall_seconds=0.3) as sim, Host(sim) as host:
        host.send(cmd.encode_command(lay.FIRMWARE_VERSION))
        host.pump(0.2)
        assert host.count(Ack) == 1 and host.packets == []
        assert sim.wait_until(lambda: time.time() > sim.start_time + 0.35, 2.0)
        assert host.request(cmd.encode_command(lay.FIRMWARE_VERSION)).version == 2113


def test_a_power_cycle_goes_dark_then_restarts_the_timer_where_asked():
    """Off for 0.4 s, then polled mode with the chosen timer (issue #23's power cycle)."""
    with simulator() as sim, Host(sim) as host:
        start_stream(host, lay.ACCEL_ANG_RATE)
        host.pump(0.2)
        cut = time.time()
        sim.power_cycle(off_seconds=0.4, timer_start=20_536_380)
        host.pump(0.6)
        # Dark, then polled: nothing streamed was sampled after the cut.
        assert all(t.sample_time < cut + 0.01 for t in sim.truth if t.source == 'stream')
        assert sim.streaming == 0
        back = time.time()
        start_stream(host, lay.ACCEL_ANG_RATE)
        host.pump(0.2)
        stop_stream(host)
        after = [t for t in sim.truth if t.source == 'stream' and t.sample_time > cut]
        assert after
        # The timer counts from the chosen value at power-up (cut + 0.4 s), 40 ppm fast.
        first = after[0]
        expected = 20_536_380 + (first.sample_time - (cut + 0.4)) * rec.TICKS_PER_SECOND
        assert abs(first.timer - expected) < 0.02 * rec.TICKS_PER_SECOND
        assert first.sample_time >= back - 0.05
        assert_host_saw_exactly_valid_truth(host, sim)


def test_a_scheduled_power_cycle_from_the_fault_config():
    with simulator(power_cycle_at=0.1, power_off_seconds=0.3, power_up_timer=7) as sim, \
            Host(sim) as host:
        assert sim.wait_until(lambda: time.time() > sim.start_time + 0.45, 2.0)
        start_stream(host, lay.ACCEL_ANG_RATE)
        host.pump(0.1)
        stop_stream(host)
        first = next(t for t in sim.truth if t.source == 'stream')
        power_up = sim.start_time + 0.4
        assert abs(first.timer - 7 - (first.sample_time - power_up)
                   * rec.TICKS_PER_SECOND) < 0.02 * rec.TICKS_PER_SECOND
    with pytest.raises(ValueError, match='power_off_seconds'):
        FaultConfig(power_off_seconds=-1.0)
    with simulator() as sim, pytest.raises(ValueError, match='uint32'):
        sim.power_cycle(timer_start=1 << 32)


def test_unplug_and_replug_at_the_same_path():
    with simulator() as sim:
        host = Host(sim)
        first_device = sim.pty.device
        start_stream(host, lay.ACCEL_ANG_RATE)
        host.pump(0.2)
        sim.unplug(0.8)
        assert not sim.pty.plugged.is_set() and not os.path.lexists(sim.port)
        # Reads fail: pyserial raises SerialException, or OSError (EIO) from in_waiting.
        with pytest.raises((serial.SerialException, OSError)):
            host.pump(1.0)
        host.close()
        with pytest.raises(serial.SerialException):
            serial.Serial(sim.port, 115200, timeout=0.05)
        assert sim.pty.plugged.wait(5.0)
        assert os.path.islink(sim.port)
        with Host(sim) as again:
            # The wireless sensor never lost power: it still streams, its timer runs on.
            assert again.pump_until(lambda: len(again.records(lay.ACCEL_ANG_RATE)) >= 5)
            stop_stream(again)
            before = host.records(lay.ACCEL_ANG_RATE)[-1].timer
            after = again.records(lay.ACCEL_ANG_RATE)[0].timer
            assert 0 < (after - before) % 2**32 < 5 * rec.TICKS_PER_SECOND
        assert sim.stats.unplugs == 1 and len(faulty(sim, 'unplugged')) >= 10
        assert first_device is not None and sim.pty.device is not None


def test_command_loss_acks_but_never_answers():
    with simulator(command_loss_probability=1.0) as sim, Host(sim) as host:
        host.send(cmd.encode_command(lay.FIRMWARE_VERSION))
        host.pump(0.3)
        assert host.count(Ack) == 1 and host.packets == []
        assert sim.host_log[-1].outcome == 'lost' and sim.commands == []
        sim.set_faults(command_loss_probability=0.0)
        assert host.request(cmd.encode_command(lay.FIRMWARE_VERSION)).version == 2113


def test_the_first_request_to_stream_is_ignored():
    with simulator(ignore_first_continuous=True) as sim, Host(sim) as host:
        host.send(cmd.set_continuous(CC))
        host.pump(0.3)
        assert host.count(Ack) == 1 and host.packets == []
        assert sim.host_log[-1].outcome == 'ignored'
        start_stream(host)
        host.pump(0.1)
        stop_stream(host)
        assert len(host.records(CC)) >= 3


def test_streaming_needs_a_polled_request_first_after_each_open():
    with simulator(needs_polled_first=True) as sim:
        for opened in range(2):
            with Host(sim) as host:
                assert sim.wait_until(lambda opened=opened: sim.stats.port_opens > opened, 2.0)
                host.send(cmd.set_continuous(CC))
                host.pump(0.3)
                assert host.packets == [], 'streaming as the very first command must fail'
                host.request(cmd.encode_command(lay.FIRMWARE_VERSION))
                start_stream(host)
                host.pump(0.1)
                stop_stream(host)
                assert len(host.records(CC)) >= 3
        assert [e.outcome for e in sim.host_log].count('ignored') == 2


def test_already_streaming_when_the_port_opens():
    with simulator(already_streaming=True) as sim:
        assert sim.streaming == CC
        time.sleep(0.2)
        with Host(sim) as host:
            assert host.pump_until(lambda: len(host.records(CC)) >= 10, 3.0)
            assert not any(isinstance(e, Ack) for _, e in host.events), 'no command was sent'
            stop_stream(host)
        assert sim.commands[0][1].code == lay.STOP_CONTINUOUS


def test_streaming_at_start_with_another_record():
    config = SimulatorConfig(streaming_at_start=lay.ACCEL_ANG_RATE, seed=3)
    with PtySimulator(config) as sim, Host(sim) as host:
        assert host.pump_until(lambda: len(host.records(lay.ACCEL_ANG_RATE)) >= 3, 3.0)
        assert host.request(cmd.read_eeprom(0xFCA6)) == rec.EepromWord(0x80C2)
        stop_stream(host)


def test_jitter_delays_writes_but_never_reorders():
    with simulator(jitter_ms=20.0) as sim, Host(sim) as host:
        stream_for(host, 0.6)
        stream = [t for t in sim.truth if t.source == 'stream']
        sent = {t.timer for t in stream}
        delays = [t.write_time - t.sample_time for t in stream]
        assert min(delays) >= sim.config.latency_s
        assert max(delays) - min(delays) >= 0.01
        assert all(b.write_time >= a.write_time for a, b in pairwise(stream))
        timers = [r.timer for r in host.records(CC)]
        assert all((b - a) % 2**32 < 2**31 for a, b in pairwise(timers))
        # The host never receives a packet before its sample time plus the latency.
        received = [t for t, e in host.events
                    if isinstance(e, DataPacket) and e.record.timer in sent]
        assert len(received) == len(stream)
        assert all(r >= t.sample_time + sim.config.latency_s
                   for r, t in zip(received, stream, strict=True))
        assert_host_saw_exactly_valid_truth(host, sim)


def test_a_full_line_loses_bytes_when_nobody_reads():
    config = SimulatorConfig(rate_hz=1000.0, streaming_at_start=True, seed=5)
    with PtySimulator(config) as sim:
        assert sim.wait_until(lambda: sim.stats.overflow_packets > 0, 5.0)
        assert sim.stats.overflow_bytes > 0
        assert faulty(sim, 'overflow')[0].write_time is None
        with Host(sim) as host:
            # pyserial flushes the stale bytes on open; the stream then arrives whole.
            assert host.pump_until(lambda: len(host.records(CC)) >= 20, 3.0)
            stop_stream(host)


def test_line_rate_limit_skips_what_115200_baud_cannot_carry():
    config = SimulatorConfig(rate_hz=400.0, limit_to_line_rate=True, seed=6)
    with PtySimulator(config) as sim, Host(sim) as host:
        start_stream(host)
        start = time.monotonic()
        host.pump(0.5)
        elapsed = time.monotonic() - start
        stop_stream(host)
        assert len(faulty(sim, 'line_rate')) > 20
        # 88-byte packets at 11520 bytes/s: at most ~131 per second get through.
        assert len(host.records(CC)) <= 131 * (elapsed + 0.3)
        assert_host_saw_exactly_valid_truth(host, sim)


def test_faults_can_be_switched_at_run_time():
    with simulator() as sim, Host(sim) as host:
        start_stream(host)
        host.pump(0.2)
        sim.set_faults(drop_probability=1.0)
        host.drain(quiet=0.2)
        count = len(host.packets)
        host.pump(0.2)
        assert len(host.packets) == count
        sim.set_faults(FaultConfig())
        assert host.pump_until(lambda: len(host.packets) > count + 3, 3.0)
        stop_stream(host)
        assert_host_saw_exactly_valid_truth(host, sim)


def test_nan_magnetometer_options():
    with PtySimulator(SimulatorConfig(nan_mag=True, seed=1)) as sim, Host(sim) as host:
        record = host.request(cmd.encode_command(lay.MAGNETOMETER))
        assert all(math.isnan(v) for v in record.mag)
    config = SimulatorConfig(mag_nan_probability=0.5, seed=2, rate_hz=400.0)
    with PtySimulator(config) as sim, Host(sim) as host:
        stream_for(host, 0.3, lay.MAGNETOMETER)
        mags = [r.mag for r in host.records(lay.MAGNETOMETER)]
        nans = sum(1 for m in mags if math.isnan(m[0]))
        assert 0.2 * len(mags) < nans < 0.8 * len(mags)
        assert_host_saw_exactly_valid_truth(host, sim)
