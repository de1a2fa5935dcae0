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
``discover`` against simulated sensors: it finds exactly what is there.

And it leaves every sensor as it found it.

Each simulator is one base station with one sensor (or one wired sensor) on
its own pseudo-terminal; several run side by side. "As found" is read from the
simulator's record of every command the sensor received: only reads (0xE9,
0xEA, 0xE5), no EEPROM write, and a stream that never changed, or that was
stopped and restarted with the same record.
"""

import json
import os
import subprocess
import sys
import threading
import time
import tty

from harness.processes import REPO
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.device.identity import DeviceInfo
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
from i3dmgx2_driver.tools import discover
from i3dmgx2_driver.tools.discover import node_command, parse_addresses, port_command
from i3dmgx2_driver.tools.discover_probe import probe_port, ProbeConfig, SensorFound
import pytest

#: Commands that only read: what discovery may send a sensor it does not stop.
READS = {lay.FIRMWARE_VERSION, lay.DEVICE_IDENTIFIER, lay.READ_EEPROM}
#: A probe as patient as a loaded test machine needs; the defaults otherwise.
PATIENT = {'ping_timeout': 1.0, 'request_timeout': 0.5}


def left_as_found(sim: PtySimulator, restarted: bool = False) -> None:
    """Assert that the sensor got no write and streams what it streamed at power-up."""
    assert sim.eeprom_writes() == []
    streams = [code for _, code in sim.stream_changes]
    start = streams[0]
    if restarted:
        assert streams == [start, 0, start], 'stopped once, restarted with the same record'
    else:
        assert streams == [start], 'the stream was never touched'
        assert set(codes(sim)) <= READS
    assert sim.streaming == start


def info(serial: str) -> DeviceInfo:
    """Return the identity a simulated wireless sensor gives."""
    return DeviceInfo('3DM-GX2', serial, '3DM-GX2 Wireless', '5g 300deg/s', '2.1.13')


def sensor_2017(seed: int, streaming: int) -> PtySimulator:
    """Return sensor 17 (serial 2017), streaming ``streaming`` from the start."""
    return PtySimulator(SimulatorConfig(address=17, serial_number='2017', seed=seed,
                                        streaming_at_start=streaming))


def restarted_as_found(sim: PtySimulator, streaming: int) -> None:
    """Check that discovery's last command started ``streaming`` again, as it found it."""
    assert sim.commands[-1][1].code == lay.SET_CONTINUOUS
    assert sim.commands[-1][1].args == (streaming,)
    left_as_found(sim, restarted=True)


def codes(sim: PtySimulator) -> list[int]:
    """Command bytes the sensor received, in order."""
    return [command.code for _, command in sim.commands]


def run_discover(*args: str, stderr=subprocess.PIPE) -> subprocess.CompletedProcess:
    """Run ``python -m i3dmgx2_driver.tools.discover`` from this source tree."""
    env = dict(os.environ, PYTHONPATH=REPO + os.pathsep + os.environ.get('PYTHONPATH', ''))
    return subprocess.run([sys.executable, '-m', 'i3dmgx2_driver.tools.discover', *args],
                          stdout=subprocess.PIPE, stderr=stderr, text=True, env=env,
                          cwd=REPO, timeout=60)


@pytest.mark.parametrize('text, addresses', [
    ('95', [95]),
    ('1-5', [1, 2, 3, 4, 5]),
    ('10-12, 3,11,7', [3, 7, 10, 11, 12]),
    ('65530-65534', [65530, 65531, 65532, 65533, 65534]),
])
def test_address_lists(text, addresses):
    assert parse_addresses(text) == addresses


@pytest.mark.parametrize('text, words', [
    ('0', 'addresses are 1..65534'),
    ('65535', 'addresses are 1..65534'),
    ('9-3', 'a range low-high'),
    ('1-x', 'not an address'),
    ('1,,2', 'empty item'),
])
def test_bad_address_lists_say_what_is_valid(text, words):
    with pytest.raises(ValueError, match=words):
        parse_addresses(text)


