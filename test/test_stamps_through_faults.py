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
Stamps against the simulator's true sample times, through every event that touches time.

The real supervisor, link and parser read a simulated sensor over a
pseudo-terminal, and every record is stamped by a :class:`SampleClock`
wired to them as the node wires it (a record to ``stamp``, a new link to
``link_changed``). The system clock the stamps follow is the real one plus
a step the test makes: the seam the node's clock reads. Each event is
applied while the sensor streams; the stamp error (stamp minus the true
sample time on the stepped clock) is checked as a series over the whole run:
within 1 ms of the steady offset (the one before the event) everywhere but
in the 0.5 s after the start and after the stream's return, within 5 ms in
those, and without a trend. test_node_stamps.py runs the power cycle of the
issue through the node process itself.
"""

from collections.abc import Callable
import dataclasses
import threading
import time

from i3dmgx2_driver.codec import line_budget, streams
from i3dmgx2_driver.device.sample_clock import SampleClock, system_clock_offset
from i3dmgx2_driver.device.supervisor import DeviceSupervisor, SupervisorConfig
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from stamp_series import check_series

pytestmark = pytest.mark.slow



class SteppedSystemClock:
    """The system clock's offset from the monotonic one, plus a step the test sets."""

    def __init__(self) -> None:
        self.step = 0.0
        self.applied = 0.0

    def offset(self) -> float:
        self.applied = self.step
        return system_clock_offset() + self.step


@dataclasses.dataclass
class Run:
    """What a scenario produced: stamped records, the truth, and when the event came."""

    rows: list  # (accel, stamp, step applied)
    truth: dict  # accel -> true sample time
    event_time: float | None
    clock: SampleClock
    log: list


class Log:
    """Collect the supervisor's messages (for a failure's explanation)."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def __getattr__(self, level: str) -> Callable[[str], None]:
        return lambda message: self.lines.append(f'{level}: {message}')


def run(event: Callable[[PtySimulator, DeviceSupervisor, SteppedSystemClock], None] | None,
        before: float = 3.0, after: float = 4.0, stream: int = streams.DEFAULT.code,
        data_rate_hz: float | None = None, **sim: object) -> Run:
    """Stream ``before`` s, apply ``event``, stream ``after`` s more; return what was seen."""
    wire = line_budget.wire_time(stream, 115200, True)
    system = SteppedSystemClock()
    clock = SampleClock(offset=system.offset)
    rows = []
    lock = threading.Lock()

    def on_record(packet, read_time: float, read_mono: float) -> None:
        with lock:
            stamp = clock.stamp(packet.record.timer, read_mono, wire)
            rows.append((packet.record.accel, stamp, system.applied))

    def on_connect() -> None:
        with lock:
            clock.link_changed()

    log = Log()
    config = dict(seed=23, **sim)
    with PtySimulator(SimulatorConfig(**config)) as simulator:
        sup = DeviceSupervisor(
            SupervisorConfig(port=simulator.port, address=95, low_latency=False,
                             stall_timeout=0.3, reconnect_interval=0.2, stream=stream,
                             data_rate_hz=data_rate_hz),
            on_record=on_record, on_connect=on_connect, log=log)
        sup.start()
        try:
            deadline = time.monotonic() + 10.0
            while not rows and time.monotonic() < deadline:
                time.sleep(0.01)
            assert rows, f'no records: {log.lines}'
            time.sleep(before)
            event_time = time.time() if event is not None else None
            if event is not None:
                event(simulator, sup, system)
            time.sleep(after)
        finally:
            sup.stop()
        truth = {t.record.accel: t.sample_time for t in simulator.truth
                 if t.valid and t.source == 'stream'}
    return Run(rows, truth, event_time, clock, log.lines)


def errors(result: Run) -> list[tuple[float, float]]:
    """(true sample time, stamp error on the stepped system clock), in order of stamping."""
    out = []
    for accel, stamp, step in result.rows:
        sample_time = result.truth.get(accel)
        if sample_time is not None:
            out.append((sample_time, stamp - step - sample_time))
    return out


def check(result: Run) -> dict:
    """Assert the error series is true after every grace; return a few figures."""
    series = errors(result)
    assert len(series) > 200, result.log
    return check_series(series, result.event_time, result.log)


def test_steady_stream_and_the_timer_rollover():
    """The simulated timer starts 5 s before its rollover: the fit goes through it."""
    result = run(None, before=8.0, after=0.0)
    check(result)
    status = result.clock.status()
    assert status.rollovers == 1
    assert status.restarts == {'start': 1}


def test_power_cycle_restarts_the_fit_and_is_reported():
    """Power lost and back at once, timer restarted: the fit starts afresh."""
    result = run(lambda sim, sup, system: sim.power_cycle())
    figures = check(result)
    assert figures['back'] is not None
    assert result.clock.status().restarts.get('reset') == 1


def test_stall_keeps_the_fit():
    result = run(lambda sim, sup, system: sim.stall(1.5))
    check(result)
    status = result.clock.status()
    assert status.restarts == {'start': 1}
    assert status.gaps >= 1


def test_unplug_and_replug_keeps_the_fit():
    """The base station unplugged: the wireless sensor's timer ran on meanwhile."""
    result = run(lambda sim, sup, system: sim.unplug(1.0))
    check(result)
    assert result.clock.status().restarts == {'start': 1}


def test_reconnect_to_another_sensor_starts_afresh():
    """While the port is gone the sensor is swapped (its timer far from the old one)."""
    def swap(sim, sup, system):
        sim.unplug(1.0)
        sim.power_cycle()

    result = run(swap)
    check(result)
    assert result.clock.status().restarts.get('reset') == 1


def test_rate_change_keeps_the_fit():
    result = run(lambda sim, sup, system: sim.set_rate(200.0))
    check(result)
    assert result.clock.status().restarts == {'start': 1}


def test_stream_stopped_and_started_again_keeps_the_fit():
    """A managed node's deactivate (0xFA, port kept) and activate 1 s later."""
    def pause(sim, sup, system):
        sup.stop_streaming()
        time.sleep(1.0)
        sup.start_streaming()

    result = run(pause)
    check(result)
    assert result.clock.status().restarts == {'start': 1}


@pytest.mark.parametrize('step', [1.0, -1.0])
def test_system_clock_step_is_followed_at_once(step):
    """NTP steps the clock: stamps follow at once; the fit is not disturbed."""
    def step_clock(sim, sup, system):
        system.step = step

    result = run(step_clock)
    errs = errors(result)
    # Stamped after the step: the error (against the stepped clock) is steady at once.
    check(dataclasses.replace(result, event_time=None))
    assert any(step_applied == step for _, _, step_applied in result.rows)
    assert result.clock.status().restarts == {'start': 1}
    assert len(errs) > 200
