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
The simulator's small parts on their own, without a pty or a thread.

The EEPROM keeps what the firmware keeps; a sensor is found by its address;
the stranger never takes one of our addresses; a simulation starts once and
stops cleanly, as often as it is asked to.
"""

import os

from i3dmgx2_driver.codec import data_rate
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.eeprom import (
    AUTOSTART_ADDRESS, ERASED_WORD, FACTORY_DIVIDER, SensorEeprom,
)
from i3dmgx2_driver.simulator.faults import FaultConfig
from i3dmgx2_driver.simulator.sensor_unit import foreign_address, unit_at
import pytest


def test_eeprom_factory_words_and_presets() -> None:
    eeprom = SensorEeprom({AUTOSTART_ADDRESS: 0x80CC, 0x1234: 7})
    assert eeprom.words == {data_rate.RATE_DIVIDER_ADDRESS: FACTORY_DIVIDER,
                            AUTOSTART_ADDRESS: 0x80CC, 0x1234: 7}
    assert eeprom.rate_hz == 100.0 and eeprom.autostart == 0xCC
    assert eeprom.read(0x1234) == 7 and eeprom.read(0x4321) == ERASED_WORD


def test_eeprom_keeps_only_a_valid_divider() -> None:
    eeprom = SensorEeprom()
    assert eeprom.write(data_rate.RATE_DIVIDER_ADDRESS, data_rate.MIN_DIVIDER - 1) is False
    assert eeprom.read(data_rate.RATE_DIVIDER_ADDRESS) == FACTORY_DIVIDER
    assert eeprom.write(data_rate.RATE_DIVIDER_ADDRESS, 1024) is True
    assert eeprom.rate_hz == 50.0
    assert eeprom.write(data_rate.RATE_DIVIDER_ADDRESS, data_rate.MAX_DIVIDER + 1) is False
    assert eeprom.read(data_rate.RATE_DIVIDER_ADDRESS) == 1024
    # Any other word is stored as given, and says nothing of the rate.
    assert eeprom.write(AUTOSTART_ADDRESS, 0x00C2) is False and eeprom.autostart == 0xC2


def test_eeprom_rate_override_beats_the_divider() -> None:
    eeprom = SensorEeprom(rate_override=1000.0)
    assert eeprom.rate_hz == 1000.0
    eeprom.rate_override = None
    assert eeprom.rate_hz == 100.0


def test_unit_at_finds_the_first_or_names_the_sensors() -> None:
    sim = PtySimulator(SimulatorConfig(addresses=(17, 95), seed=1))
    assert unit_at(sim.units, None) is sim.units[17]
    assert unit_at(sim.units, 95).address == 95
    with pytest.raises(ValueError, match=r'no sensor at address 3: the sensors are \[17, 95\]'):
        unit_at(sim.units, 3)


def test_the_stranger_takes_none_of_our_addresses() -> None:
    config = SimulatorConfig(addresses=(95, 96, 97), seed=1)
    assert foreign_address(config, config.faults) == 98
    assert foreign_address(config, FaultConfig(foreign_address=96)) == 96


@pytest.mark.slow
def test_a_simulation_starts_once_and_stops_as_often_as_asked() -> None:
    sim = PtySimulator(SimulatorConfig(seed=1))
    assert not sim.started and sim.start_time is None
    sim.stop()
    with sim:
        port = sim.port
        assert sim.started and sim.start_time is not None and sim.pty.plugged.is_set()
        assert port is not None and os.path.lexists(port)
        with pytest.raises(RuntimeError, match='already started'):
            sim.start()
    assert not sim.started and not os.path.lexists(port)
    sim.stop()