@pytest.mark.slow
def test_probe_finds_each_sensor_and_leaves_it_as_it_was():
    with PtySimulator(SimulatorConfig(address=42, serial_number='2042', seed=71)) as polled, \
            PtySimulator(SimulatorConfig(address=17, serial_number='2017', seed=72,
                                         streaming_at_start=lay.ACCEL_ANG_RATE)) as streaming:
        found = probe_port(polled.port, ProbeConfig(**PATIENT))
        assert found.status == 'probed' and found.base_station is True
        assert found.pinged == 99
        assert found.sensors == (SensorFound(42, 'ping', info('2042'), 512, 0, False,
                                             None, None),)
        assert found.sensors[0].rate_hz == 100.0

        records_before = streaming.stats.records_sent
        found = probe_port(streaming.port, ProbeConfig(**PATIENT))
        assert found.base_station is True
        assert found.pinged == 98, 'the address heard streaming is not pinged'
        [sensor] = found.sensors
        assert sensor._replace(lqi=None, rssi=None) == SensorFound(
            17, 'stream', info('2017'), 512, lay.ACCEL_ANG_RATE, False, None, None)
        assert 0 < sensor.lqi <= 255 and 0 < sensor.rssi <= 255

        # Left as found: only reads, and the stream never stopped.
        assert set(codes(polled)) == READS and set(codes(streaming)) == READS
        left_as_found(polled)
        left_as_found(streaming)
        assert streaming.wait_until(
            lambda: streaming.stats.records_sent > records_before + 100, timeout=10)
        for sim in (polled, streaming):
            pinged = sorted(e.address for e in sim.host_log if e.kind == 'ping')
            assert len(pinged) == len(set(pinged)), 'each address is pinged once'


@pytest.mark.slow
def test_a_sensor_outside_the_factory_range_needs_its_range():
    with PtySimulator(SimulatorConfig(address=4242, serial_number='4242', seed=73)) as sim:
        found = probe_port(sim.port, ProbeConfig(**PATIENT))
        assert (found.status, found.base_station, found.sensors, found.pinged) == \
            ('probed', True, (), 99)
        assert codes(sim) == [], 'nothing but pings reached a sensor'
        found = probe_port(sim.port, ProbeConfig(addresses=range(4200, 4300), **PATIENT))
        assert [(s.address, s.info.serial_number) for s in found.sensors] == [(4242, '4242')]


@pytest.mark.slow
def test_a_busy_port_is_reported_and_left_alone():
    with PtySimulator(SimulatorConfig(seed=74)) as sim:
        holder = SerialPort(sim.port)
        try:
            found = probe_port(sim.port, ProbeConfig(**PATIENT))
        finally:
            holder.close()
        assert found.status == 'busy' and found.sensors == () and found.base_station is None
        assert sim.port in found.message and 'in use' in found.message
        assert sim.host_log == []


@pytest.mark.slow
def test_a_port_with_nothing_behind_it():
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        found = probe_port(os.ttyname(slave), ProbeConfig(request_timeout=0.1,
                                                          request_retries=1))
        assert (found.status, found.base_station, found.sensors, found.pinged) == \
            ('probed', False, (), 2)
    finally:
        os.close(slave)
        os.close(master)
    assert probe_port('/nonexistent/ttyUSB7').status == 'missing'


@pytest.mark.slow
def test_stop_streams_restarts_the_same_record():
    with sensor_2017(75, lay.EULER_ANGLES) as sim:
        found = probe_port(sim.port, ProbeConfig(stop_streams=True, **PATIENT))
        [sensor] = found.sensors
        assert (sensor.info, sensor.streaming, sensor.restarted, sensor.note) == \
            (info('2017'), lay.EULER_ANGLES, True, '')
        received = codes(sim)
        stop = received.index(lay.STOP_CONTINUOUS)
        assert set(received[:stop]) == set(), 'not a request while it streamed'
        assert set(received[stop + 1:-1]) <= READS | {lay.STOP_CONTINUOUS}
        restarted_as_found(sim, lay.EULER_ANGLES)


