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
Nothing left behind: every process the package or its scripts start ends with whoever started it.

As a user meets it: ``bash scripts/demo.sh`` typed into an interactive shell
on a terminal, and the terminal closed (the shell gets SIGHUP, and hands it
to its jobs; the simulator runs in a session of its own, which no SIGHUP
reaches); or the script killed outright. And each installed executable
(``lib/i3dmgx2_driver/`` of the install the environment names, what ``ros2 run`` runs) on
a terminal that hangs up, and started in a session of its own by a parent
that is then killed (only the parent-death signal, ``lifetime.die_with_parent``,
reaches it). Every time, no process of the ones started is left 2 s later.

The terminal is a pseudo-terminal (``pty.openpty``, the session leader on it
through ``setsid -c``): its master closed is the terminal closed.
"""

import os
from pathlib import Path
import pty
import select
import signal
import subprocess
import sys
import threading
import time

from harness.instrumented_node import STATS_ENV
from harness.processes import ADDRESS, DEFAULT_HANGUP, installed_executables, \
    isolate_ros_domain, REPO as REPO_PATH, run_by_colcon
from i3dmgx2_driver.lifetime import SHUTDOWN_DEADLINE
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest

pytestmark = pytest.mark.slow

REPO = Path(REPO_PATH)
LIB = installed_executables()
#: How long after the hang-up (or the kill) every process must be gone (s): what a stop is
#: promised (lifetime.SHUTDOWN_DEADLINE, then every thread's stack and exit), and a second for
#: the last exit to be seen on a machine whose cores other tests keep busy (2 s alone, seen
#: missed once beside three workers).
GONE_WITHIN = SHUTDOWN_DEADLINE + 1.0
FIXTURE = REPO / 'test' / 'fixtures' / 'gx2_real_0xcc_records.txt'


def _alive(pid: int) -> bool:
    try:
        with open(f'/proc/{pid}/stat') as handle:
            state = handle.read().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state not in ('Z', 'X')


def _family(root: int) -> set[int]:
    """Return ``root`` and every process below it now."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            with open(f'/proc/{entry}/stat') as handle:
                ppid = int(handle.read().rsplit(')', 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        children.setdefault(ppid, []).append(int(entry))
    found, todo = set(), [root]
    while todo:
        pid = todo.pop()
        if pid not in found:
            found.add(pid)
            todo += children.get(pid, [])
    return found


def _left(pids: set[int], within: float) -> set[int]:
    """Return the processes of ``pids`` still running after ``within`` s (reaping ours)."""
    deadline = time.monotonic() + within
    while True:
        for pid in pids:
            try:
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass
        left = {pid for pid in pids if _alive(pid)}
        if not left or time.monotonic() >= deadline:
            return left
        time.sleep(0.05)


def _describe(pids: set[int]) -> list[str]:
    described = []
    for pid in sorted(pids):
        try:
            with open(f'/proc/{pid}/cmdline', 'rb') as handle:
                command = handle.read().replace(b'\0', b' ').decode(errors='replace')
            described.append(f'{pid}: {command[:200]}')
        except OSError:
            described.append(f'{pid}: gone')
    return described


def _kill_all(pids: set[int]) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


class Terminal:
    """A pseudo-terminal with ``argv`` as its session leader; closing it hangs it up."""

    def __init__(self, argv: list[str], env: dict[str, str]) -> None:
        self._master, slave = pty.openpty()
        # setsid -c: a session of its own, the pty its controlling terminal (as a terminal
        # emulator starts a shell), without forking this threaded process by hand.
        self.proc = subprocess.Popen(['setsid', '-c', *DEFAULT_HANGUP, *argv], stdin=slave,
                                     stdout=slave, stderr=slave, env=env, cwd=REPO)
        os.close(slave)
        self.pid = self.proc.pid
        self._text = bytearray()
        self._closing = threading.Event()
        # Read all the time (a full pty would block the writer), never blocked in read:
        # a read under way would keep the master open after close(), and no hang-up.
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while not self._closing.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.05)
            if ready:
                try:
                    data = os.read(self._master, 4096)
                except OSError:
                    return
                if not data:
                    return
                self._text += data

    def text(self) -> str:
        """Return what was written to the terminal so far."""
        return self._text.decode(errors='replace')

    def send_line(self, line: str) -> None:
        """Type ``line`` and Enter."""
        os.write(self._master, line.encode() + b'\n')

    def wait_for(self, text: str, timeout: float) -> bool:
        """Wait until ``text`` was written to the terminal."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.text():
                return True
            time.sleep(0.05)
        return text in self.text()

    def close(self) -> None:
        """Close the terminal (its master): the session is hung up."""
        self._closing.set()
        self._reader.join()
        os.close(self._master)


def _env() -> dict[str, str]:
    isolate_ros_domain()
    env = dict(os.environ)
    env['RCUTILS_COLORIZED_OUTPUT'] = '0'
    return env


@pytest.fixture(scope='module')
def sim():
    with PtySimulator(SimulatorConfig(address=ADDRESS, seed=3)) as simulator:
        yield simulator


def _tool_argv(tool: str, sim: PtySimulator, tmp_path: Path) -> tuple[list[str], str]:
    """Return the command line of ``tool`` and what it writes once it runs ('' to wait)."""
    ros = ['--ros-args', '-p', f'port:={sim.port}', '-p', f'address:={ADDRESS}']
    return {
        'simulator': (['--quiet'], 'port: '),
        # The plain node on the one simulator for all: another test's node has let it go.
        'node': (ros, 'start-up heap frozen'),
        'lifecycle_node': (ros, 'start-up heap frozen'),
        'replay': (['--fixture', str(FIXTURE), '--loop'], 'port: '),
        'monitor': (['--duration', '0'], 'waiting for'),
        'noise': (['--minutes', '5'], ' left, '),
        'discover': (['--port', sim.port, '--listen', '30'], ''),
        'bringup': (['--port', sim.port, '--address', str(ADDRESS), '--output-dir',
                     str(tmp_path)], ''),
    }[tool]


TOOLS = ('simulator', 'node', 'lifecycle_node', 'replay', 'monitor', 'noise', 'discover',
         'bringup')


def _started(terminal_or_text, marker: str, pid: int) -> None:
    if marker:
        assert terminal_or_text.wait_for(marker, 30.0), terminal_or_text.text()
    else:
        time.sleep(3.0)
    assert _alive(pid), 'it ended by itself before the hang-up'


@pytest.mark.parametrize('tool', TOOLS)
def test_each_tool_ends_when_its_terminal_hangs_up(tool, sim, tmp_path):
    if not (LIB / tool).exists():
        pytest.fail(f'{LIB / tool} is missing: run scripts/setup.sh (or colcon build)')
    args, marker = _tool_argv(tool, sim, tmp_path)
    terminal = Terminal([str(LIB / tool), *args], _env())
    family: set[int] = set()
    try:
        _started(terminal, marker, terminal.pid)
        family = _family(terminal.pid)
        terminal.close()
        left = _left(family, GONE_WITHIN)
        assert not left, f'{tool} left {_describe(left)} behind:\n{terminal.text()[-3000:]}'
    finally:
        _kill_all(family | {terminal.pid})


def _ends_with_its_killed_parent(name: str, argv: list[str], log: Path, env: dict[str, str],
                                 marker: str = '') -> None:
    """
    Start ``argv`` in a session of its own under a shell, kill the shell; assert nothing is left.

    setsid: no terminal, no process group of the parent's; only the
    parent-death signal can tell it that the parent is gone. ``marker``:
    what its output says once it runs ('' to give it 3 s).
    """
    command = ' '.join(f"'{part}'" for part in argv)
    parent = subprocess.Popen([*DEFAULT_HANGUP, 'bash', '-c',
                               f'setsid {command} > {log} 2>&1 & wait'],
                              env=env, stdin=subprocess.DEVNULL, cwd=str(REPO))
    family: set[int] = set()
    try:
        deadline = time.monotonic() + (30.0 if marker else 3.0)
        while time.monotonic() < deadline and not (marker and marker in _text(log)):
            time.sleep(0.1)
        family = _family(parent.pid) - {parent.pid}
        assert family and all(_alive(pid) for pid in family), _text(log)
        parent.kill()
        parent.wait()
        left = _left(family, GONE_WITHIN)
        assert not left, f'{name} left {_describe(left)} behind:\n{_text(log)[-3000:]}'
    finally:
        _kill_all(family)


def _text(path: Path) -> str:
    return path.read_text(errors='replace') if path.exists() else ''


@pytest.mark.parametrize('tool', TOOLS)
def test_each_tool_in_a_session_of_its_own_ends_with_its_parent(tool, sim, tmp_path):
    args, _ = _tool_argv(tool, sim, tmp_path)
    _ends_with_its_killed_parent(tool, [str(LIB / tool), *args], tmp_path / 'out.txt', _env())


def test_the_benchmarks_observed_node_ends_with_its_parent(sim, tmp_path):
    """
    The node every soak and memory curve runs (``harness.instrumented_node``), in its own session.

    Its parent (the benchmark) killed: the node must not stream on (one
    outlived a memory curve stopped with SIGTERM, 2026-11-27).
    """
    env = _env()
    env[STATS_ENV] = str(tmp_path / 'stats.json')
    env['PYTHONPATH'] = os.pathsep.join((str(REPO), env.get('PYTHONPATH', '')))
    argv = [sys.executable, '-m', 'harness.instrumented_node', '--ros-args',
            '-p', f'port:={sim.port}', '-p', f'address:={ADDRESS}']
    _ends_with_its_killed_parent('the observed node', argv, tmp_path / 'out.txt', env,
                                 marker='start-up heap frozen')


def _demo(terminal: Terminal) -> set[int]:
    """Start the demo from the terminal's shell; return the shell's processes once it streams."""
    terminal.send_line(f'cd {REPO} && bash scripts/demo.sh')
    assert terminal.wait_for('[demo] ros2 run i3dmgx2_driver monitor', 300.0), terminal.text()
    # The monitor's first line with data: the whole demo runs.
    assert terminal.wait_for(' Hz  accel', 30.0), terminal.text()
    return _family(terminal.pid)


def _demo_env(tmp_path: Path) -> dict[str, str]:
    """Return the terminal's environment: the demo's work folder under ``tmp_path`` (TMPDIR)."""
    return dict(_env(), TMPDIR=str(tmp_path))


#: scripts/demo.sh sets up the checkout it is in (.venv, pip, colcon build into its install/):
#: ``colcon test`` tests what colcon installed, and leaves the source folder as it is.
demo_of_the_checkout = pytest.mark.skipif(
    run_by_colcon(), reason='scripts/demo.sh sets up the source folder: scripts/test.sh runs it')


@demo_of_the_checkout
def test_the_demo_leaves_nothing_when_its_terminal_is_closed(tmp_path):
    terminal = Terminal(['bash', '--norc', '--noprofile', '-i'], _demo_env(tmp_path))
    family: set[int] = set()
    try:
        family = _demo(terminal)
        assert len(family) >= 5, _describe(family)  # shell, script, simulator, node, monitor
        assert len(list(tmp_path.glob('i3dmgx2-demo-*'))) == 1, terminal.text()[-3000:]
        terminal.close()
        left = _left(family, GONE_WITHIN)
        assert not left, f'left behind: {_describe(left)}\n{terminal.text()[-3000:]}'
        # Nor a file: the script's own folder went with it.
        assert not list(tmp_path.glob('i3dmgx2-demo-*')), terminal.text()[-3000:]
    finally:
        _kill_all(family | {terminal.pid})


@demo_of_the_checkout
def test_the_demo_leaves_nothing_when_the_script_is_killed(tmp_path):
    # SIGKILL leaves the script's folder (no trap runs): under tmp_path, not /tmp.
    terminal = Terminal(['bash', '--norc', '--noprofile', '-i'], _demo_env(tmp_path))
    family: set[int] = set()
    try:
        family = _demo(terminal)
        scripts = [pid for pid in family if 'demo.sh' in ' '.join(_describe({pid}))]
        assert len(scripts) == 1, _describe(family)
        os.kill(scripts[0], signal.SIGKILL)
        left = _left(family - {terminal.pid}, GONE_WITHIN)
        assert not left, f'left behind: {_describe(left)}\n{terminal.text()[-3000:]}'
    finally:
        _kill_all(family)
        terminal.close()
