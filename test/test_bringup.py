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
``bringup``: the report a first hardware user sends, and its capture replayed.

``bringup`` runs against the simulator with radio-like delays and losses
(a few seconds per stream), must leave the sensor as it found it, and writes
its folder; the capture it wrote is then replayed through the node, which
must publish every record of its stream that the capture holds. The figures
(rate, lost records, LQI/RSSI, drift) and the timeouts' check are tested on
made-up records without a process.
"""

import json
import os
import time

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.capture.file_format import read_capture
from i3dmgx2_driver.codec import layouts, streams
from i3dmgx2_driver.codec.data_rate import RATE_DIVIDER_ADDRESS, ticks_per_cycle
from i3dmgx2_driver.codec.framing import DataPacket
from i3dmgx2_driver.codec.parser import SensorStreamParser
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.device import timeouts
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.simulator.faults import FaultConfig
from i3dmgx2_driver.tools import bringup
from i3dmgx2_driver.tools import bringup_round_trips as rt
from i3dmgx2_driver.tools.replay import Replayer
import pytest
from sensor_msgs.msg import Imu

#: The radio as a base station shows it: latency, jitter, lost packets and commands.
RADIO = {'latency_s': 0.03, 'faults': FaultConfig(drop_probability=0.02,
                                                  command_loss_probability=0.05,
                                                  jitter_ms=5.0)}
SHORT = ['--pings', '5', '--commands', '5', '--cycles', '2', '--stream-seconds', '1.5',
         '--listen', '0.5']


def test_stream_figures_count_lost_records_by_the_timer_and_fit_the_clock():
    divider = 512
    step = ticks_per_cycle(divider)
    start = TIMER_MODULUS - 3 * step  # across the timer's rollover
    log = []
    for i in range(500):
        if i in (100, 101, 300):
            continue  # three records lost on the way
        # A device clock 50 ppm slow against the host's, and 1..3 ms of delay.
        host = 10.0 + i * divider / 51200.0 * (1 + 50e-6) + 0.001 * (1 + i % 3)
        log.append((host, 0xCC, (start + i * step) % TIMER_MODULUS, 200 + i % 10, 150 + i % 5))
    got = bringup.stream_figures(log, divider, wire_time=0.0)
    assert got['records'] == 497 and got['lost'] == 3
    assert got['rate_hz'] == pytest.approx(100.0, rel=0.01)
    assert got['lqi']['count'] == 497 and got['lqi']['min'] == 200 and got['lqi']['max'] == 209
    assert 200 <= got['lqi']['median'] <= 209
    assert got['rssi']['min'] == 150
    assert got['drift_ppm'] == pytest.approx(50.0, abs=10.0)
    assert got['longest_gap_ms'] == pytest.approx(30.0, abs=1.5)


def test_a_round_trip_near_a_timeout_names_it():
    assert rt.close_calls({rt.PING: 0.01, rt.COMMAND: 0.03}) == []
    said = rt.close_calls({rt.COMMAND: 0.06, rt.RECORD_GAP: 0.6})
    assert any('RESUME_TIMEOUT = 0.1 s' in s for s in said)
    assert any('raise the node parameter read_timeout' in s for s in said)
    assert not any('REQUEST_TIMEOUT' in s for s in said), '60 ms is far from 0.5 s'
    ping = rt.close_calls({rt.PING: 0.26})
    assert any('PING_TIMEOUT = 0.3 s' in s and 'ping took up to 260 ms' in s for s in ping)
    assert any('discover --ping-timeout' in s for s in ping)


def test_every_timeout_bounds_something_bringup_measures():
    kinds = {rt.PING, rt.COMMAND, rt.CONTINUOUS_START, rt.RECORD_GAP}
    for timeout in rt.radio_timeouts():
        assert timeout.measured in kinds
        assert getattr(timeouts, timeout.name) == timeout.seconds


def test_a_report_of_a_port_that_never_opened_still_reads(tmp_path):
    report = {'started': 'now', 'folder': str(tmp_path), 'address': 95, 'baud': 115200,
              'port': {'path': '/dev/ttyUSB9'}, 'round_trips': {}, 'streams': [],
              'error': 'serial port /dev/ttyUSB9 does not exist'}
    text = bringup.format_report(report)
    assert 'Error: serial port /dev/ttyUSB9 does not exist' in text
    assert 'please attach it to your bug report' in text


def test_bad_arguments_exit_2(capsys):
    with pytest.raises(SystemExit) as info:
        bringup.main(['--port', '/dev/ttyUSB0', '--address', '0'])
    assert info.value.code == 2
    with pytest.raises(SystemExit) as info:
        bringup.main(['--port', '/dev/ttyUSB0', '--address', '5', '--streams', 'fast'])
    assert info.value.code == 2
    assert 'unknown stream' in capsys.readouterr().err


def records_in_capture(path: str, code: int, address: int) -> int:
    """Count the data packets of ``code`` from ``address`` that the capture holds."""
    _, chunks = read_capture(path)
    parser = SensorStreamParser(address=address, wireless=True)
    record_type = layouts.LAYOUTS[code].record_type
    return sum(1 for _, data in chunks for event in parser.feed(data)
               if isinstance(event, DataPacket) and type(event.record) is record_type)


@pytest.mark.slow
def test_bringup_reports_leaves_the_sensor_as_found_and_its_capture_replays(tmp_path):
    with PtySimulator(SimulatorConfig(seed=19, streaming_at_start=True, **RADIO)) as sim:
        status = bringup.main(['--port', sim.port, '--address', '95', '--output-dir',
                               str(tmp_path), *SHORT])
        streaming = sim.streaming
        divider = sim.sensor.eeprom[RATE_DIVIDER_ADDRESS]
    assert status == 0
    (folder,) = tmp_path.iterdir()
    assert folder.name.startswith('bringup-')
    assert sorted(os.listdir(folder)) == ['report.json', 'report.txt', 'session.gx2cap']
    report = json.loads((folder / 'report.json').read_text())
    assert report['identity']['serial_number'] == '3095'
    assert report['identity']['firmware'] and report['identity']['model_name']
    assert report['as_found'] == {'streaming': '0xCC', 'rate_divider': 512, 'rate_hz': 100.0}
    trips = report['round_trips']
    assert trips['ping']['count'] + trips['ping']['lost'] == 5
    assert trips['command']['count'] + trips['command']['lost'] + \
        trips['command']['nacked'] == 5
    assert trips['command']['min'] >= 30.0, 'the radio latency is in every round trip'
    assert trips['continuous_start']['count'] >= 1 and trips['continuous_stop']['count'] >= 1
    assert [s['code'] for s in report['streams']] == \
        [f'0x{s.code:02X}' for s in streams.STREAMS]
    for stream in report['streams']:
        assert 'error' not in stream, stream
        assert stream['rate_hz'] == pytest.approx(stream['rate_asked_hz'], rel=0.1)
        assert stream['records'] > 100 and stream['lost'] < stream['records'] * 0.1
        assert stream['lqi']['min'] is not None and stream['rssi']['median'] is not None
    # Left exactly as found: the same stream, the same divider in EEPROM, and said so.
    assert streaming == 0xCC and divider == 512
    assert report['left']['as_found'] and report['left']['rate_divider'] == 512
    text = (folder / 'report.txt').read_text()
    assert 'Left as found: yes' in text and 'streaming 0xCC' in text
    assert 'please attach it to your bug report' in text
    # Every 0xCC record the capture holds is published by the node replaying it.
    capture = str(folder / 'session.gx2cap')
    expected = records_in_capture(capture, 0xCC, 95)
    assert expected > 200
    replay_through_node(capture, expected)


def replay_through_node(capture: str, expected: int) -> None:
    isolate_ros_domain()
    _, chunks = read_capture(capture)
    chunks = list(chunks)
    # A byte nobody parses plays first, when the node first writes (quiet: it flushes
    # what has arrived); the session follows 3 s later, at its recorded pace.
    chunks.insert(0, (chunks[0][0] - 3.0, b'\x00'))
    replayer = Replayer(chunks, speed=1.0, wait_for_host=True)
    replayer.start()
    listener = Listener({'imu/raw_data': Imu}, depth=5000)
    # Pauses in the session (the rate being written) are no stall to reopen the port for.
    node = NodeProcess({'port': replayer.port, 'address': 95, 'time_source': 'host',
                        'read_timeout': 10.0})
    try:
        assert replayer.wait(120), node.output()
        deadline = time.monotonic() + 10
        while len(listener.received('imu/raw_data')) < expected and \
                time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(0.5)
        got = len(listener.received('imu/raw_data'))
        assert got == expected, node.output()
        assert node.stop()[0] == 0
    finally:
        node.close()
        listener.close()
        replayer.stop()


@pytest.mark.slow
def test_a_sensor_that_is_not_there_is_reported_soon_and_nothing_is_written(tmp_path):
    with PtySimulator(SimulatorConfig(seed=20)) as sim:
        start = time.monotonic()
        status = bringup.main(['--port', sim.port, '--address', '12', '--output-dir',
                               str(tmp_path), *SHORT])
        took = time.monotonic() - start
        assert sim.eeprom_writes() == []
    assert status == 1
    assert took < 15, 'no identity read waits out every retry for a sensor not there'
    (folder,) = tmp_path.iterdir()
    report = json.loads((folder / 'report.json').read_text())
    assert 'the base station answered the pings, the sensor did not' in report['error']
    assert 'discover' in report['error']
    assert 'Error: node 12 does not answer' in (folder / 'report.txt').read_text()