@pytest.mark.slow
def test_a_sensor_that_cannot_answer_while_streaming_is_stopped_read_and_restarted():
    # Every command is lost until the first 0xFA reaches the base station: the
    # radio of a busy stream. Combined mode fails; the stream is stopped, the
    # sensor read, and its stream restarted with the same record.
    with sensor_2017(76, lay.ACCEL_ANG_RATE_MAG) as sim:
        sim.set_faults(command_loss_probability=1.0)

        def clear_on_stop():
            sim.wait_until(lambda: any(e.raw[:1] == bytes((lay.STOP_CONTINUOUS,))
                                       for e in sim.host_log), timeout=30)
            sim.set_faults(command_loss_probability=0.0)

        watcher = threading.Thread(target=clear_on_stop, daemon=True)
        watcher.start()
        found = probe_port(sim.port, ProbeConfig(request_timeout=0.2, ping_timeout=1.0))
        watcher.join(timeout=5)
        [sensor] = found.sensors
        assert (sensor.found_by, sensor.info, sensor.streaming, sensor.restarted) == \
            ('stream', info('2017'), lay.ACCEL_ANG_RATE_MAG, True)
        restarted_as_found(sim, lay.ACCEL_ANG_RATE_MAG)


@pytest.mark.slow
def test_the_rate_is_the_sensors_own():
    with PtySimulator(SimulatorConfig(address=3, serial_number='2003', seed=77,
                                      divider=256)) as sim:
        [sensor] = probe_port(sim.port, ProbeConfig(**PATIENT)).sensors
        assert (sensor.address, sensor.divider, sensor.rate_hz) == (3, 256, 200.0)
        left_as_found(sim)


@pytest.mark.slow
def test_a_wired_sensor_is_found_without_a_base_station():
    with PtySimulator(SimulatorConfig(wireless=False, serial_number='5001', seed=78)) as sim:
        found = probe_port(sim.port, ProbeConfig(request_timeout=0.5))
        assert (found.base_station, found.pinged) == (False, 2)
        assert found.sensors == (SensorFound(None, 'wired', info('5001'), 512, 0, False,
                                             None, None),)
        assert not found.sensors[0].wireless
        left_as_found(sim)


@pytest.mark.slow
@pytest.mark.parametrize('stop_streams', [False, True], ids=['combined', 'stop-streams'])
def test_a_streaming_wired_sensor_is_found_by_its_stream(stop_streams):
    with PtySimulator(SimulatorConfig(wireless=False, serial_number='5002', seed=79,
                                      streaming_at_start=lay.EULER_ANGLES,
                                      divider=1024)) as sim:
        found = probe_port(sim.port, ProbeConfig(stop_streams=stop_streams,
                                                 request_timeout=0.5))
        assert (found.base_station, found.pinged) == (False, 0), 'no ping: it streams wired'
        assert found.sensors == (SensorFound(None, 'stream', info('5002'), 1024,
                                             lay.EULER_ANGLES, stop_streams, None, None),)
        left_as_found(sim, restarted=stop_streams)


def test_command_lines():
    wireless = SensorFound(95, 'ping', None, None, 0, False, None, None)
    wired = SensorFound(None, 'wired', None, None, 0, False, None, None)
    assert node_command('/dev/serial/by-id/usb-FTDI_X-if00-port0', wireless) == (
        'ros2 run i3dmgx2_driver node --ros-args '
        '-p port:=/dev/serial/by-id/usb-FTDI_X-if00-port0 -p address:=95')
    assert node_command('/dev/ttyUSB0', wired) == (
        'ros2 run i3dmgx2_driver node --ros-args -p port:=/dev/ttyUSB0 '
        '-p wireless:=false -p address:=1')


