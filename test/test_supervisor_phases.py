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
The supervisor's phases, as the managed node drives them, against the simulator.

No ROS: the device layer alone, seen from both ends. connect() opens and
quiets without streaming; start_streaming() returns once records flow;
stop_streaming() sends 0xFA and keeps the port; stop() lets it go. Each
failure of connect() says why and leaves the port free.
"""

import contextlib
import os
import threading
import time

from i3dmgx2_driver.device.link import DeviceError, DeviceTimeout
from i3dmgx2_driver.device.port import PortBusy, PortMissing, SerialPort
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.device.status import State
from i3dmgx2_driver.device.supervisor import DeviceSupervisor, DeviceUnavailable
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
import pytest


class Records:
    """Counts what the reader hands over."""

    def __init__(self) -> None:
        self.count = 0
        self.lock = threading.Lock()

    def __call__(self, packet, read_time, read_mono) -> None:
        with self.lock:
            self.count += 1

    def wait_for(self, count: int, timeout: float = 10.0) -> int:
        deadline = time.monotonic() + timeout
        while self.count < count and time.monotonic() < deadline:
            time.sleep(0.01)
        return self.count


def held(path: str) -> bool:
    """Whether another opener holds ``path`` exclusively now."""
    try:
        SerialPort(path, low_latency=False).close()
    except PortBusy:
        return True
    return False


def supervisor(port: str, records: Records, **config) -> DeviceSupervisor:
    return DeviceSupervisor(DeviceConfig(port=port, address=95, low_latency=False,
                                         **config), on_record=records)


@contextlib.contextmanager
def connected_then_stalled(seed: int):
    """Yield (sim, supervisor), connected to a sensor that then falls silent for 5 s."""
    with PtySimulator(SimulatorConfig(seed=seed)) as sim:
        sup = supervisor(sim.port, Records())
        sup.connect()
        sim.stall(5.0)
        yield sim, sup


def in_thread(call) -> tuple[threading.Thread, list[str]]:
    """Start ``call`` in a thread; return it and the DeviceTimeout messages it raised."""
    errors: list[str] = []

    def run():
        try:
            call()
        except DeviceError as exc:
            errors.append(str(exc))

    thread = threading.Thread(target=run)
    thread.start()
    return thread, errors


@pytest.mark.slow
def test_phases_open_stream_quiet_and_close():
    with PtySimulator(SimulatorConfig(seed=71, faults=FaultConfig(already_streaming=True))) as sim:
        records = Records()
        sup = supervisor(sim.port, records)
        sup.connect()
        assert sup.status().state is State.READY
        assert sup.status().info is not None and sup.status().info.serial_number
        assert sup.status().divider is not None
        assert sim.wait_until(lambda: sim.streaming == 0, timeout=2), 'not quieted'
        assert held(sim.port)
        before = records.count
        time.sleep(0.3)
        assert records.count == before, 'records flow before start_streaming'

        sup.start_streaming()
        assert sup.status().state is State.STREAMING
        assert records.wait_for(before + 20) >= before + 20

        sent = time.time()
        sup.stop_streaming()
        assert sup.status().state is State.READY
        assert [t for t, c in sim.commands if c.code == 0xFA and t >= sent]
        assert sim.streaming == 0
        assert held(sim.port), 'deactivating let the port go'
        time.sleep(0.1)  # records already on the line
        quiet = records.count
        time.sleep(0.3)
        assert records.count == quiet

        sup.start_streaming()  # again, on the same port
        assert records.wait_for(quiet + 20) >= quiet + 20
        assert sup.status().connections == 1, 'the port was reopened'

        sup.stop()
        assert sup.status().state is State.STOPPED
        assert sim.wait_until(lambda: sim.streaming == 0, timeout=2)
        assert not held(sim.port)


@pytest.mark.slow
def test_an_operation_has_the_sensor_paused_then_the_stream_back():
    with PtySimulator(SimulatorConfig(seed=77)) as sim:
        records = Records()
        sup = supervisor(sim.port, records)
        try:
            sup.connect()
            with pytest.raises(DeviceUnavailable, match='not streaming'):
                sup.run_paused(lambda link: None)
            sup.start_streaming()
            seen = []
            result = sup.run_paused(lambda link: seen.append((link, sup.status().state)) or 42)
            assert result == 42 and seen == [(sup.link, State.PAUSED)]
            assert sup.status().state is State.STREAMING
            before = records.count
            assert records.wait_for(before + 20) >= before + 20, 'the stream did not restart'
        finally:
            sup.stop()


def test_connect_fails_on_a_missing_port(tmp_path):
    sup = supervisor(os.path.join(tmp_path, 'ttyGX2'), Records())
    with pytest.raises(PortMissing, match='does not exist'):
        sup.connect()
    assert sup.link is None


@pytest.mark.slow
def test_connect_fails_on_a_busy_port_then_succeeds():
    with PtySimulator(SimulatorConfig(seed=72)) as sim:
        sup = supervisor(sim.port, Records())
        holder = SerialPort(sim.port, low_latency=False)
        try:
            with pytest.raises(PortBusy, match='in use by another process'):
                sup.connect()
        finally:
            holder.close()
        sup.connect()
        assert sup.status().state is State.READY
        sup.stop()


@pytest.mark.slow
def test_connect_fails_on_a_silent_sensor_and_frees_the_port():
    with PtySimulator(SimulatorConfig(seed=73, address=96)) as sim:
        sup = supervisor(sim.port, Records())
        with pytest.raises(DeviceTimeout, match='node 95 is silent'):
            sup.connect()
        assert sup.link is None
        assert not held(sim.port)
        # It gave up after the ping and the polls, before asking the identity.
        sent = [h.command.code for h in sim.host_log if h.command is not None]
        assert 0xC2 in sent and 0xEA not in sent and 0xE9 not in sent, sent


@pytest.mark.slow
def test_start_streaming_reopens_a_port_lost_while_inactive():
    with PtySimulator(SimulatorConfig(seed=74)) as sim:
        records = Records()
        sup = supervisor(sim.port, records)
        sup.connect()
        sim.unplug(seconds=0.5)
        assert sim.pty.plugged.wait(10)
        sup.start_streaming()
        assert records.wait_for(20) >= 20
        assert sup.status().connections == 2
        sup.stop()


@pytest.mark.slow
def test_stop_streaming_cuts_a_pending_request_short():
    # A request to a sensor that does not answer waits out its retries (1.5 s);
    # stopping the stream makes it give up at once, the port still open.
    with connected_then_stalled(seed=75) as (sim, sup):
        thread, failures = in_thread(
            lambda: sup.link.request(bytes((0xC2,)), 0xC2, timeout=0.5, retries=3))
        time.sleep(0.2)
        sup.stop_streaming()
        thread.join(timeout=1.0)
        assert not thread.is_alive(), 'the request did not give up'
        assert failures and 'cancelled' in failures[0]
        assert held(sim.port)
        sup.stop()


@pytest.mark.slow
def test_stop_while_the_stream_starts_leaves_the_port_closed():
    # A signal during activate: stop() comes while start_streaming() waits for records.
    with connected_then_stalled(seed=76) as (sim, sup):
        thread, errors = in_thread(sup.start_streaming)
        time.sleep(0.3)
        sup.stop()
        thread.join(timeout=2.0)
        assert not thread.is_alive()
        assert errors and 'stopped while the stream was starting' in errors[0]
        time.sleep(0.5)  # time enough for a supervisor thread to open the port again
        assert sup.link is None and not held(sim.port)
