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
First contact (issue #15): every mistake a new user makes gets one clear message.

One test per row of the issue's table, each a real node process against the
simulator, a temporary file, a directory, /dev/null or a pseudo-terminal fed
with random bytes. Asserted: the exit status, and the words that matter (the
path, the parameter names, the address heard). Waits are bounded by generous
timeouts; nothing is judged by how fast it happened.
"""

import grp
import os
import random
import re
import select
import shutil
import signal
import sys
import threading
import tty

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from harness.processes import (
    isolate_ros_domain, LIFECYCLE_COMMAND, LifecycleClient, Listener, NodeProcess, REPO,
)
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.slow

#: The advice to find the right port, in every message about a wrong one.
PORT_HINT = 'ls /dev/serial/by-id/'


@pytest.fixture(autouse=True)
def _domain():
    isolate_ros_domain()


def lines_with(output: str, text: str) -> list[str]:
    return [line for line in output.splitlines() if text in line]


# -- a path that is no serial port: exit 2 at once, one FATAL line -------------

@pytest.fixture(params=['regular file', 'directory', '/dev/null'])
def not_a_port(request, tmp_path):
    if request.param == 'regular file':
        path = tmp_path / 'passwd'
        path.write_text('root:x:0:0:root:/root:/bin/bash\n')
        return str(path), 'is a regular file'
    if request.param == 'directory':
        return str(tmp_path), 'is a directory'
    return '/dev/null', 'is a character device (1:3) that is not a terminal'


def test_a_path_that_is_no_serial_port_exits_2_with_one_message(not_a_port):
    path, what = not_a_port
    with NodeProcess({'port': path, 'address': 95}) as node:
        assert node.wait(timeout=30) == 2, node.output()
        output = node.output()
        fatal = lines_with(output, '[FATAL]')
        assert len(fatal) == 1, output
        assert f"parameter 'port': {path} {what}, not a serial port" in fatal[0]
        assert PORT_HINT in fatal[0] and '-p port:=' in fatal[0]
        assert 'retrying' not in output and 'cannot open' not in output


# -- parameter names the node does not declare --------------------------------

def test_a_misspelt_required_parameter_is_named_with_the_real_one():
    with NodeProcess({'adress': 95}) as node:
        assert node.wait(timeout=30) == 2, node.output()
        output = node.output()
        assert "parameter 'address' is required" in output
        assert "unknown parameter 'adress' (did you mean 'address'?)" in output


def test_a_misspelt_optional_parameter_is_warned_once_and_the_node_runs_on():
    with PtySimulator(SimulatorConfig(seed=151)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        # The params file (key /**) and rclpy's own use_sim_time are no reason to warn.
        node = NodeProcess({}, extra_args=[
            '--params-file', os.path.join(REPO, 'config', 'i3dmgx2.yaml'),
            '-p', f'port:={sim.port}', '-p', 'address:=95', '-p', 'data_rat:=200.0',
            '-p', 'use_sim_time:=false'])
        with listener, node:
            assert len(listener.wait_for('imu/raw_data', 10, timeout=30)) >= 10, node.output()
            assert node.stop()[0] == 0
            unknown = lines_with(node.output(), 'unknown parameter')
            assert len(unknown) == 1, node.output()
            assert "unknown parameter 'data_rat' (did you mean 'data_rate'?)" in unknown[0]
            assert '[WARN]' in unknown[0]


# -- the other framing ----------------------------------------------------------

def test_a_wired_setting_on_a_streaming_base_station_says_wireless_true():
    with PtySimulator(SimulatorConfig(seed=152, streaming_at_start=True)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95, 'wireless': False})
        with listener, node:
            assert node.wait_for_output('set -p wireless:=true', timeout=20), node.output()
            assert node.stop()[0] == 0
            line = lines_with(node.output(), 'set -p wireless:=true')[0]
            assert f'{sim.port} sends wireless packets from node 95' in line
            assert listener.received('imu/raw_data') == []


def test_a_wired_setting_on_a_silent_base_station_says_wireless_true():
    # A base station ignores unframed commands: not one byte comes back.
    with PtySimulator(SimulatorConfig(seed=153)) as sim:
        node = NodeProcess({'port': sim.port, 'address': 95, 'wireless': False})
        with node:
            assert node.wait_for_output('-p wireless:=true', timeout=20), node.output()
            line = lines_with(node.output(), '-p wireless:=true')[0]
            assert f'not one byte from {sim.port}' in line
            assert node.stop()[0] == 0


def test_a_wireless_setting_on_a_streaming_wired_sensor_says_wireless_false():
    # The wired sensor does not understand packets, so its stream goes on.
    config = SimulatorConfig(wireless=False, seed=156, streaming_at_start=True)
    with PtySimulator(config) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95})
        with listener, node:
            assert node.wait_for_output('set -p wireless:=false', timeout=20), node.output()
            assert node.stop()[0] == 0
            line = lines_with(node.output(), 'set -p wireless:=false')[0]
            assert f'{sim.port} sends wired (unframed) records' in line
            assert listener.received('imu/raw_data') == []
            assert 'streaming' not in node.output()


def test_a_wireless_setting_on_a_polled_wired_sensor_says_wireless_false():
    # A wired sensor gives no ACK for a packet, where a base station would; it may
    # answer a command byte inside a packet (0xC2 of a polled request) as a raw
    # command, in a wired record. Either way the fix is named.
    with PtySimulator(SimulatorConfig(wireless=False, seed=157)) as sim:
        node = NodeProcess({'port': sim.port, 'address': 95})
        with node:
            assert node.wait_for_output('-p wireless:=false', timeout=20), node.output()
            line = lines_with(node.output(), '-p wireless:=false')[0]
            assert (f"not one byte from {sim.port} in 3.0 s, not even the base station's ACK"
                    in line) or f'{sim.port} sends wired (unframed) records' in line, line
            assert node.stop()[0] == 0
            assert 'streaming' not in node.output()


# -- another address on the air ------------------------------------------------

def test_packets_from_another_address_are_named_and_streaming_never_announced():
    with PtySimulator(SimulatorConfig(seed=154, streaming_at_start=True)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 12, 'reconnect_interval': 0.3})
        with listener, node:
            assert node.wait_for_output('packets arrive from node 95', timeout=20), \
                node.output()
            # Past a whole start-up dialogue (and its retry), then a stop.
            assert node.wait_for_output('device not answering', timeout=40), node.output()
            assert node.stop()[0] == 0
            output = node.output()
            line = lines_with(output, 'packets arrive from node 95')[0]
            assert 'none from node 12: is that your sensor? If so, set -p address:=95' in line
            assert 'streaming' not in output, output
            assert listener.received('imu/raw_data') == []


# -- bytes that are no packets --------------------------------------------------

class NoisyPty:
    """A pseudo-terminal whose other end sends random bytes and swallows what comes."""

    def __init__(self, seed: int) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self._rng = random.Random(seed)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(0.05):
            try:
                os.write(self.master, self._rng.randbytes(200))
                while select.select([self.master], [], [], 0)[0]:
                    os.read(self.master, 4096)
            except OSError:
                pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        os.close(self.slave)
        os.close(self.master)


def test_bytes_that_are_no_packet_point_at_the_baud_rate():
    noisy = NoisyPty(seed=155)
    try:
        with NodeProcess({'port': noisy.path, 'address': 95}) as node:
            assert node.wait_for_output('not one valid 3DM-GX2 packet', timeout=20), \
                node.output()
            assert node.stop()[0] == 0
            line = lines_with(node.output(), 'not one valid 3DM-GX2 packet')[0]
            assert re.search(rf'\d+ bytes in \d+\.\d s from {re.escape(noisy.path)}, and not one',
                             line), line
            assert 'check the baud rate' in line and '115200' in line
            assert 'streaming' not in node.output()
    finally:
        noisy.close()


# -- a port this user may not open ---------------------------------------------

def _without_dac_override() -> list[str] | None:
    """Return a command that runs the node as root without its power to ignore file modes."""
    if os.geteuid() != 0:
        return [sys.executable, '-m', 'i3dmgx2_driver.ros.main']
    setpriv = shutil.which('setpriv')
    if setpriv is None:
        return None
    return [setpriv, '--bounding-set', '-dac_override,-dac_read_search',
            sys.executable, '-m', 'i3dmgx2_driver.ros.main']


def test_a_port_that_may_not_be_opened_names_the_owning_group():
    command = _without_dac_override()
    if command is None:
        pytest.skip('as root, needs setpriv to drop the override of file modes')
    master, slave = os.openpty()
    path = os.ttyname(slave)
    try:
        if os.geteuid() == 0:
            # Someone else's device, of a group root is not in.
            group = next(g for g in ('dialout', 'uucp', 'nogroup') if _has_group(g))
            os.chown(path, 65534, grp.getgrnam(group).gr_gid)
            os.chmod(path, 0o660)
        else:
            os.chmod(path, 0o060)  # the owner (this user) may not, the group may
        group = grp.getgrgid(os.stat(path).st_gid).gr_name
        with NodeProcess({'port': path, 'address': 95}, command=command) as node:
            assert node.wait_for_output('permission denied', timeout=20), node.output()
            assert node.proc.poll() is None, 'retried: permissions can change'
            assert node.stop()[0] == 0
            line = lines_with(node.output(), 'permission denied')[0]
            assert f'permission denied opening {path}' in line
            assert f'the {group} group' in line
    finally:
        os.close(slave)
        os.close(master)


def _has_group(name: str) -> bool:
    try:
        grp.getgrnam(name)
    except KeyError:
        return False
    return True


# -- a port missing at start: said once, retried, ERROR on /diagnostics ---------

def test_a_missing_port_is_said_once_and_an_error_on_diagnostics(tmp_path):
    path = str(tmp_path / 'ttyUSB0')
    listener = Listener({'/diagnostics': DiagnosticArray})
    node = NodeProcess({'port': path, 'address': 95, 'reconnect_interval': 0.2})
    with listener, node:
        # Four diagnostics periods: about twenty attempts to open the port.
        arrays = listener.wait_for('/diagnostics', 4, timeout=30)
        errors = [s for a in arrays for s in a.status if s.name == 'i3dmgx2_driver: connection']
        assert len(errors) >= 4, node.output()
        assert all(s.level == DiagnosticStatus.ERROR for s in errors)
        assert f'serial port {path} does not exist' in errors[-1].message
        assert node.proc.poll() is None
        assert node.stop(signal.SIGTERM)[0] == 0
        missing = lines_with(node.output(), 'does not exist')
        assert len(missing) == 1, node.output()
        assert PORT_HINT in missing[0] and 'retrying every 0.2 s' in missing[0]


# -- the managed node: configure fails with the same words ----------------------

def test_managed_configure_refuses_a_path_that_is_no_serial_port(tmp_path):
    path = tmp_path / 'passwd'
    path.write_text('root:x:0:0\n')
    params = {'port': str(path), 'address': 95, 'data_rat': 200.0}
    with Listener({}) as listener, \
            NodeProcess(params, command=LIFECYCLE_COMMAND) as node, NodeProcess(params) as plain:
        client = LifecycleClient(listener)
        assert client.wait_ready(), node.output()
        for _ in range(2):  # the same words every time, and the node lives on
            assert not client.change('configure')
            assert client.state() == 'unconfigured'
        assert plain.wait(timeout=30) == 2, plain.output()
        fatal = lines_with(plain.output(), '[FATAL]')[0]
        words = fatal[fatal.index("parameter 'port'"):]
        output = node.output()
        assert output.count(f'configure failed: {words}') == 2, output
        # An unknown name is said once, at start, however often configure runs.
        assert len(lines_with(output, "unknown parameter 'data_rat'")) == 1, output
        assert node.stop()[0] == 0