def test_one_command_for_a_base_station_with_several_sensors():
    found = [SensorFound(a, 'ping', None, None, 0, False, None, None) for a in (17, 95)]
    assert port_command('/dev/i3dmgx2', found) == (
        'ros2 run i3dmgx2_driver node --ros-args -p port:=/dev/i3dmgx2 '
        "-p 'addresses:=[17,95]'")
    assert port_command('/dev/i3dmgx2', found[1:]) == node_command('/dev/i3dmgx2', found[1])


@pytest.mark.slow
def test_discover_prints_one_command_that_serves_every_sensor_behind_the_base_station():
    config = SimulatorConfig(addresses=(17, 95, 40), seed=87,
                             faults=FaultConfig(already_streaming=True))
    with PtySimulator(config) as sim:
        result = run_discover('--port', sim.port)
        assert result.returncode == 0, result.stderr
        lines = result.stdout.splitlines()
        commands = [line.strip() for line in lines if 'ros2 run' in line]
        assert commands == [f'ros2 run i3dmgx2_driver node --ros-args -p port:={sim.port} '
                            f"-p 'addresses:=[17,40,95]'"], result.stdout
        assert '3 sensors' in result.stdout
        for address in (17, 95, 40):
            assert sim.streaming_of(address) == lay.ACCEL_ANG_RATE_MAG_ORIENTATION


def fake_sysfs(tmp_path, timer: int | None) -> tuple[str, str]:
    """Return a port path and a /sys/class/tty whose entry for it has ``timer``."""
    port = tmp_path / 'dev' / 'ttyUSB7'
    port.parent.mkdir()
    port.write_text('')
    entry = tmp_path / 'sys' / 'ttyUSB7' / 'device'
    entry.mkdir(parents=True)
    if timer is not None:
        (entry / 'latency_timer').write_text(f'{timer}\n')
    return str(port), str(tmp_path / 'sys')


@pytest.mark.parametrize('timer, group, member, words', [
    (16, 'dialout', True, ['its latency timer is 16 ms']),
    (1, 'dialout', False, ['belongs to the dialout group, which you are not in']),
    (16, 'root', False, ['latency timer is 16 ms', 'belongs to the root group',
                         'joining root would give you far more than this port']),
    (None, 'uucp', False, ['belongs to the uucp group']),
])
def test_discover_mentions_the_udev_rule_where_it_would_help(tmp_path, monkeypatch, timer,
                                                             group, member, words):
    path, sys_class_tty = fake_sysfs(tmp_path, timer)
    monkeypatch.setattr(discover, 'port_group', lambda p: (group, member))
    note = discover.udev_note(path, '', sys_class_tty)
    for word in words:
        assert word in note
    assert 'sudo udevadm control --reload-rules' in note and '99-i3dmgx2.rules' in note


@pytest.mark.parametrize('timer', [1, None])
def test_discover_says_nothing_of_the_rule_where_all_is_well(tmp_path, monkeypatch, timer):
    path, sys_class_tty = fake_sysfs(tmp_path, timer)
    monkeypatch.setattr(discover, 'port_group', lambda p: ('dialout', True))
    assert discover.udev_note(path, '', sys_class_tty) == ''
    # A refused open whose message already recommends the rule is not told twice.
    monkeypatch.setattr(discover, 'port_group', lambda p: ('root', False))
    assert discover.udev_note(path, 'permission denied ...: install the udev rule ...',
                              sys_class_tty) == ''


# -- the command line ------------------------------------------------------------


