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
What a robot's image installs: the driver runs without matplotlib.

matplotlib is an optional extra for the plot tool (on a robot it pulls in a
GUI stack). The node, ``discover`` and ``bringup`` are run here in an
interpreter where ``import matplotlib`` fails (``sys.modules['matplotlib']``
is None, which is how Python says "not installed" to every importer), each
against the simulator; the plot tool then says how to install matplotlib
instead of a traceback.
"""

import subprocess
import sys

from harness.processes import isolate_ros_domain, NodeProcess, REPO, ros_env
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
from i3dmgx2_driver.tools import figures, plot
import pytest

#: Run a module as ``python -m`` would, with matplotlib made impossible to import.
WITHOUT_MATPLOTLIB = (
    'import runpy, sys\n'
    "sys.modules['matplotlib'] = None\n"
    'module = sys.argv[1]\n'
    'sys.argv = [module] + sys.argv[2:]\n'
    "runpy.run_module(module, run_name='__main__', alter_sys=True)\n")


def without_matplotlib(module: str) -> list[str]:
    """Return the command that runs ``module`` where matplotlib cannot be imported."""
    return [sys.executable, '-c', WITHOUT_MATPLOTLIB, module]


def run(module: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*without_matplotlib(module), *args], env=ros_env(), cwd=REPO,
                          capture_output=True, text=True, timeout=timeout)


def test_drawing_without_matplotlib_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, 'matplotlib', None)
    monkeypatch.setitem(sys.modules, 'matplotlib.figure', None)
    monkeypatch.setitem(sys.modules, 'matplotlib.backends.backend_agg', None)
    assert not figures.have_matplotlib()
    with pytest.raises(figures.MatplotlibMissing) as info:
        figures.agg_figure()
    assert 'python3-matplotlib' in str(info.value) and 'pip install' in str(info.value)


def test_plot_without_matplotlib_exits_with_the_hint(monkeypatch, capsys, fixture_path):
    monkeypatch.setattr(plot, 'have_matplotlib', lambda: False)
    assert plot.main(['--fixture', str(fixture_path), '-o', '/nonexistent/x.png']) == 1
    err = capsys.readouterr().err
    assert 'sudo apt install python3-matplotlib' in err
    assert 'Traceback' not in err


@pytest.mark.slow
def test_the_node_streams_without_matplotlib():
    isolate_ros_domain()
    with PtySimulator(SimulatorConfig(seed=61)) as sim, \
            NodeProcess({'port': sim.port, 'address': 95},
                        command=without_matplotlib('i3dmgx2_driver.ros.main')) as node:
        assert node.wait_for_output('first record received', timeout=30), node.output()
        assert node.stop()[0] == 0, node.output()
        assert 'matplotlib' not in node.output()


@pytest.mark.slow
def test_discover_finds_a_sensor_without_matplotlib():
    with PtySimulator(SimulatorConfig(seed=62, address=42, serial_number='2042')) as sim:
        result = run('i3dmgx2_driver.tools.discover', '--port', sim.port)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.splitlines()[-1].strip().endswith('-p address:=42')


@pytest.mark.slow
def test_plot_without_matplotlib_says_how_to_install_it(fixture_path, tmp_path):
    result = run('i3dmgx2_driver.tools.plot', '--fixture', str(fixture_path), '-o',
                 str(tmp_path / 'x.png'))
    assert result.returncode == 1
    assert 'python3-matplotlib' in result.stderr and 'Traceback' not in result.stderr
    # --help needs nothing to draw.
    assert run('i3dmgx2_driver.tools.plot', '--help').returncode == 0


@pytest.mark.slow
def test_bringup_runs_without_matplotlib(tmp_path):
    with PtySimulator(SimulatorConfig(seed=63)) as sim:
        result = run('i3dmgx2_driver.tools.bringup', '--port', sim.port, '--address', '95',
                     '--output-dir', str(tmp_path), '--pings', '2', '--commands', '2',
                     '--cycles', '1', '--stream-seconds', '0.5', '--listen', '0.2',
                     '--streams', 'inertial')
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'Left as found: yes' in result.stdout
