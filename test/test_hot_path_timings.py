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
The hot path's timings (device/hot_path.py): ordered and real when on, nothing when off.

Off, the observer costs nothing a record: the structure of the functions on
the path says so (the reader looks once, before its loop; the record path
never), and the allocation test (test_hot_path_allocation.py) says that the
path still leaves nothing behind. It is one hook, ``hot_path.timings``, set
once for the process: the environment's recorder installs itself there.
On, the real node (``I3DMGX2_TIMINGS``) against the simulator writes one
row per published message whose stage times follow the path's order, each
after the simulator wrote the packet.
"""

import ast
import inspect
import json
import textwrap
import time

from fake_ports import FakePort
from harness.processes import isolate_ros_domain, NodeProcess, ros_env
from i3dmgx2_driver.device import hot_path
from i3dmgx2_driver.device.hot_path import (
    recorder_from_environment, ROW_FIELDS, STAGES_ENV, TIMINGS_ENV, TimingsRecorder,
)
from i3dmgx2_driver.device.link import DeviceLink, PortReader
from i3dmgx2_driver.device.port import PortDisconnected
from i3dmgx2_driver.ros.record_publisher import RecordPath, RecordPublisher
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from test_codec_golden import ADDRESS, FIXTURE_DATA_PACKET

#: The stage methods of the observer, in the order a sample passes them.
STAGES = ('read', 'parsed', 'stamped', 'packed', 'published')


def _uses_in_loops(function) -> list[str]:
    """List every mention of the hot path's observer inside a loop of ``function``."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(function)))
    return [ast.unparse(node) for loop in ast.walk(tree) if isinstance(loop, (ast.For, ast.While))
            for node in ast.walk(loop)
            if (isinstance(node, ast.Attribute) and node.attr == 'timings')
            or (isinstance(node, ast.Name) and node.id in ('timings', 'hot_path'))]


def test_off_nothing_of_the_observer_runs_for_a_record():
    assert _uses_in_loops(PortReader._read) == []
    source = inspect.getsource(RecordPublisher.on_record) + inspect.getsource(RecordPath.messages)
    assert 'timings' not in source and 'hot_path' not in source


class _Calls:
    """An observer that lists the calls it gets."""

    def __init__(self, stages: bool = True) -> None:
        self.calls: list[str] = []
        self.stages = stages

    def __getattr__(self, name: str):
        if name not in STAGES:
            raise AttributeError(name)
        return lambda *args: self.calls.append(name)


class _CannedPort(FakePort):
    """A port whose reads return the given chunks, then report it unplugged."""

    def __init__(self, chunks: list[bytes]) -> None:
        self._chunks = list(chunks)

    def read_some(self, timeout: float) -> bytes:
        if not self._chunks:
            raise PortDisconnected('unplugged')
        return self._chunks.pop(0)


def test_the_link_reports_each_read_then_its_parse(monkeypatch):
    packet = FIXTURE_DATA_PACKET
    timings = _Calls()
    monkeypatch.setattr(hot_path, 'timings', timings)
    records = []

    def on_record(packet, now, mono) -> None:
        timings.calls.append('record')
        records.append(packet)

    port = _CannedPort([packet[:10], packet[10:] + packet, b''])
    DeviceLink(port, ADDRESS, on_record).reader._run()  # here
    assert len(records) == 2
    # The second read completes two records: both are handed over after its parse. The
    # empty read (a silence) is parsed by nothing.
    assert timings.calls == ['read', 'parsed', 'read', 'parsed', 'record', 'record', 'read']


def test_without_its_stages_the_observer_hears_the_read_alone(monkeypatch):
    # The floor's marks and no more (hot_path.HotPathObserver.stages): no parse marked.
    timings = _Calls(stages=False)
    monkeypatch.setattr(hot_path, 'timings', timings)
    port = _CannedPort([FIXTURE_DATA_PACKET])
    DeviceLink(port, ADDRESS, lambda p, t, m: timings.calls.append('record')).reader._run()
    assert timings.calls == ['read', 'record']


