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
Shutdown cannot hang: a signal never deadlocks the run loop, and a stop that hangs ends at 3 s.

The run loop (``ros/main.py`` ``run()``) with the real rclpy in a process of
its own, and a node that costs nothing to make, so that it can be started and
stopped many times:

- a signal at any moment of the main thread's wait: the handler used to set a
  ``threading.Event``, whose lock the interrupted ``wait()`` could hold; the
  main thread then waited for itself, for good (the hang seen once in a
  hundred stops right after the first record). Here the wait is entered as
  often as it can be, so that signals land in that moment often;
- a stop made to hang (a node whose ``shutdown()`` never returns, a thread
  that holds up the interpreter's exit): the process writes every thread's
  stack and exits 1 at the deadline, rather than hanging.
"""

import os
import signal
import subprocess
import sys
import time

from harness.processes import isolate_ros_domain, REPO, ros_env
from i3dmgx2_driver.lifetime import SHUTDOWN_DEADLINE, StopSignal
import pytest

#: How a process past its deadline ends: faulthandler's ``dump_traceback_later(exit=True)``
#: writes the stacks, then calls ``_exit(1)``.
FAULTHANDLER_EXIT = 1

_PRELUDE = """
import os, random, signal, sys, threading, time
import rclpy
from rclpy.node import Node
from i3dmgx2_driver.ros import main


class Quiet(Node):
    finished = False

    def __init__(self):
        super().__init__('stop_probe')

    def shutdown(self):
        HOLD()


def HOLD():
    pass
"""

_SIGNAL_STORM = _PRELUDE + """
main._POLL_PERIOD = 0.0  # the main thread enters its wait without pause: the race, often
rng = random.Random(7)
for i in range(RUNS):
    timer = threading.Timer(rng.uniform(0.02, 0.06), os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    code = main.run(Quiet)
    timer.join()
    try:
        from i3dmgx2_driver import lifetime
        lifetime.cancel_deadline()  # this process goes on to the next run
    except ImportError:
        pass
    assert code == 0, code
print('all stopped', flush=True)
"""

_HANGING_STOP = _PRELUDE + """
def BESIDE():
    threading.Event().wait()  # another thread, waiting too: its stack is written as well


threading.Thread(target=BESIDE, daemon=True).start()


def HOLD():
    print('stopping', flush=True)
    threading.Event().wait()  # the injected wait: this stop never ends by itself


print('ready', flush=True)
sys.exit(main.run(Quiet))
"""

_HELD_EXIT = _PRELUDE + """
def HOLD():
    # A thread the interpreter waits for at exit, that never ends: past run(), the exit hangs.
    threading.Thread(target=threading.Event().wait, name='held-exit').start()


print('ready', flush=True)
code = main.run(Quiet)
print('run returned', code, flush=True)
sys.exit(code)
"""


def _python(script: str, tree: str = str(REPO)) -> subprocess.Popen:
    isolate_ros_domain()
    env = ros_env()
    env['PYTHONPATH'] = tree + os.pathsep + env['PYTHONPATH']
    return subprocess.Popen([sys.executable, '-c', script], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env, cwd=tree)


def _finish(proc: subprocess.Popen, timeout: float) -> tuple[int | None, str]:
    """Wait for the end; a process still running is sent SIGABRT (its stacks), then killed."""
    try:
        out, _ = proc.communicate(timeout=timeout)
        return proc.returncode, out
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGABRT)
        try:
            out, _ = proc.communicate(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
        return None, out


def _wait_line(proc: subprocess.Popen, text: str, timeout: float = 30.0) -> list[str]:
    lines = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if line.strip() == text:
            return lines
    raise AssertionError(f'no {text!r}: {"".join(lines)}')


@pytest.mark.slow
def test_a_signal_at_any_moment_of_the_wait_never_hangs_the_run_loop():
    # 40 starts and stops, each signal landing at a random moment of a wait entered
    # without pause. With the old handler (Event.set) a few of them hang for good.
    proc = _python(_SIGNAL_STORM.replace('RUNS', '40'))
    code, out = _finish(proc, 120.0)
    assert code == 0 and 'all stopped' in out, f'exit {code}:\n{out[-8000:]}'


@pytest.mark.slow
def test_a_stop_that_hangs_ends_at_the_deadline_with_every_threads_stack():
    proc = _python(_HANGING_STOP)
    _wait_line(proc, 'ready')
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    _wait_line(proc, 'stopping')
    start = time.monotonic()
    code, out = _finish(proc, SHUTDOWN_DEADLINE + 7.0)
    took = time.monotonic() - start
    assert code == FAULTHANDLER_EXIT, f'exit {code} after {took:.1f} s:\n{out[-8000:]}'
    assert SHUTDOWN_DEADLINE - 0.5 < took < SHUTDOWN_DEADLINE + 3.0, took
    # faulthandler's words: the deadline, then each thread, where it waited.
    assert 'Timeout (0:00:03)!' in out, out
    assert out.count('most recent call first') >= 2, out  # the main thread and the other
    assert 'in HOLD' in out and 'in shutdown' in out and 'in BESIDE' in out, out


@pytest.mark.slow
def test_an_exit_held_up_after_the_run_loop_ends_at_the_deadline():
    proc = _python(_HELD_EXIT)
    _wait_line(proc, 'ready')
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    start = time.monotonic()
    code, out = _finish(proc, SHUTDOWN_DEADLINE + 7.0)
    took = time.monotonic() - start
    assert 'run returned 0' in out, out
    assert code == FAULTHANDLER_EXIT, f'exit {code} after {took:.1f} s:\n{out[-8000:]}'
    assert took < SHUTDOWN_DEADLINE + 3.0, took
    assert 'Timeout (0:00:03)!' in out and 'in wait' in out, out


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_the_stop_signal_is_set_by_each_signal_and_wakes_a_waiter_at_once(signum):
    # The default disposition, whatever this process inherited (``nohup`` ignores SIGHUP,
    # which install() rightly honours).
    inherited = signal.signal(signum, signal.SIG_DFL)
    stop = StopSignal().install()
    try:
        assert not stop.wait(0.01)
        os.kill(os.getpid(), signum)
        start = time.monotonic()
        assert stop.wait(5.0)
        assert time.monotonic() - start < 1.0
        assert stop.signum == signum
    finally:
        stop.restore()
        restored = signal.signal(signum, inherited)
    assert restored is signal.SIG_DFL  # what install() found, put back


_SIGNAL_TO_ANOTHER_THREAD = """
import signal, threading
from i3dmgx2_driver.lifetime import StopSignal

stop = StopSignal().install()
asleep = threading.Event()
beside = threading.Thread(target=lambda: (asleep.set(), threading.Event().wait(60)), daemon=True)
beside.start()
asleep.wait()
# Delivered to that thread, as the kernel may deliver a process's signal to any of its
# threads; the main thread is asleep in the wait, with no timeout to wake it.
threading.Timer(0.2, signal.pthread_kill, (beside.ident, signal.SIGTERM)).start()
print('stopped', stop.wait(), stop.signum == signal.SIGTERM, flush=True)
"""


@pytest.mark.slow
def test_a_signal_delivered_to_another_thread_still_ends_the_wait():
    # Before the pipe was the interpreter's wakeup fd, this waited for ever: the demo's node,
    # under load, went on after the script's SIGTERM.
    code, out = _finish(_python(_SIGNAL_TO_ANOTHER_THREAD), timeout=60.0)
    assert (code, out.strip()) == (0, 'stopped True True'), out


def test_a_sensor_that_fails_its_stop_is_said_and_the_others_still_stop(capsys):
    from types import SimpleNamespace

    from i3dmgx2_driver.device.link import DeviceTimeout
    from i3dmgx2_driver.ros.driver_core import DriverSet

    stopped = []

    def core(address: int, fails: bool) -> SimpleNamespace:
        def shutdown(report: bool) -> None:
            if fails:
                raise DeviceTimeout('no answer to the stop')
            stopped.append(address)
        return SimpleNamespace(sensor=SimpleNamespace(address=address), shutdown=shutdown)

    closed = []
    drivers = SimpleNamespace(cores=[core(95, True), core(96, False)],
                              fault_capture=SimpleNamespace(close=lambda: closed.append('fault')),
                              _capture=SimpleNamespace(close=lambda: closed.append('raw')))
    drivers.each = DriverSet.each.__get__(drivers)
    DriverSet.shutdown(drivers)
    assert stopped == [96] and closed == ['fault', 'raw']
    assert '[i3dmgx2_driver] stopping node 95: no answer to the stop' in capsys.readouterr().err
