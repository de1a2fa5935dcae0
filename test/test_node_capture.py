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
The node's raw capture (``capture_file``): written, re-parsable, complete, and harmless.

Complete means every packet the simulator wrote while the node was reading
is in the capture byte for byte; harmless means a capture that cannot be
written (here a file size limit, as a full disk would) is logged once and
switched off while the IMU stream goes on.
"""

import sys
import warnings

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver import __version__
from i3dmgx2_driver.capture.file_format import read_capture, TruncatedCaptureWarning
from i3dmgx2_driver.codec.framing import DataPacket
from i3dmgx2_driver.codec.parser import SensorStreamParser
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu
from test_node_messages import match, stream_truth

pytestmark = pytest.mark.slow

#: Run the node with a file size limit, as a full disk would stop the capture.
LIMITED_NODE = (
    'import resource, signal, sys\n'
    'signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n'
    'resource.setrlimit(resource.RLIMIT_FSIZE, (20000, 20000))\n'
    'from i3dmgx2_driver.ros.main import main\n'
    'sys.exit(main())\n')


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


def test_capture_holds_every_packet_and_parses_back(tmp_path):
    path = tmp_path / 'session.gx2'
    faults = FaultConfig(garbage_probability=0.05, corrupt_checksum_probability=0.03)
    with PtySimulator(SimulatorConfig(seed=71, faults=faults)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95, 'capture_file': str(path)})
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', 200, timeout=30)) >= 200, \
                node.output()
            assert node.stop()[0] == 0
            published = listener.received('imu/raw_data')
        truth = sim.truth
    header, chunks = read_capture(path)
    assert (header['port'], header['address'], header['baud'], header['wireless']) == \
        (sim.port, 95, 115200, True)
    assert header['driver_version'] == __version__
    assert __version__ in header['tool_version']
    assert header['start_time'] > 1e9
    chunks = list(chunks)
    times = [t for t, _ in chunks]
    assert times == sorted(times) and times[0] >= header['start_time']
    blob = b''.join(data for _, data in chunks)
    # Every packet written from the first the node published to the last is
    # there, byte for byte (corrupted ones too: the capture is of the line, not
    # of the parser). The node read those, so a lost chunk or a capture that
    # starts late or ends early shows. Not the packets beyond: the first read
    # after the open may hold only a packet's tail and the node may stop
    # before it reads the rest of the last one; judged by times, the edges
    # depend on how late the reader ran (its read stamped after a later write).
    pairs = match(published, stream_truth(sim), 'enu')
    assert all(entry is not None for _, entry in pairs), 'a message matches no valid record'
    first, last = pairs[0][1].index, pairs[-1][1].index
    written = [t for t in truth if t.write_time is not None and first <= t.index <= last]
    assert len(written) >= 200
    missing = [t.index for t in written if t.packet not in blob]
    assert not missing, f'{len(missing)} packets not in the capture'
    assert any(t.fault == 'checksum' for t in written)
    # Parsed back, it gives the records the simulator sent, in order.
    parser = SensorStreamParser(address=95)
    records = [e.record for _, data in chunks for e in parser.feed(data)
               if isinstance(e, DataPacket)
               and isinstance(e.record, AccelAngRateMagOrientation)]
    sent = [t.record for t in written if t.valid and t.source == 'stream']
    by_timer = {r.timer: r for r in records}
    assert sent and all(by_timer.get(r.timer) == r for r in sent)
    assert parser.stats.checksum_failures > 0


def test_capture_that_cannot_be_written_is_dropped_and_the_driver_runs_on(tmp_path):
    path = tmp_path / 'limited.gx2'
    with PtySimulator(SimulatorConfig(seed=72)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95, 'capture_file': str(path)},
                           command=[sys.executable, '-c', LIMITED_NODE])
        with listener, node:
            assert node.wait_for_output('capture is off', timeout=30), node.output()
            listener.clear()
            assert len(listener.wait_for('imu/raw_data', 100, timeout=15)) >= 100, \
                node.output()
            assert node.proc.poll() is None
            assert node.stop()[0] == 0
            output = node.output()
    assert output.count('capture is off') == 1, output
    assert 'the driver keeps running without it' in output
    # Under `scripts/test.sh --cov` the node's coverage data, written at its exit, meets the
    # same file-size limit and says so: its traceback is coverage's, not the driver's.
    driver_output = output.split('Exception ignored in atexit callback: <bound method '
                                 'Coverage._atexit')[0]
    assert 'Traceback' not in driver_output, output
    assert path.stat().st_size <= 20000
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', TruncatedCaptureWarning)
        header, chunks = read_capture(path)
        assert header['address'] == 95 and list(chunks)
