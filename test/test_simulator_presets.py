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
Power-up presets, and the record of what the host did.

Presets: the EEPROM divider, EEPROM words, the record auto-started at power-up. The
record: ``commands``, ``host_log``, ``eeprom_writes()``, ``stream_changes``.

A driver test starts from any record and rate the device could be left in, and then
proves what the driver did to it: nothing written to the EEPROM, a stream restarted.
"""

from itertools import pairwise

from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.sensor import STREAMABLE
import pytest
from test_simulator import code_of, Host, start_stream, stop_stream, ticks_per_cycle

CC = lay.ACCEL_ANG_RATE_MAG_ORIENTATION


@pytest.mark.slow
@pytest.mark.parametrize('wireless', [True, False], ids=['wireless', 'wired'])
def test_divider_preset_is_read_back_and_sets_the_rate(wireless):
    config = SimulatorConfig(divider=1024, wireless=wireless, seed=41)
    with PtySimulator(config) as sim, Host(sim) as host:
        assert host.request(cmd.read_eeprom(0xFCA2)) == rec.EepromWord(1024)
        assert sim.sensor.rate_hz == 50.0
        start_stream(host, lay.ACCEL_ANG_RATE)
        assert host.pump_until(lambda: len(host.records(lay.ACCEL_ANG_RATE)) >= 6)
        stop_stream(host)
        records = host.records(lay.ACCEL_ANG_RATE)
        assert all(abs((b.timer - a.timer) % 2**32 - ticks_per_cycle(1024)) <= 1
                   for a, b in pairwise(records))
        stream = [t for t in sim.truth if t.source == 'stream']
        assert all(abs(b.sample_time - a.sample_time - 0.02) < 1e-6
                   for a, b in pairwise(stream))
        assert sim.eeprom_writes() == [], 'a preset is not a write by the host'


@pytest.mark.slow
def test_eeprom_preset_and_its_precedence():
    config = SimulatorConfig(eeprom={0x1234: 0xBEEF, 0xFCA2: 256}, seed=42)
    with PtySimulator(config) as sim, Host(sim) as host:
        assert host.request(cmd.read_eeprom(0x1234)) == rec.EepromWord(0xBEEF)
        assert host.request(cmd.read_eeprom(0xFCA2)) == rec.EepromWord(256)
        assert sim.sensor.rate_hz == 200.0
    # divider and streaming_at_start win over the same words in eeprom.
    config = SimulatorConfig(eeprom={0xFCA2: 256, 0xFCA6: 0x80C2}, divider=2048,
                             streaming_at_start=CC)
    assert config.power_up_eeprom == {0xFCA2: 2048, 0xFCA6: 0x80CC}
    assert SimulatorConfig(wireless=False, streaming_at_start=0xC2).power_up_eeprom == {
        0xFCA6: 0x00C2}
    assert SimulatorConfig().power_up_eeprom == {}


@pytest.mark.slow
@pytest.mark.parametrize('code', sorted(STREAMABLE), ids=lambda c: f'0x{c:02X}')
def test_streaming_at_start_works_for_every_streamable_record(code):
    with PtySimulator(SimulatorConfig(streaming_at_start=code, divider=256, seed=43)) as sim:
        assert sim.streaming == code
        with Host(sim) as host:
            assert host.pump_until(lambda: len(host.records(code)) >= 5)
            assert {code_of(p.record) for p in host.packets} == {code}
            assert host.request(cmd.read_eeprom(0xFCA6)) == rec.EepromWord(0x8000 | code)
            stop_stream(host)
            records = host.records(code)
            assert all(abs((b.timer - a.timer) % 2**32 - ticks_per_cycle(256)) <= 1
                       for a, b in pairwise(records))
        assert [c for _, c in sim.stream_changes] == [code, 0]


@pytest.mark.slow
def test_a_divider_beyond_the_line_301_hz_of_0xcc():
    """Divider 170 with 0xCC: 301 packets/s of 88 bytes, where the line carries ~131."""
    config = SimulatorConfig(divider=170, streaming_at_start=CC, limit_to_line_rate=True,
                             seed=44)
    with PtySimulator(config) as sim, Host(sim) as host:
        assert sim.sensor.rate_hz == pytest.approx(301.176, abs=1e-3)
        host.pump(0.5)
        stop_stream(host)
        stream = [t for t in sim.truth if t.source == 'stream']
        sent = [t for t in stream if t.fault is None]
        skipped = [t for t in stream if t.fault == 'line_rate']
        assert len(skipped) > 0.4 * len(stream) and len(sent) > 0.3 * len(stream)
        # What was sent still sits on the 301 Hz grid: whole cycles apart.
        step = ticks_per_cycle(170)
        for a, b in pairwise(sent):
            cycles = ((b.timer - a.timer) % 2**32) / step
            assert abs(cycles - round(cycles)) < 1e-4 and round(cycles) >= 1
        assert host.request(cmd.read_eeprom(0xFCA2)) == rec.EepromWord(170)


def test_presets_are_validated_with_clear_messages():
    for divider in (169, 51201, 0):
        with pytest.raises(ValueError, match=r'divider must be in 170\.\.51200'):
            SimulatorConfig(divider=divider)
    with pytest.raises(ValueError, match=r'0xC4 cannot be streamed; streamable records: '
                                         r'0xC1, 0xC2, 0xC3, .*0xD3'):
        SimulatorConfig(streaming_at_start=0xC4)
    with pytest.raises(ValueError, match='eeprom'):
        SimulatorConfig(eeprom={0xFCA2: 0x10000})
    assert SimulatorConfig(streaming_at_start=True).start_stream == CC
    assert SimulatorConfig(faults=FaultConfig(already_streaming=True)).start_stream == CC


@pytest.mark.slow
def test_the_record_shows_no_eeprom_write_and_a_restarted_stream():
    with PtySimulator(SimulatorConfig(streaming_at_start=CC, seed=45)) as sim, \
            Host(sim) as host:
        assert host.request(cmd.read_eeprom(0xFCA2)) == rec.EepromWord(512)
        stop_stream(host)
        start_stream(host, CC)
        start_stream(host, CC)          # the same record again: no change of stream
        host.pump(0.1)
        assert sim.eeprom_writes() == []
        assert sim.eeprom == {0xFCA2: 512, 0xFCA6: 0x80CC}
        changes = [code for _, code in sim.stream_changes]
        assert changes == [CC, 0, CC], 'streaming from power-up, stopped, restarted'
        # Every command the sensor received, decoded, in order; the host log has them too.
        codes = [c.code for _, c in sim.commands]
        assert codes == [0xE5, 0xFA, 0xFA, 0xC4, 0xC4]
        assert [c.args for _, c in sim.commands_of(lay.SET_CONTINUOUS)] == [(CC,), (CC,)]
        assert [e.command for e in sim.host_log] == [c for _, c in sim.commands]
        assert all(e.kind == 'packet' and e.outcome == 'delivered' for e in sim.host_log)
        host.request(cmd.write_eeprom(0xFCA2, 1024))
        stop_stream(host)
        (_, write), = sim.eeprom_writes()
        assert write == cmd.decode_command(cmd.write_eeprom(0xFCA2, 1024))
        assert write.args == (0xFCA2, 1024)
        assert sim.eeprom[0xFCA2] == 1024


@pytest.mark.slow
def test_a_write_lost_on_the_radio_is_in_the_host_log_only():
    with PtySimulator(SimulatorConfig(seed=46)) as sim, Host(sim) as host:
        sim.set_faults(command_loss_probability=1.0)
        host.send(cmd.write_eeprom(0xFCA2, 1024))
        assert sim.wait_until(lambda: sim.stats.commands_lost == 1, 3.0)
        assert sim.eeprom_writes() == [] and sim.eeprom[0xFCA2] == 512
        entry, = sim.host_log
        assert (entry.command.code, entry.outcome) == (lay.WRITE_EEPROM, 'lost')
