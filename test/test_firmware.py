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
Every firmware the sensor shipped with: each command's least firmware, and who reads it.

The codec's table and what it says (codec/command_firmware.py), the simulator that
answers only what its firmware has, at each boundary (the version below a
command's least firmware and that version itself) for every gated command,
the dialogue that stops at a stream the firmware lacks, the temperature
poller, the bias store's refusal, the self test's skipped step, and what
discover and bringup print. The node processes are test_node_firmware.py's.
"""

import io
import random

from i3dmgx2_driver.codec import command_firmware as fw, commands, layouts as lay, streams
from i3dmgx2_driver.codec.errors import EncodeError
from i3dmgx2_driver.device.identity import DeviceInfo
from i3dmgx2_driver.device.link import DeviceTimeout
from i3dmgx2_driver.device.port import PortUnusable
from i3dmgx2_driver.device.self_test import format_report, Step, temperature_step
from i3dmgx2_driver.device.sensor_firmware import FirmwareLacksStream, SensorFirmware
from i3dmgx2_driver.device.status import DeviceStatus
from i3dmgx2_driver.ros import diagnostic_statuses as d
from i3dmgx2_driver.ros.temperature import TemperaturePoller
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.cli import build_parser, config_from_args
from i3dmgx2_driver.simulator.sensor import DEFAULT_FIRMWARE, SensorSpec, SimulatedSensor
from i3dmgx2_driver.simulator.sensor_unit import unit_specs
from i3dmgx2_driver.tools import bringup, discover
from i3dmgx2_driver.tools.discover_probe import PortProbe, SensorFound
from i3dmgx2_driver.tools.port_listing import PortInfo
from log_lines import Log
import pytest
from test_sensor_dialogue import Talk

#: The manual's least firmware of every command that needs more than 2.1.00.
GATED = {lay.EULER_ANGLES_ANG_RATE: 2105, lay.TRANSFER_TO_NON_VOLATILE: 2112,
         lay.TEMPERATURES: 2112, lay.STABILISED_ACCEL_ANG_RATE_MAG: 2112,
         lay.DELTA_ANGLE_VELOCITY_MAG: 2113}
#: Arguments of the gated commands that take any.
ARGS = {lay.TRANSFER_TO_NON_VOLATILE: (2,)}
BOUNDARIES = [(code, version) for code, least in GATED.items() for version in (least - 1, least)]


def _id(value) -> str:
    return f'0x{value[0]:02X}@{fw.text(value[1])}' if isinstance(value, tuple) else str(value)


# -- the table -------------------------------------------------------------------------

def test_the_table_holds_every_commands_least_firmware():
    assert {code: layout.firmware for code, layout in lay.LAYOUTS.items()
            if layout.firmware != lay.FIRMWARE_BASE} == GATED
    assert lay.FIRMWARE_BASE == 2100 and fw.NEWEST == 2113 == DEFAULT_FIRMWARE


@pytest.mark.parametrize('code', sorted(GATED), ids=lambda c: f'0x{c:02X}')
def test_a_command_is_had_from_its_least_firmware_on(code):
    least = GATED[code]
    assert not fw.has(least - 1, code) and fw.has(least, code) and fw.has(least + 1, code)
    assert fw.has(None, code), 'a firmware not read checks nothing'
    assert fw.refusal('it', code, least) == ''
    assert fw.refusal('it', code, least - 1) == \
        f'it (0x{code:02X}) needs firmware {fw.text(least)}; this sensor has ' \
        f'{fw.text(least - 1)}'


def test_what_a_firmware_lacks_is_said_in_the_users_words():
    assert fw.summary(2103) == 'firmware 2.1.03: no euler, stabilised, temperatures, bias store'
    assert fw.summary(2105) == 'firmware 2.1.05: no stabilised, temperatures, bias store'
    assert fw.summary(2112) == 'firmware 2.1.12' and fw.lacks(2112) == []
    assert 'not checked' in fw.summary(None) and fw.lacks(None) == []
    assert fw.stream_refusal(streams.BY_NAME['euler'], 2103) == (
        'euler (0xCF) needs firmware 2.1.05; this sensor has 2.1.03; it offers full, '
        'inertial_orientation, inertial_mag, inertial')
    assert fw.stream_refusal(streams.BY_NAME['euler'], 2105) == ''
    assert [s.name for s in fw.offered(2111)] == [
        'full', 'inertial_orientation', 'inertial_mag', 'inertial', 'euler']


@pytest.mark.parametrize('version', [2100, 2103, 2112, 2113, 3000, 12999])
def test_a_version_is_written_and_read_as_the_manual_writes_it(version):
    assert fw.parse(fw.text(version)) == version
    assert fw.version_of('') is None


@pytest.mark.parametrize('text', ['2.1.3', '2103', 'v2.1.03', '2.10.03', ''])
def test_a_version_written_otherwise_says_how_to_write_it(text):
    with pytest.raises(ValueError, match=r'major\.minor\.patch with two patch digits'):
        fw.parse(text)


@pytest.mark.parametrize('code', [lay.WRITE_EEPROM, lay.STOP_CONTINUOUS, lay.SET_CONTINUOUS,
                                  lay.FIRMWARE_VERSION, lay.CAPTURE_GYRO_BIAS,
                                  lay.TRANSFER_TO_NON_VOLATILE, lay.PING, 0x77],
                         ids=lambda c: f'0x{c:02X}')
def test_set_continuous_takes_only_a_record_the_sensor_can_stream(code):
    with pytest.raises(EncodeError, match=f'0x{code:02X} is not a record the sensor can '
                                          f'stream; streamable records: 0xC1, '):
        commands.set_continuous(code)


def test_set_continuous_takes_every_streamable_record_and_0():
    assert {s.code for s in streams.STREAMS} <= lay.STREAMABLE
    for code in (0, *lay.STREAMABLE):
        assert commands.set_continuous(code) == bytes((lay.SET_CONTINUOUS, 0xC1, 0x29, code))


# -- the simulated sensor at each boundary -----------------------------------------------

@pytest.mark.parametrize('code, version', BOUNDARIES, ids=_id)
def test_the_simulator_answers_a_command_only_from_its_least_firmware(code, version):
    sensor = SimulatedSensor(SensorSpec(firmware_version=version), seed=1)
    replies = sensor.handle(commands.encode_command(code, *ARGS.get(code, ())), 1.0)
    has = version >= GATED[code]
    assert [reply.code for reply in replies] == ([code] if has else [])
    assert sensor.ignored == (0 if has else 1)
    if code in lay.STREAMABLE:  # and streams it only then
        replies = sensor.handle(commands.set_continuous(code), 2.0)
        assert sensor.streaming == (code if has else 0)
        assert [reply.code for reply in replies] == ([lay.SET_CONTINUOUS] if has else [])


def test_the_simulators_firmware_is_set_for_every_sensor_or_one():
    args = build_parser().parse_args(['--address', '17', '--address', '95', '--firmware',
                                      '2.1.03', '--firmware', '95=2.1.12'])
    config = config_from_args(args)
    assert (config.firmware_of(17), config.firmware_of(95)) == (2103, 2112)
    assert [spec.firmware_version for spec, _ in unit_specs(config, random.Random(0))] == \
        [2103, 2112]
    assert config_from_args(build_parser().parse_args([])).firmware_version == 2113
    with pytest.raises(ValueError, match='firmware_versions: 40 is none of the sensors'):
        SimulatorConfig(firmware_versions={40: 2103})


def test_a_bad_firmware_argument_exits_2_saying_how_to_write_it(capsys):
    with pytest.raises(SystemExit) as exited:
        build_parser().parse_args(['--firmware', '2.1.3'])
    assert exited.value.code == 2
    assert 'two patch digits (2.1.03, 2.1.13)' in capsys.readouterr().err


# -- the node's pieces -------------------------------------------------------------------

def known(version: str) -> SensorFirmware:
    firmware = SensorFirmware()
    firmware.learn(version)
    return firmware


class RequestLink:
    """A link that times every request out, and counts them (the poller's only use)."""

    def __init__(self) -> None:
        self.asked: list[int] = []

    def request(self, data: bytes, code: int, *args) -> None:
        self.asked.append(code)
        raise DeviceTimeout('no reply')


class LoggingNode:
    """What the temperature poller needs of a node with a period of 0: its logger."""

    def __init__(self) -> None:
        self.log = Log()

    def get_logger(self) -> Log:
        return self.log


@pytest.mark.parametrize('version, polled', [('2.1.11', False), ('2.1.12', True), ('', True)])
def test_the_temperature_is_polled_only_from_firmware_2_1_12(version, polled):
    node, link = LoggingNode(), RequestLink()
    poller = TemperaturePoller(node, lambda: link, 'imu_link', 0.0, None,
                               firmware=known(version))
    poller.period = 1.0  # as the parameter says; period 0 only keeps the thread off here
    for _ in range(3):
        assert not poller.poll()
    assert link.asked == ([lay.TEMPERATURES] * 3 if polled else [])
    if polled:
        assert poller.unavailable == ''
        return
    assert poller.unavailable == ('the temperature poll (0xD1) needs firmware 2.1.12; this '
                                  'sensor has 2.1.11')
    assert node.log.lines == [('warning', f'temperature_period 1 s: {poller.unavailable}: the '
                                          f'temperature is not polled (imu/temperature stays '
                                          f'silent)')], 'said once'


def test_diagnostics_say_the_temperature_is_unavailable_and_no_fault():
    info = DeviceInfo('3DM-GX2', '3095', '3DM-GX2 Wireless', '5g 300deg/s', '2.1.03')
    why = 'the temperature poll (0xD1) needs firmware 2.1.12; this sensor has 2.1.03'
    status = d.device_status(DeviceStatus(info=info, connections=1, divider=512), 95, None,
                             why)
    assert status.level == d.OK
    assert status.value('accel temperature (C)') == f'unavailable on this firmware: {why}'


def test_the_self_test_skips_a_step_the_firmware_lacks_and_does_not_fail():
    step = temperature_step(None, known('2.1.11'))  # no link: nothing is sent
    assert step == Step('temperatures respond (0xD1)', True,
                        'skipped: 0xD1 needs firmware 2.1.12; this sensor has 2.1.11', True)
    report = format_report([Step('a', True, 'x'), step])
    assert report.splitlines() == [
        'PASS a: x',
        'SKIP temperatures respond (0xD1): skipped: 0xD1 needs firmware 2.1.12; this sensor '
        'has 2.1.11',
        'self test passed: 1/1 steps passed, 1 skipped (the firmware lacks them)']
    assert temperature_step(RequestLink(), known('2.1.12')) == \
        Step('temperatures respond (0xD1)', False, 'no reply'), 'from 2.1.12 it is asked'


# -- the tools ----------------------------------------------------------------------------

def test_discover_prints_what_the_firmware_lacks():
    def sensor(address: int, version: str) -> SensorFound:
        info = DeviceInfo('3DM-GX2', str(address), 'GX2', '', version)
        return SensorFound(address, 'ping', info, 512, 0, False, None, None)

    port = PortInfo('/dev/i3dmgx2-test', None, None, None, '', None)
    probe = PortProbe(port.device, 'probed', '', True,
                      (sensor(17, '2.1.03'), sensor(95, '2.1.13')), 99, 0.1, 0.6)
    out = io.StringIO()
    discover.print_results([(port, probe)], out)
    notes = [line.strip() for line in out.getvalue().splitlines() if 'firmware 2.1' in line]
    assert notes == ['node 17: firmware 2.1.03: no euler, stabilised, temperatures, bias store']


def test_bringup_skips_a_stream_the_firmware_lacks_and_reports_it():
    said: list[str] = []
    session = bringup.Bringup(None, bringup.RecordLog(), None, said.append)
    session.firmware = 2111
    out = session.run_stream(streams.BY_NAME['stabilised'])  # no link: nothing is sent
    why = ('stabilised (0xD2) needs firmware 2.1.12; this sensor has 2.1.11; it offers full, '
           'inertial_orientation, inertial_mag, inertial, euler')
    assert out == {'stream': '0xD2 (stabilised)', 'code': '0xD2', 'skipped': why}
    assert said == [f'skipping 0xD2 (stabilised): {why}']
    report = {'started': 'now', 'port': {'path': '/dev/x'}, 'address': 95, 'folder': 'f',
              'identity': {'firmware': '2.1.11', 'firmware_lacks': fw.lacks(2111)},
              'streams': [out]}
    text = bringup.format_report(report)
    assert 'firmware                     2.1.11: no stabilised, temperatures, bias store' \
        in text, text
    assert '0xD2 (stabilised)  -         skipped: needs firmware 2.1.12' in text, text


# -- the dialogue against the simulator (a pty link) ----------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize('stream, version', [('euler', 2104), ('euler', 2105),
                                             ('stabilised', 2111), ('stabilised', 2112)])
