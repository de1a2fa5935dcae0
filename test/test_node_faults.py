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
The node against every fault the simulator injects.

It survives, recovers, and publishes only what is valid.

Each test starts a fresh simulator and node process; the listener is real
rclpy in this process. Assertions are on content and counts, never on how
fast something happened, apart from generous timeouts.
"""

import contextlib
import signal
import time

from harness.processes import isolate_ros_domain, Listener, NodeProcess
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu
from test_node_messages import match, stream_truth

pytestmark = pytest.mark.slow


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


def run_node(sim: PtySimulator, **params):
    """Start a listener and a node on ``sim``; return both."""
    listener = Listener({'imu/raw_data': Imu})
    base = {'port': sim.port, 'address': 95, 'read_timeout': 0.5, 'reconnect_interval': 0.3}
    base.update(params)
    return listener, NodeProcess(base)


@contextlib.contextmanager
def streaming(seed: int, count: int):
    """Yield (sim, listener, node) once the node on a fresh simulator published ``count``."""
    with PtySimulator(SimulatorConfig(seed=seed)) as sim:
        listener, node = run_node(sim)
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', count, timeout=30)) >= count
            yield sim, listener, node


def published_records(listener, sim):
    """(message, truth entry) pairs; an entry is None for an unmatched message."""
    all_truth = [t for t in sim.truth if isinstance(t.record, AccelAngRateMagOrientation)]
    return match(listener.received('imu/raw_data'), all_truth, 'enu')


def test_corrupted_stream_publishes_only_valid_records_once():
    faults = FaultConfig(garbage_probability=0.1, corrupt_checksum_probability=0.05,
                         corrupt_length_probability=0.05, foreign_probability=0.05,
                         drop_probability=0.02)
    with PtySimulator(SimulatorConfig(seed=21, faults=faults)) as sim:
        listener, node = run_node(sim)
        with listener, node:
            listener.wait_for('imu/raw_data', 400, timeout=40)
            assert node.stop()[0] == 0
            pairs = published_records(listener, sim)
            assert len(pairs) >= 400, node.output()
            assert all(entry is not None and entry.valid for _, entry in pairs), \
                'a corrupted or foreign record was published'
            indices = [entry.index for _, entry in pairs]
            assert len(indices) == len(set(indices))
            valid = [t.index for t in stream_truth(sim)
                     if indices[0] <= t.index <= indices[-1]]
            assert sorted(indices) == valid, 'a valid record was lost'
            bad = [t for t in sim.truth if not t.valid and t.write_time is not None
                   and indices[0] <= t.index <= indices[-1]]
            faults_seen = {t.fault for t in bad}
            assert {'checksum', 'length', 'foreign'} <= faults_seen


@pytest.mark.parametrize('faults', [
    FaultConfig(already_streaming=True),
    FaultConfig(ignore_first_continuous=True),
    FaultConfig(needs_polled_first=True),
    FaultConfig(command_loss_probability=0.3),
    FaultConfig(nack_probability=0.4),
], ids=['already-streaming', 'ignores-first-continuous', 'needs-polled-first',
        'commands-lost', 'nacks'])
def test_start_up_quirks(faults):
    with PtySimulator(SimulatorConfig(seed=22, faults=faults)) as sim:
        listener, node = run_node(sim)
        with listener, node:
            got = listener.wait_for('imu/raw_data', 50, timeout=30)
            assert len(got) >= 50, node.output()
            assert all(entry is not None and entry.valid
                       for _, entry in published_records(listener, sim))
            if faults.nack_probability:
                rejected = [h for h in sim.host_log if h.outcome == 'rejected: busy']
                assert rejected, 'the fault never fired'
                # Every NACKed request was sent again and got through.
                delivered = {h.raw for h in sim.host_log if h.outcome == 'delivered'}
                assert {h.raw for h in rejected} <= delivered | {b'\xfa'}
            assert node.stop()[0] == 0


def test_stall_is_recovered_by_rerequesting_continuous():
    with streaming(seed=23, count=50) as (sim, listener, node):
        requests_before = len(sim.commands_of(0xC4))
        # The sensor stops streaming without a word (a brown-out, a lost
        # radio link that came back with the sensor in polled mode).
        with sim.lock:
            sim.sensor.streaming = 0
        listener.clear()
        got = listener.wait_for('imu/raw_data', 50, timeout=30)
        assert len(got) >= 50, node.output()
        assert len(sim.commands_of(0xC4)) > requests_before
        assert 'no data for' in node.output()
        assert node.stop()[0] == 0


def test_radio_stall_then_resume():
    faults = FaultConfig(stall_at=1.5, stall_seconds=1.5)
    with PtySimulator(SimulatorConfig(seed=24, faults=faults)) as sim:
        listener, node = run_node(sim)
        with listener, node:
            time.sleep(3.5)
            listener.clear()
            assert len(listener.wait_for('imu/raw_data', 50, timeout=30)) >= 50, node.output()
            assert node.proc.poll() is None
            assert node.stop()[0] == 0


def test_unplug_and_replug_reconnects_every_time():
    with streaming(seed=25, count=30) as (sim, listener, node):
        for _ in range(2):
            sim.unplug(seconds=1.0)
            assert sim.pty.plugged.wait(10)
            listener.clear()
            got = listener.wait_for('imu/raw_data', 30, timeout=30)
            assert len(got) >= 30, node.output()
        output = node.output()
        assert 'disconnected' in output or 'Input/output error' in output
        # The identity is read at every connection but logged only once.
        assert output.count('device: model') == 1, output
        assert sim.stats.port_opens >= 3
        assert node.proc.poll() is None
        pairs = published_records(listener, sim)
        assert all(entry is not None and entry.valid for _, entry in pairs)
        assert node.stop()[0] == 0


def test_port_missing_at_start_then_appears(tmp_path):
    link = str(tmp_path / 'ttyGX2')
    listener = Listener({'imu/raw_data': Imu})
    node = NodeProcess({'port': link, 'address': 95, 'reconnect_interval': 0.3})
    with listener, node:
        assert node.wait_for_output('does not exist'), node.output()
        assert node.proc.poll() is None
        with PtySimulator(SimulatorConfig(seed=26, symlink=link)):
            assert len(listener.wait_for('imu/raw_data', 30, timeout=30)) >= 30, \
                node.output()
        assert node.output().count('does not exist') == 1, 'the warning is not throttled'
        assert node.stop()[0] == 0


def test_silent_device_is_reported_and_retried():
    # A sensor with another address never answers: the base station pings fail
    # and every request times out, forever, without a crash.
    with PtySimulator(SimulatorConfig(seed=27, address=96)) as sim:
        node = NodeProcess({'port': sim.port, 'address': 95, 'reconnect_interval': 0.3})
        with node:
            assert node.wait_for_output('does not answer', timeout=30), node.output()
            assert node.wait_for_output('device not answering', timeout=30), node.output()
            assert 'does not answer the base station ping: check it is powered, its address ' \
                   '(ros2 run i3dmgx2_driver discover lists the nodes on the air) and the ' \
                   'radio channel' in node.output()
            assert node.proc.poll() is None
            code, took = node.stop()
            assert code == 0 and took < 2.0


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_signal_stops_stream_closes_port_exits_zero(sig):
    with PtySimulator(SimulatorConfig(seed=28)) as sim:
        listener, node = run_node(sim)
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', 20, timeout=30)) >= 20
            sent_before = time.time()
            code, took = node.stop(sig)
            assert code == 0, node.output()
            assert took < 2.0
            assert [t for t, c in sim.commands if c.code == 0xFA and t >= sent_before]
            assert sim.wait_until(lambda: sim.streaming == 0, timeout=2)
