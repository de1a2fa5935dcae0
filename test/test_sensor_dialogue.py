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
SensorDialogue with a link and a simulator alone: no supervisor, no thread of its own.

What the dialogue says and learns, step by step: quiet, identity and rate,
the one EEPROM write (and none when the rate is already right), continuous
mode until records arrive, an exclusive operation, the resume of a known
sensor, and the refusal of a silent address with the reason.
"""

import threading
import time

from i3dmgx2_driver.codec import commands, layouts as lay
from i3dmgx2_driver.device.dialogue import SensorDialogue
from i3dmgx2_driver.device.identity import read_firmware
from i3dmgx2_driver.device.link import DeviceError, DeviceLink, DeviceTimeout, LinkOptions
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
from log_lines import Log
import pytest

pytestmark = pytest.mark.slow


class Talk:
    """A link on the simulator's port, its reader running, and a dialogue over it."""

    def __init__(self, sim: PtySimulator, **config) -> None:
        self.records = 0
        self.timers: list[int] = []
        self.log = Log()
        self.warnings: list[tuple[str, str]] = []
        self.cancel = threading.Event()
        self.link = DeviceLink(SerialPort(sim.port, low_latency=False), config.get('address', 95),
                               self._on_record, LinkOptions(select_timeout=0.05))
        self.dialogue = SensorDialogue(
            DeviceConfig(port=sim.port, **{'address': 95, **config}), self.log,
            lambda key, message, period: self.warnings.append((key, message)), self.cancel)
        self.dialogue.quiet(self.link)
        self.link.start()

    def _on_record(self, packet, read_time, read_mono) -> None:
        self.records += 1
        self.timers.append(packet.record.timer)

    def close(self) -> None:
        self.link.stop()
        self.link.port.close()


def test_bring_up_learns_identity_and_rate_then_streams():
    with PtySimulator(SimulatorConfig(seed=3)) as sim:
        talk = Talk(sim)
        try:
            dialogue = talk.dialogue
            dialogue.initialise(talk.link)
            assert dialogue.ping_ok is True
            assert dialogue.info.serial_number == '3095'
            assert dialogue.divider == 512 and dialogue.expected_rate_hz == 100.0
            assert 'fits' in dialogue.line_use or dialogue.line_use
            assert talk.records == 0  # nothing streams before it is asked
            assert dialogue.start_continuous(talk.link)
            assert talk.records > 0 and sim.streaming == lay.ACCEL_ANG_RATE_MAG_ORIENTATION
            assert sim.eeprom_writes() == []  # no rate asked: nothing written
        finally:
            talk.close()


def test_the_rate_is_written_once_and_not_again_when_right():
    with PtySimulator(SimulatorConfig(seed=4)) as sim:
        for _ in range(2):
            talk = Talk(sim, data_rate_hz=200.0)
            try:
                talk.dialogue.initialise(talk.link)
                assert talk.dialogue.divider == 256
            finally:
                talk.close()
        assert len(sim.eeprom_writes()) == 1
        assert sim.eeprom[0xFCA2] == 256


def test_an_exclusive_operation_runs_with_the_stream_stopped():
    with PtySimulator(SimulatorConfig(seed=5)) as sim:
        talk = Talk(sim)
        try:
            talk.dialogue.initialise(talk.link)
            assert talk.dialogue.start_continuous(talk.link)
            seen = []

            def operation(link):
                seen.append(sim.streaming)
                return read_firmware(link, 0.5, 3)

            talk.dialogue.stop(talk.link)
            assert operation(talk.link) == '2.1.13'
            assert seen == [0]
            assert talk.dialogue.start_continuous(talk.link)
        finally:
            talk.close()


def test_resume_confirms_the_same_sensor_by_its_serial_number():
    with PtySimulator(SimulatorConfig(seed=6)) as sim:
        talk = Talk(sim)
        try:
            assert not talk.dialogue.can_resume()  # nothing known yet
            talk.dialogue.initialise(talk.link)
            assert talk.dialogue.start_continuous(talk.link)
            assert talk.dialogue.can_resume()
            talk.dialogue.expect_stream(talk.link)
            assert talk.dialogue.resume(talk.link)
            assert any('same sensor (serial 3095)' in m for _, m in talk.log.lines)
        finally:
            talk.close()


def test_a_silent_address_is_refused_with_the_reason():
    with PtySimulator(SimulatorConfig(seed=7, faults=FaultConfig(already_streaming=True))) as sim:
        talk = Talk(sim, address=12, request_timeout=0.1)
        try:
            with pytest.raises(DeviceTimeout, match=r'node 12 is silent.*seen: node 95'):
                talk.dialogue.initialise(talk.link, require_answer=True,
                                         observed=lambda: 'seen: node 95')
            assert talk.warnings and talk.warnings[0][0] == 'ping'
        finally:
            talk.close()


