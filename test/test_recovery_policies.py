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
The supervisor's decisions that need no port: policies on a fake clock, the report, the loop.

StallWatch and ReopenWait (the reconnect back-off) decide on a clock passed
in; DeviceReport is the one place that changes what diagnostics show; the
supervisor's thread is driven here with a serial port that never opens (its
class's opening replaced in this process), so that what it decides about a
failed port is seen without a simulator (the
exclusive access, which needs a streaming sensor, is driven in
test_supervisor_phases.py).
"""

import time

from i3dmgx2_driver.device.observer import Finding
from i3dmgx2_driver.device.port import PortMissing, PortNotSerial, SerialPort
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.device.status import DeviceReport, State
from i3dmgx2_driver.device.supervisor import DeviceSupervisor
from i3dmgx2_driver.device.watchdog import (
    LOOK_MARGIN_S, PORT_SETTLE_S, PORT_WATCH_S, ReopenWait, StallWatch,
)
from log_lines import Log
import pytest


class FakeClock:
    """A monotonic clock that moves only when waited on."""

    def __init__(self) -> None:
        self.now = 1000.0
        self.waits: list[float] = []
        self.cancelled = False

    def __call__(self) -> float:
        return self.now

    def wait(self, seconds: float) -> bool:
        """Wait as Event.wait does: True when cancelled (then at once)."""
        if self.cancelled:
            return True
        self.waits.append(seconds)
        self.now += seconds
        return False


# -- StallWatch ---------------------------------------------------------------------------


def test_a_stall_is_silence_beyond_the_timeout():
    clock = FakeClock()
    watch = StallWatch(stall_timeout=1.0, period=0.01, clock=clock)
    assert watch.stall_after == 1.0
    assert not watch.stalled(clock.now - 1.0)
    assert watch.stalled(clock.now - 1.001)


def test_a_slow_rate_is_no_stall():
    clock = FakeClock()
    watch = StallWatch(stall_timeout=0.3, period=0.5, clock=clock)  # 2 Hz
    assert watch.stall_after == pytest.approx(1.5)
    assert not watch.stalled(clock.now - 1.0)


def test_the_watch_sleeps_until_the_stream_would_have_stalled():
    clock = FakeClock()
    watch = StallWatch(stall_timeout=1.0, period=0.01, clock=clock)
    assert watch.next_look(clock.now - 0.25) == pytest.approx(0.75 + LOOK_MARGIN_S)
    assert watch.next_look(clock.now - 5.0) == pytest.approx(LOOK_MARGIN_S)  # at once
    last = clock.now
    clock.wait(watch.next_look(last))  # nothing came meanwhile: stalled when it looks
    assert watch.stalled(last)


# -- ReopenWait ---------------------------------------------------------------------------


def test_a_port_that_stays_is_tried_again_after_the_interval():
    clock = FakeClock()
    ReopenWait('/dev/x', 1.0, clock.wait, exists=lambda path: True, clock=clock)()
    assert 1.0 <= sum(clock.waits) <= 1.0 + 1.5 * PORT_WATCH_S  # within one look
    assert set(clock.waits) == {PORT_WATCH_S}


def test_a_port_seen_missing_is_reopened_once_it_is_back():
    clock = FakeClock()
    start = clock.now
    present = iter([False] * 5 + [True])
    ReopenWait('/dev/x', 1.0, clock.wait, exists=lambda path: next(present),
               clock=clock)()
    assert clock.waits[-1] == PORT_SETTLE_S
    assert clock.now - start == pytest.approx(6 * PORT_WATCH_S + PORT_SETTLE_S)


def test_a_port_closed_for_a_stall_is_reopened_at_once():
    clock = FakeClock()
    ReopenWait('/dev/x', 1.0, clock.wait, exists=lambda path: True,
               clock=clock)(after_stall=True)
    assert clock.waits == []


def test_a_stop_ends_the_wait_at_once():
    clock = FakeClock()
    clock.cancelled = True
    ReopenWait('/dev/x', 1.0, clock.wait, exists=lambda path: True, clock=clock)()
    assert clock.waits == []


# -- DeviceReport -------------------------------------------------------------------------


def test_streaming_is_declared_by_one_method_only():
    report = DeviceReport(Log())
    with pytest.raises(ValueError):
        report.enter(State.STREAMING)
    report.finding(Finding('silence', 'nothing on the line'))
    assert report.advice == 'nothing on the line'
    report.streaming('full')
    report.streaming('resumed')
    report.stalled()
    report.streaming()
    fields = report.fields()
    assert fields['state'] is State.STREAMING and fields['advice'] == ''
    assert fields['last_start'] == 'resumed' and fields['resumes'] == 1
    assert fields['stalls'] == 1


def test_a_problem_is_said_once_and_kept_as_the_last_error():
    log = Log()
    report = DeviceReport(log)
    for n in range(3):
        report.warn('missing', f'port missing ({n})')
    assert log.lines == [('warning', 'port missing (0)')]
    assert report.fields()['last_error'] == 'port missing (2)'


# -- the supervisor thread, on a port that never opens ----------------------------------


class FailingPort:
    """A serial port that never opens: it raises ``error`` each time, and counts the tries."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, error: Exception) -> None:
        self.error = error
        self.opened = 0
        monkeypatch.setattr(SerialPort, '__init__', self._open)

    def _open(self, *args, **kwargs) -> None:
        self.opened += 1
        raise self.error


def supervisor_on(**config):
    log, fatal = Log(), []
    sup = DeviceSupervisor(DeviceConfig(port='/dev/x', address=95, **config),
                           on_record=lambda packet, now, mono: None, log=log,
                           on_fatal=fatal.append)
    return sup, fatal, log


def wait_until(condition, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.005)
    return condition()


def test_a_port_that_can_never_work_ends_the_loop_once(monkeypatch):
    error = PortNotSerial('/tmp: a directory, not a serial port')
    port = FailingPort(monkeypatch, error)
    sup, fatal, log = supervisor_on()
    sup.start()
    assert wait_until(lambda: fatal) and sup.join(5.0)
    assert port.opened == 1 and fatal == [error]
    status = sup.status()
    assert status.state is State.STOPPED and status.fatal_error == str(error)
    assert log.lines == [], 'the entry point says it, once, as it exits'


def test_a_missing_port_is_retried_and_said_once(monkeypatch):
    port = FailingPort(monkeypatch, PortMissing('/dev/x: no such port'))
    sup, fatal, log = supervisor_on(reconnect_interval=0.01)
    sup.start()
    try:
        assert wait_until(lambda: port.opened >= 5
                          and sup.status().state is State.DISCONNECTED)
    finally:
        sup.stop()
        assert sup.join(5.0)
    assert port.opened >= 5 and not fatal
    assert log.lines == [('warning', '/dev/x: no such port (retrying every 0.01 s)')]
