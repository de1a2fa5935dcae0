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
The ROS layout, as a ROS user gets it from colcon.

The test builds with colcon into a temporary prefix and runs the installed
executables that ``ros2 run`` runs.

``ros2`` itself is not on PyPI, so the test does by hand what ``ros2 run
i3dmgx2_driver node`` does: find ``lib/i3dmgx2_driver/node`` under the
package's prefix and execute it, with nothing of the source tree on the path.
"""

import contextlib
import glob
import os
from pathlib import Path
import shutil
import subprocess
import sys

from harness.processes import isolate_ros_domain, LifecycleClient, Listener, NodeProcess, REPO
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.slow

COLCON = os.path.join(os.path.dirname(sys.executable), 'colcon')


@pytest.fixture(scope='module')
def prefix(tmp_path_factory):
    """Build and install the package with colcon into a fresh prefix."""
    assert os.path.exists(COLCON), 'colcon is part of requirements-dev.txt'
    base = tmp_path_factory.mktemp('colcon')
    source = base / 'src' / 'i3dmgx2_driver'
    # Copy what git would check out, not build products of a local setup.
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(
        '.venv', 'build', 'install', 'log', '.git', '__pycache__', '.*_cache', '.hypothesis',
        'benchmarks', 'docs'))
    env = {k: v for k, v in os.environ.items()
           if k not in ('PYTHONPATH', 'AMENT_PREFIX_PATH', 'COLCON_PREFIX_PATH',
                        'CMAKE_PREFIX_PATH')}
    result = subprocess.run(
        [COLCON, '--log-base', str(base / 'log'), 'build', '--base-paths', str(base / 'src'),
         '--build-base', str(base / 'build'), '--install-base', str(base / 'install'),
         '--event-handlers', 'console_direct-', 'desktop_notification-', 'terminal_title-'],
        cwd=base, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return base / 'install' / 'i3dmgx2_driver'


def installed_env(prefix) -> dict:
    """Return what a sourced install/setup.bash gives: the installed package only."""
    env = dict(os.environ)
    site = glob.glob(str(prefix / 'lib' / 'python3*' / 'site-packages'))
    assert site, 'colcon installed no Python package'
    env['PYTHONPATH'] = site[0]
    env['AMENT_PREFIX_PATH'] = str(prefix)
    env['PYTHONUNBUFFERED'] = '1'
    return env


def test_layout_is_what_ros2_expects(prefix):
    lib = prefix / 'lib' / 'i3dmgx2_driver'
    for exe in ('node', 'lifecycle_node', 'simulator', 'replay', 'plot', 'monitor',
                'discover', 'bringup', 'noise', 'magcal'):
        assert os.access(lib / exe, os.X_OK), f'{exe} is not an executable in {lib}'
    share = prefix / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'i3dmgx2_driver').exists()
    assert (share / 'i3dmgx2_driver' / 'package.xml').exists()
    assert (share / 'i3dmgx2_driver' / 'config' / 'i3dmgx2.yaml').exists()
    assert (share / 'i3dmgx2_driver' / 'launch' / 'i3dmgx2.launch.py').exists()
    assert (share / 'i3dmgx2_driver' / 'udev' / '99-i3dmgx2.rules').exists()
    for xacro in ('i3dmgx2.urdf.xacro', 'example.urdf.xacro'):
        assert (share / 'i3dmgx2_driver' / 'urdf' / xacro).exists()
    assert not (prefix / 'bin' / 'node').exists(), 'node must not land on PATH'
    site = glob.glob(str(prefix / 'lib' / 'python3*' / 'site-packages'))
    assert sorted(p.name for p in Path(site[0]).iterdir() if not p.name.endswith('-info')) \
        == ['i3dmgx2_driver'], 'only the driver is installed: harness/ is for tests and benchmarks'


def test_share_directory_found_through_ament_index(prefix):
    code = ('from ament_index_python.packages import get_package_share_directory as g;'
            'print(g("i3dmgx2_driver"))')
    out = subprocess.run([sys.executable, '-c', code], env=installed_env(prefix),
                         capture_output=True, text=True, timeout=60, cwd='/')
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(prefix / 'share' / 'i3dmgx2_driver')


@contextlib.contextmanager
def installed_on_simulator(prefix: Path, executable: str, seed: int):
    """Yield a listener and the installed ``executable`` running on a simulated sensor."""
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=seed)) as sim:
        listener = Listener({'imu/raw_data': Imu})
        node = NodeProcess({'port': sim.port, 'address': 95},
                           command=[str(prefix / 'lib' / 'i3dmgx2_driver' / executable)],
                           env=installed_env(prefix))
        with listener, node:
            yield listener, node


def test_installed_node_publishes(prefix):
    with installed_on_simulator(prefix, 'node', seed=41) as (listener, node):
        got = listener.wait_for('imu/raw_data', 20, timeout=30)
        assert len(got) >= 20, node.output()
        assert str(prefix) in node.proc.args[0]
        assert node.stop()[0] == 0


def test_installed_lifecycle_node_is_driven_through_its_services(prefix):
    with installed_on_simulator(prefix, 'lifecycle_node', seed=42) as (listener, node):
        client = LifecycleClient(listener)
        assert client.wait_ready(), node.output()
        assert client.change('configure') and client.change('activate'), node.output()
        got = listener.wait_for('imu/raw_data', 20, timeout=30)
        assert len(got) >= 20, node.output()
        assert client.change('deactivate') and client.change('shutdown'), node.output()
        assert node.wait(timeout=10) == 0, node.output()


def test_installed_simulator_prints_its_port(prefix):
    proc = subprocess.Popen([str(prefix / 'lib' / 'i3dmgx2_driver' / 'simulator'),
                             '--duration', '1'], env=installed_env(prefix), cwd='/',
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    assert out.splitlines()[0].startswith('port: /')


def test_installed_discover_finds_a_simulated_sensor(prefix):
    with PtySimulator(SimulatorConfig(seed=42, address=42, serial_number='2042')) as sim:
        result = subprocess.run([str(prefix / 'lib' / 'i3dmgx2_driver' / 'discover'),
                                 '--port', sim.port], env=installed_env(prefix), cwd='/',
                                capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.splitlines()[-1].strip() == \
        f'ros2 run i3dmgx2_driver node --ros-args -p port:={sim.port} -p address:=42'