def test_a_stream_the_firmware_lacks_stops_initialise_before_it_is_asked(stream, version):
    code = streams.BY_NAME[stream].code
    with PtySimulator(SimulatorConfig(seed=9, firmware_version=version)) as sim:
        talk = Talk(sim, stream=code)
        try:
            if version < GATED[code]:
                with pytest.raises(FirmwareLacksStream) as refused:
                    talk.dialogue.initialise(talk.link)
                assert isinstance(refused.value, PortUnusable), 'exit 2, no retry'
                assert str(refused.value).startswith(
                    f'node 95: stream {stream} (0x{code:02X}) needs firmware '
                    f'{fw.text(GATED[code])}; this sensor has {fw.text(version)}; it offers '
                    f'full, inertial_orientation, inertial_mag, inertial')
                assert lay.SET_CONTINUOUS not in [c.code for _, c in sim.commands]
                assert code not in [c.code for _, c in sim.commands], 'never asked for'
            else:
                talk.dialogue.initialise(talk.link)
                assert talk.dialogue.firmware.version == version
                assert talk.dialogue.start_continuous(talk.link) and sim.streaming == code
        finally:
            talk.close()


@pytest.mark.slow
def test_a_firmware_that_is_not_told_is_said_and_the_stream_asked_as_before():
    with PtySimulator(SimulatorConfig(seed=10)) as sim:
        talk = Talk(sim, stream=lay.EULER_ANGLES_ANG_RATE)
        request = talk.link.request

        def no_firmware(data: bytes, code: int, *args, **kwargs):
            if code == lay.FIRMWARE_VERSION:
                raise DeviceTimeout('no reply (lost, as if never answered)')
            return request(data, code, *args, **kwargs)

        talk.link.request = no_firmware
        try:
            talk.dialogue.initialise(talk.link)
            assert talk.dialogue.firmware.version is None
            [(_, said)] = [w for w in talk.warnings if w[0] == 'firmware']
            assert said.startswith('node 95 did not tell its firmware (0xE9): could not check '
                                   'that it has the stream')
            assert talk.dialogue.start_continuous(talk.link)
            assert sim.streaming == lay.EULER_ANGLES_ANG_RATE
        finally:
            talk.close()
