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
The simulator's command line: ``python -m i3dmgx2_driver.simulator``.

It must print the port first (flushed, so that a script can read it at once), serve a
driver on that port, and exit with status 0 on SIGINT and SIGTERM.
"""

import os
from pathlib import Path
import selectors
import signal
import subprocess
import sys

from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.simulator import cli
import pytest
from test_simulator import Host

REPO = Path(__file__).resolve().parents[1]


class _Port:
    """Enough of a PtySimulator for Host: a port path and an address."""

    def __init__(self, port: str) -> None:
        self.port = port


def launch(*args: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    return subprocess.Popen(
        [sys.executable, '-m', 'i3dmgx2_driver.simulator', '--seed', '1', *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)


def read_line(process: subprocess.Popen, timeout: float = 20.0) -> str:
    with selectors.DefaultSelector() as selector:
        selector.register(process.stdout, selectors.EVENT_READ)
        if not selector.select(timeout):
            process.kill()
            pytest.fail('the simulator printed nothing')
    return process.stdout.readline().rstrip('\n')


@pytest.mark.slow
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_cli_prints_the_port_serves_it_and_exits_cleanly(signum):
    process = launch('--status-interval', '0.2')
    try:
        first = read_line(process)
        assert first.startswith('port: ')
        port = first[len('port: '):]
        assert os.path.islink(port)
        with Host(_Port(port)) as host:
            assert host.request(cmd.encode_command(lay.FIRMWARE_VERSION)).version == 2113
        status = read_line(process)
        assert 'records=' in status and 'commands=' in status
        process.send_signal(signum)
        assert process.wait(timeout=20) == 0, process.stderr.read()
        assert not os.path.lexists(port), 'the port goes away with the simulator'
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


@pytest.mark.slow
def test_cli_duration_and_fixed_symlink(tmp_path):
    link = tmp_path / 'gx2'
    process = launch('--duration', '0.5', '--symlink', str(link), '--quiet',
                     '--already-streaming', '--drop', '0.1')
    try:
        assert read_line(process) == f'port: {link}'
        assert process.wait(timeout=20) == 0
        assert process.stdout.read() == '', '--quiet prints the port line only'
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert not os.path.lexists(link)


@pytest.mark.slow
def test_cli_main_in_process(capsys):
    assert cli.main(['--duration', '0.3', '--static', '--nan-mag', '--rate', '500',
                     '--garbage', '0.1', '--jitter-ms', '2']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith('port: ') and 'records=' in lines[-1]


def test_cli_rejects_bad_arguments(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(['--drop', '1.5'])
    assert exit_info.value.code == 2
    assert 'probability' in capsys.readouterr().err


def test_cli_config_from_arguments():
    args = cli.build_parser().parse_args(
        ['--address', '7', '--serial', '1207', '--corrupt-checksum', '0.2', '--foreign', '0.1',
         '--needs-polled-first', '--unplug-at', '3', '--unplug-for', '1', '--ppm', '-20'])
    config = cli.config_from_args(args)
    assert config.address == 7 and config.serial_number == '1207'
    assert config.faults.corrupt_checksum_probability == 0.2
    assert config.faults.foreign_probability == 0.1 and config.faults.needs_polled_first
    assert (config.faults.unplug_at, config.faults.unplug_seconds) == (3.0, 1.0)
    assert config.clock_ppm == -20.0 and config.truth_limit == 0


def test_cli_wired_divider_and_stream_options():
    args = cli.build_parser().parse_args(['--wired', '--divider', '170', '--stream', '0xcc'])
    config = cli.config_from_args(args)
    assert config.wireless is False
    assert config.divider == 170 and config.streaming_at_start == 0xCC
    assert config.power_up_eeprom == {0xFCA2: 170, 0xFCA6: 0x00CC}
    defaults = cli.config_from_args(cli.build_parser().parse_args([]))
    assert defaults.wireless is True and defaults.divider is None
    assert defaults.streaming_at_start is False
    assert cli.config_from_args(cli.build_parser().parse_args(
        ['--divider', '0x200', '--stream', '194'])).power_up_eeprom == {
            0xFCA2: 512, 0xFCA6: 0x80C2}


@pytest.mark.parametrize('argv, message', [
    (['--divider', '169'],
     'argument --divider: the data-rate divider is an integer in 170..51200 '
     '(rate 51200/N Hz: 301.2..1 Hz), got 169'),
    (['--divider', '51201'], 'in 170..51200'),
    (['--divider', 'fast'], 'got fast'),
    (['--stream', '0xC4'],
     'argument --stream: 0xC4 is not a record the sensor can stream; streamable: 0xC1, 0xC2, '
     '0xC3, 0xC5, 0xC6, 0xC7, 0xC8, 0xCB, 0xCC, 0xCE, 0xCF, 0xD1, 0xD2, 0xD3'),
    (['--stream', 'cc'], 'cc is not a record the sensor can stream'),
    (['--wired', '--nack', '0.1'],
     'nack_probability is a fault of the radio or the base station; a wired sensor has '
     'neither'),
    (['--wired', '--foreign', '0.1'], 'foreign_probability'),
])
def test_cli_refuses_bad_presets_with_a_clear_message(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(argv)
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_cli_wired_sensor_streams_its_preset_record(tmp_path):
    link = tmp_path / 'gx2'
    process = launch('--wired', '--stream', '0xC2', '--divider', '256', '--symlink', str(link),
                     '--status-interval', '0.3')
    try:
        assert read_line(process) == f'port: {link}'
        with Host(_Port(str(link)), wireless=False) as host:
            assert host.pump_until(lambda: len(host.records(lay.ACCEL_ANG_RATE)) >= 5, 10.0)
            assert host.request(cmd.read_eeprom(0xFCA2)).value == 256
            assert host.parser.stats.checksum_failures == 0
        status = read_line(process)
        assert ' wired ' in status and 'streaming=0xC2' in status and 'rate=200Hz' in status
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=20) == 0, process.stderr.read()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
