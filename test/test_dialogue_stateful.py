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
The start-up dialogue against a hostile base station, as a hypothesis state machine.

A SensorDialogue (device/dialogue.py) and its link talk, through the hostile
station of harness/hostile.py, to the simulated base station. Hypothesis
interleaves the dialogue's steps (quiet, initialise, continuous mode, resume)
with attacks armed for one phase of the dialogue (every mode of the
station), and with spells of good behaviour. Whatever the order:

- a step ends with success or with the dialogue's own DeviceTimeout, never
  with another exception, and within its bounded time;
- the consumer is handed only records from the configured address;
- a started stream delivers records of the configured stream;
- once the station behaves, initialise and continuous mode succeed;
- the data-rate divider is written to the EEPROM once, for the one change of
  setting, however the attacks cut the dialogue (never twice).
"""

import threading
import time

from harness.hostile import Attack, HostileStation, MODES, PHASES
from hypothesis import HealthCheck, settings, strategies as st
from hypothesis.stateful import invariant, precondition, rule, RuleBasedStateMachine
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.data_rate import divider_for_rate
from i3dmgx2_driver.device.dialogue import SensorDialogue
from i3dmgx2_driver.device.link import DeviceError, DeviceLink, LinkOptions
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from log_lines import Log
import pytest

pytestmark = pytest.mark.slow

ADDRESS = 95
RATE_HZ = 200.0
#: The longest any one step may take under attack (s): every wait of the dialogue is bounded.
STEP_LIMIT = 20.0


class HostileDialogue(RuleBasedStateMachine):
    """One simulator, one hostile station, one link and dialogue per example."""

    def __init__(self) -> None:
        super().__init__()
        self.sim = PtySimulator(SimulatorConfig(address=ADDRESS, seed=11, rate_hz=400.0,
                                                wire_baud=None)).start()
        self.station = HostileStation(self.sim.port, ADDRESS, seed=5)
        self.station.start()
        self.foreign: list[int] = []
        self.records: list[int] = []
        self.link = DeviceLink(SerialPort(self.station.path, low_latency=False), ADDRESS,
                               self._on_record, LinkOptions(select_timeout=0.05))
        self.dialogue = SensorDialogue(
            DeviceConfig(port=self.station.path, address=ADDRESS, data_rate_hz=RATE_HZ,
                         request_timeout=0.15, continuous_retries=3),
            Log(), lambda key, message, period: None, threading.Event())
        self.dialogue.quiet(self.link)
        self.link.start()
        self.initialised = False

    def _on_record(self, packet, read_time, read_mono) -> None:
        if packet.address != ADDRESS:
            self.foreign.append(packet.address)
        self.records.append(type(packet.record).__name__)

    def _step(self, action) -> bool:
        """Run one dialogue step; True if it succeeded, False on its DeviceTimeout."""
        start = time.monotonic()
        try:
            action()
            ok = True
        except DeviceError:
            ok = False
        assert time.monotonic() - start < STEP_LIMIT
        return ok

    @rule(phase=st.sampled_from(PHASES), mode=st.sampled_from(MODES),
          seconds=st.floats(0.05, 0.6))
    def attack(self, phase, mode, seconds):
        self.station.arm(Attack(phase, mode, seconds))

    @rule()
    def quiet(self):
        self.dialogue.quiet(self.link)

    @rule()
    def initialise(self):
        if self._step(lambda: self.dialogue.initialise(self.link)):
            self.initialised = True

    @precondition(lambda self: self.initialised)
    @rule()
    def stream(self):
        before = len(self.records)
        if self._step(lambda: self.dialogue.start_continuous(self.link)):
            # Records of the configured stream arrived (the wait counts only those).
            assert 'AccelAngRateMagOrientation' in self.records[before:]

    @precondition(lambda self: self.dialogue.can_resume())
    @rule()
    def resume(self):
        self.dialogue.expect_stream(self.link)
        self._step(lambda: self.dialogue.resume(self.link))

    @rule()
    def behave(self):
        """Disarm; let any attack end: the dialogue must then succeed."""
        self.station.armed = None
        while self.station.hostile:
            time.sleep(0.02)
        self.dialogue.quiet(self.link)
        assert self._step(lambda: self.dialogue.initialise(self.link))
        self.initialised = True
        assert self._step(lambda: self.dialogue.start_continuous(self.link))

    @invariant()
    def only_our_address(self):
        assert self.foreign == []

    @invariant()
    def the_divider_is_written_once_at_most(self):
        writes = [c for _, c in self.sim.eeprom_writes() if c.code == lay.WRITE_EEPROM]
        assert len(writes) <= 1, writes
        if writes:
            assert self.sim.eeprom[0xFCA2] == divider_for_rate(RATE_HZ)

    def teardown(self):
        self.link.stop()
        self.link.port.close()
        self.station.stop()
        self.sim.stop()


# Derandomised, with no example database: CI runs the same 12 sequences every time. The
# outcome of a step still depends on thread timing (a real pseudo-terminal), and a replay
# of a stored or random sequence then differs from the run that found it (hypothesis's
# FlakyFailure), which would say nothing about the dialogue. Explore more by hand with
# other settings (max_examples=200, derandomize=False).
HostileDialogue.TestCase.settings = settings(
    max_examples=12, stateful_step_count=8, deadline=None, derandomize=True, database=None,
    suppress_health_check=[HealthCheck.too_slow])
test_dialogue_against_a_hostile_base_station = HostileDialogue.TestCase
