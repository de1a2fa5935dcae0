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
The fault capture without a node: the ring, the episodes, the files, the triggers.

The ring (``RecentBytes``) keeps the last seconds and never more than its
cap; a storm of faults writes one file per episode; the files are captures
that read back as what the reader read; the oldest go beyond the cap; and
``FaultWatch`` names each fault the driver counts, once. The node's side
(each trigger in a running node, the service, a replay of a file) is in
test_node_fault_capture.py.
"""

import dataclasses
import logging
import os

from i3dmgx2_driver.capture.fault_capture import CHUNK_COST, FaultCapture, RecentBytes
from i3dmgx2_driver.capture.file_format import read_capture
from i3dmgx2_driver.capture.raw_capture import bytes_sink
from i3dmgx2_driver.device.status import DeviceStatus, State
from i3dmgx2_driver.ros.diagnostic_statuses import connection_status
from i3dmgx2_driver.ros.fault_watch import CORRUPT_BURST, FaultWatch
import pytest

LOG = logging.getLogger('test_fault_capture')


def test_ring_keeps_the_last_seconds_and_never_more_than_its_cap():
    ring = RecentBytes(seconds=2.0, max_bytes=10_000)
    data = b'x' * 40
    for i in range(500):  # 5 s at 100 reads a second
        ring.on_bytes(data, 100.0 + i * 0.01)
    chunks = ring.snapshot()
    assert chunks[-1][0] == pytest.approx(104.99)
    assert chunks[0][0] >= 104.99 - 2.0
    assert all(chunk is data for _, chunk in chunks), 'a read is kept by reference'
    reads, held = ring.held
    assert held == reads * (len(data) + CHUNK_COST) <= 10_000
    # A flood of reads within the seconds is cut by the cap, oldest first.
    for i in range(1000):
        ring.on_bytes(b'y', 105.0 + i * 1e-4)
    reads, held = ring.held
    assert held <= 10_000 and ring.snapshot()[-1] == (105.0 + 999 * 1e-4, b'y')


def test_a_storm_of_faults_writes_one_file_per_episode(tmp_path):
    faults = FaultCapture(str(tmp_path), seconds=10.0, kept=5, log=LOG, after=2.0)
    faults.on_bytes(b'abc', 1000.0)
    for step in range(10):  # a fault every 0.1 s from t = 50 s
        faults.trigger('corrupt' if step % 2 else 'stall', now=50.0 + step * 0.1)
    assert faults.due(now=51.9) == ''
    assert faults.due(now=52.0) == 'stall+corrupt'
    assert faults.due(now=52.1) == ''
    # Within min_gap (= seconds) of that file: the next one waits for it to pass.
    faults.trigger('stall', now=53.0)
    assert faults.due(now=61.9) == ''
    assert faults.due(now=62.0) == 'stall'
    # Long after: a file FAULT_AFTER after the fault.
    faults.trigger('disconnect', now=100.0)
    assert faults.due(now=101.0) == '' and faults.due(now=102.0) == 'disconnect'


def test_files_are_captures_of_what_was_read_and_the_oldest_go(tmp_path):
    directory = tmp_path / 'faults'
    faults = FaultCapture(str(directory), seconds=5.0, kept=3, log=LOG, port='/dev/gx2',
                          address=95, wireless=True)
    chunks = [(2000.0 + i * 0.5, bytes([i]) * (i + 1)) for i in range(20)]
    for receive_time, data in chunks:
        faults.on_bytes(data, receive_time)
    directory.mkdir()
    (directory / 'notes.txt').write_text('not ours')
    paths = [faults.save(f'cause{i}') for i in range(5)]
    header, read = read_capture(paths[-1])
    kept = [c for c in chunks if c[0] >= chunks[-1][0] - 5.0]
    assert list(read) == kept
    assert (header['port'], header['address'], header['cause']) == ('/dev/gx2', 95, 'cause4')
    assert header['start_time'] == kept[0][0]
    names = sorted(os.listdir(directory))
    assert names == sorted([os.path.basename(p) for p in paths[-3:]] + ['notes.txt'])
    assert all(n.startswith('i3dmgx2_') and n.endswith('.gx2cap') for n in names[:-1])
    assert 'cause4' in names[-2] and faults.written == 5
    assert f'5 written, the last {paths[-1]} (cause4)' in faults.describe()


def test_off_keeps_nothing_and_says_why_no_file(tmp_path):
    faults = FaultCapture('', seconds=30.0, kept=20, log=LOG)
    assert not faults.active and faults.on_bytes is None and faults.describe() == 'off'
    faults.trigger('stall')
    with pytest.raises(ValueError, match='off'):
        faults.save()
    faults.start(lambda: ['stall'])  # nothing to start
    faults.close()
    with pytest.raises(ValueError, match='nothing read'):
        FaultCapture(str(tmp_path), 30.0, 20, LOG).save()


def test_a_directory_that_cannot_be_written_is_said_and_the_ring_goes_on(tmp_path):
    blocker = tmp_path / 'file'
    blocker.write_text('')
    faults = FaultCapture(str(blocker / 'sub'), seconds=5.0, kept=3, log=LOG)
    faults.on_bytes(b'x', 1.0)
    with pytest.raises(OSError):
        faults.save()
    faults.on_bytes(b'y', 2.0)
    assert faults.ring.snapshot() == [(1.0, b'x'), (2.0, b'y')]


def test_bytes_sink_hands_each_read_to_every_sink():
    got = []
    assert bytes_sink(None, None) is None
    sink = got.append
    assert bytes_sink(None, sink) is sink
    both = bytes_sink(lambda d, t: got.append(('a', d)), lambda d, t: got.append(('b', d)))
    both(b'z', 1.0)
    assert got == [('a', b'z'), ('b', b'z')]


class Counters:
    """What the watch reads: a supervisor snapshot and the device resets."""

    def __init__(self) -> None:
        self.device = DeviceStatus(state=State.STREAMING, parser={})
        self.resets = 0

    def change(self, **changes) -> None:
        self.device = dataclasses.replace(self.device, **changes)


@pytest.mark.parametrize(('change', 'cause'), [
    ({'stalls': 1}, 'stall'),
    ({'reconnects': 1}, 'disconnect'),
    ({'state': State.DISCONNECTED}, 'disconnect'),
    ({'parser': {'checksum_failures': CORRUPT_BURST}}, 'corrupt'),
    ({'parser': {'nacks': 1}}, 'refused'),
    ({}, 'device_reset'),
])
def test_each_fault_counted_is_told_once(change, cause):
    counters = Counters()
    watch = FaultWatch(lambda: counters.device, lambda: counters.resets, prefix='left-')
    assert watch.look(0.0) == []
    counters.change(**change)
    if not change:
        counters.resets += 1
    assert watch.look(0.25) == [f'left-{cause}']
    assert watch.look(0.5) == []


def test_what_is_not_a_fault():
    counters = Counters()
    counters.change(state=State.CONNECTING)
    watch = FaultWatch(lambda: counters.device, lambda: counters.resets)
    watch.look(0.0)
    # The port missing at start, a NACK in the bring-up, corrupted packets now and then.
    counters.change(state=State.DISCONNECTED, parser={'nacks': 2})
    assert watch.look(0.25) == []
    counters.change(state=State.STREAMING, parser={'nacks': 2, 'checksum_failures': 1})
    assert watch.look(1.0) == []
    counters.change(parser={'nacks': 2, 'checksum_failures': CORRUPT_BURST})
    assert watch.look(4.0) == []  # spread over more than the window
    counters.change(parser={'nacks': 2, 'checksum_failures': 2 * CORRUPT_BURST})
    assert watch.look(4.5) == ['corrupt']


def test_the_connection_status_says_where_the_fault_capture_goes():
    device = DeviceStatus(state=State.STREAMING)
    values = dict(connection_status(device, 'off', 'keeping the last 30 s').values)
    assert values['fault capture'] == 'keeping the last 30 s'
    assert 'fault capture' not in dict(connection_status(device, 'off').values)