def test_another_stream_does_not_pass_for_the_one_asked():
    # A sensor power-cycled into its EEPROM auto-start streams 0xCC while the driver
    # asked for 0xC2: neither the stall watch (last_data_mono) nor the wait for the
    # stream (link.records) may take those records for the stream (found by the long
    # soak: the node stayed on the wrong stream for good).
    config = SimulatorConfig(seed=8, streaming_at_start=lay.ACCEL_ANG_RATE_MAG_ORIENTATION,
                             rate_hz=200.0)
    with PtySimulator(config) as sim:
        talk = Talk(sim, stream=lay.ACCEL_ANG_RATE, request_timeout=0.2, continuous_retries=2)
        try:
            talk.dialogue.initialise(talk.link)
            assert talk.dialogue.start_continuous(talk.link)
            assert sim.streaming == lay.ACCEL_ANG_RATE
            sim.set_faults(ignore_first_continuous=True)
            sim.power_cycle()  # back up streaming 0xCC, as its EEPROM says
            assert sim.wait_until(lambda: sim.streaming == lay.ACCEL_ANG_RATE_MAG_ORIENTATION)
            time.sleep(0.3)
            records, last = talk.link.records, talk.link.last_data_mono
            time.sleep(0.3)
            assert talk.records > 0  # 0xCC records reach the consumer (counted, not ours)
            assert (talk.link.records, talk.link.last_data_mono) == (records, last)
            # The first request is ignored: only 0xC2 records end the wait, not the 0xCC.
            assert talk.dialogue.start_continuous(talk.link)
            assert sim.streaming == lay.ACCEL_ANG_RATE
        finally:
            talk.close()


def test_the_divider_is_written_once_through_lost_replies_and_restarts():
    # Replies dropped and commands lost on the radio, dialogues restarted with the same
    # setting: the sensor receives the write of its divider once, never again.
    faults = FaultConfig(drop_probability=0.4, command_loss_probability=0.3)
    with PtySimulator(SimulatorConfig(seed=9, faults=faults)) as sim:
        done = 0
        for _ in range(6):
            talk = Talk(sim, data_rate_hz=200.0, request_timeout=0.15)
            try:
                talk.dialogue.initialise(talk.link)
                done += 1
            except DeviceError:
                pass  # a dialogue may give up on so rough a radio; the next one goes on
            finally:
                talk.close()
        assert done > 0
        assert len(sim.eeprom_writes()) == 1
        assert sim.eeprom[0xFCA2] == 256


def test_a_dialogue_never_writes_the_same_divider_twice():
    # Once written, a divider is not written again by the same dialogue, even when the
    # sensor (another one put in its place, or a reply that only looks valid) says
    # otherwise later: it goes on with what the sensor says and says why.
    with PtySimulator(SimulatorConfig(seed=10)) as sim:
        talk = Talk(sim, data_rate_hz=200.0)
        try:
            talk.dialogue.initialise(talk.link)
            assert talk.dialogue.eeprom_writes == 1
            # Someone else sets 512 again.
            talk.link.request(commands.write_eeprom(0xFCA2, 512), lay.WRITE_EEPROM, 0.5, 3)
            talk.dialogue.initialise(talk.link)
            assert talk.dialogue.eeprom_writes == 1 and talk.dialogue.divider == 512
            assert any('not writing its EEPROM again' in m for _, m in talk.warnings)
        finally:
            talk.close()


@pytest.mark.parametrize('stream', [lay.ACCEL_ANG_RATE, lay.ACCEL_ANG_RATE_MAG_ORIENTATION])
def test_a_sensor_still_streaming_loses_no_record_to_the_first_polls(stream):
    """
    Found by the hour-long soak: its stop lost, the sensor streams 0xC2 while started in full.

    A record of the stream that came while a 0xC2 poll waited was taken for
    the poll's reply: neither published nor the answer. Every record the
    sensor streamed in that time must reach the consumer.
    """
    with PtySimulator(SimulatorConfig(seed=8, divider=171)) as sim:  # 300 Hz
        talk = Talk(sim, stream=stream)
        try:
            talk.link.send(commands.set_continuous(stream))  # streaming, as if the stop was lost
            while talk.records < 40:
                time.sleep(0.01)
            begin = time.time()
            for _ in range(20):  # the first polls, many times over: each a chance to collide
                talk.dialogue.initialise(talk.link)
            end = time.time()
            time.sleep(0.1)
        finally:
            talk.close()
        streamed = [e.timer for e in sim.truth if e.source == 'stream' and e.valid
                    and e.write_time is not None and begin <= e.write_time <= end]
        assert len(streamed) > 100
        assert set(streamed) <= set(talk.timers), 'records of the stream taken for replies'