@pytest.mark.slow
def test_command_line_reports_every_port_as_json():
    with PtySimulator(SimulatorConfig(address=42, serial_number='2042', seed=81,
                                      firmware_version=2103)) as a, \
            PtySimulator(SimulatorConfig(address=17, serial_number='2017', seed=82,
                                         streaming_at_start=0xCC)) as b, \
            PtySimulator(SimulatorConfig(address=4242, seed=83)) as none, \
            PtySimulator(SimulatorConfig(address=7, seed=84)) as busy, \
            PtySimulator(SimulatorConfig(wireless=False, serial_number='5003', seed=88)) as wired:
        holder = SerialPort(busy.port)
        try:
            result = run_discover('--json', '--port', a.port, '--port', b.port,
                                  '--port', none.port, '--port', busy.port,
                                  '--port', wired.port)
        finally:
            holder.close()
        assert result.returncode == 0, result.stderr
        assert result.stderr == '', 'no progress when not on a terminal'
        report = json.loads(result.stdout)
        assert report['found'] == 3
        ports = {p['device']: p for p in report['ports']}
        assert [ports[s.port]['status'] for s in (a, b, none, busy, wired)] == \
            ['probed', 'probed', 'probed', 'busy', 'probed']
        [third] = ports[wired.port]['sensors']
        assert (third['link'], third['address'], third['serial_number'], third['command']) == \
            ('wired', None, '5003', f'ros2 run i3dmgx2_driver node --ros-args '
                                    f'-p port:={wired.port} -p wireless:=false -p address:=1')
        assert ports[wired.port]['base_station'] is False
        assert ports[none.port]['sensors'] == [] and ports[none.port]['base_station'] is True
        assert busy.port in ports[busy.port]['message']
        [first] = ports[a.port]['sensors']
        assert first == {
            'address': 42, 'link': 'wireless', 'found_by': 'ping',
            'model_number': '3DM-GX2', 'serial_number': '2042',
            'model_name': '3DM-GX2 Wireless', 'options': '5g 300deg/s', 'firmware': '2.1.03',
            'firmware_lacks': ['euler', 'stabilised', 'temperatures', 'bias store'],
            'firmware_note': 'firmware 2.1.03: no euler, stabilised, temperatures, bias store',
            'rate_divider': 512, 'rate_hz': 100.0, 'streaming': None,
            'stream_restarted': False, 'lqi': None, 'rssi': None, 'note': None,
            'command': f'ros2 run i3dmgx2_driver node --ros-args -p port:={a.port} '
                       f'-p address:=42'}
        [second] = ports[b.port]['sensors']
        assert (second['address'], second['found_by'], second['streaming'],
                second['stream_restarted']) == (17, 'stream', '0xCC', False)
        # A firmware that has everything the driver offers: nothing lacks, no note.
        assert (second['firmware'], second['firmware_lacks'], second['firmware_note']) == \
            ('2.1.13', [], None)
        for sim in (a, b, none, busy, wired):
            left_as_found(sim)
        assert busy.host_log == []


@pytest.mark.slow
def test_command_line_prints_the_driver_command_and_exit_status():
    with PtySimulator(SimulatorConfig(address=42, serial_number='2042', seed=85)) as sim:
        result = run_discover('--port', sim.port)
        assert result.returncode == 0, result.stderr
        assert f'ros2 run i3dmgx2_driver node --ros-args -p port:={sim.port} -p address:=42' \
            in result.stdout.splitlines()[-1]
        assert '2042' in result.stdout and '100.0 Hz' in result.stdout
    with PtySimulator(SimulatorConfig(address=4242, seed=86)) as sim:
        result = run_discover('--port', sim.port)
        assert result.returncode == 1, result.stdout + result.stderr
        assert 'a base station, but no sensor answered (pinged 99 addresses)' in result.stdout
        assert '--addresses 1-65534' in result.stdout
    result = run_discover('--addresses', '0-100')
    assert result.returncode == 2
    assert "'0-100': addresses are 1..65534" in result.stderr


@pytest.mark.slow
def test_progress_is_shown_on_a_terminal():
    master, slave = os.openpty()
    try:
        with PtySimulator(SimulatorConfig(address=42, seed=87)) as sim:
            result = run_discover('--port', sim.port, stderr=slave)
        assert result.returncode == 0
        os.set_blocking(master, False)
        shown = b''
        deadline = time.monotonic() + 5
        while b'pinging 99/99' not in shown and time.monotonic() < deadline:
            try:
                shown += os.read(master, 65536)
            except BlockingIOError:
                time.sleep(0.05)
        assert b'listening for streams' in shown
        assert f'\r\x1b[K{sim.port}: pinging 99/99'.encode() in shown
    finally:
        os.close(slave)
        os.close(master)