def test_without_an_observer_the_link_runs_as_before():
    assert hot_path.timings is None  # off unless installed
    records = []
    port = _CannedPort([FIXTURE_DATA_PACKET])
    DeviceLink(port, ADDRESS, lambda p, t, m: records.append(p)).reader._run()
    assert len(records) == 1


@pytest.mark.slow
def test_the_node_records_ordered_stage_times_for_every_message(tmp_path):
    isolate_ros_domain()
    out = tmp_path / 'timings.json'
    with PtySimulator(SimulatorConfig(address=ADDRESS, seed=83)) as sim:
        node = NodeProcess({'port': sim.port, 'address': ADDRESS},
                           env=ros_env({TIMINGS_ENV: str(out), STAGES_ENV: '1'}))
        with node:
            assert node.wait_for_output('start-up heap frozen', 30), node.output()
            # A second of records after start-up (100 Hz), then the node stops.
            _wait_count(sim, sim.stats.records_sent + 100)
            assert node.stop()[0] == 0, node.output()
        written = {t.timer: t.write_time for t in sim.truth
                   if t.valid and t.write_time is not None and t.timer is not None}
    document = json.loads(out.read_text())
    assert document['fields'] == list(ROW_FIELDS)
    rows = [dict(zip(ROW_FIELDS, row, strict=True)) for row in document['rows']]
    assert len(rows) >= 50, len(rows)
    assert document['reader']['cpus']
    for row in rows:
        assert row['timer'] in written
        marks = [written[row['timer']], row['read'], row['parsed'], row['stamped'],
                 row['packed'], row['published']]
        assert marks == sorted(marks), row
        assert row['cpu_read'] <= row['cpu_published'], row
    timers = [row['timer'] for row in rows]
    assert len(set(timers)) == len(timers)


def _wait_count(sim: PtySimulator, count: int, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while sim.stats.records_sent < count and time.monotonic() < deadline:
        time.sleep(0.05)


def test_the_environment_installs_its_recorder_as_the_one_observer(monkeypatch, tmp_path):
    monkeypatch.setattr(hot_path, 'timings', None)
    monkeypatch.delenv(TIMINGS_ENV, raising=False)
    assert recorder_from_environment() == (None, '')
    assert hot_path.timings is None
    out = str(tmp_path / 'timings.json')
    monkeypatch.setenv(TIMINGS_ENV, out)
    recorder, path = recorder_from_environment()
    try:
        assert isinstance(recorder, TimingsRecorder) and path == out
        assert hot_path.timings is recorder
    finally:
        recorder.save(path)  # takes its callback off the collector


def test_the_recorder_keeps_one_row_per_published_message(tmp_path):
    times = iter(float(t) for t in range(100))
    recorder = TimingsRecorder(clock=lambda: next(times), cpu_clock=lambda: 0.5, stages=True)
    try:
        recorder.read(88, 10.5)
        recorder.parsed()
        for timer in (7, 8):
            recorder.stamped()
            recorder.packed(timer)
            recorder.published(timer / 10)
    finally:
        recorder.save(str(tmp_path / 'timings.json'))
    assert recorder.rows == [(7, 0.7, 10.5, 0.0, 1.0, 2.0, 3.0, 0.5, 0.5),
                             (8, 0.8, 10.5, 0.0, 4.0, 5.0, 6.0, 0.5, 0.5)]
    saved = json.loads((tmp_path / 'timings.json').read_text())
    assert saved['rows'] == [list(row) for row in recorder.rows]


def test_a_recorder_without_stages_leaves_the_parse_and_stamp_unmarked(tmp_path):
    times = iter(float(t) for t in range(100))
    recorder = TimingsRecorder(clock=lambda: next(times), cpu_clock=lambda: 0.5)
    try:
        recorder.read(88, 10.5)
        recorder.packed(7)
        recorder.published(0.7)
    finally:
        recorder.save(str(tmp_path / 'timings.json'))
    assert recorder.rows == [(7, 0.7, 10.5, None, None, 0.0, 1.0, 0.5, 0.5)]
    saved = json.loads((tmp_path / 'timings.json').read_text())
    assert saved['rows'] == [list(row) for row in recorder.rows]
