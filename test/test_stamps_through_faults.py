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

import dataclasses
import time

from harness.stamp_runs import check, errors, run
from i3dmgx2_driver.codec import line_budget, streams
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.simulator.faults import FaultConfig
import pytest

pytestmark = [pytest.mark.slow, pytest.mark.long]


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


def test_power_cycle_just_before_the_rollover_is_a_reset_not_a_rollover():
    """
    The issue's cut: timer 0.4 s before its rollover, dark for a second, back at 1.04 s.

    The timer's fall looks like a rollover; the monotonic clock says 1.05 s
    passed where a rollover would mean 1.445 s of device time.
    """
    def cut(sim, sup, system):
        target = TIMER_MODULUS - round(0.4 * TICKS_PER_SECOND)
        assert sim.wait_until(lambda: sim.truth[-1].timer >= target - 196_608, 10.0)
        at = time.time()
        sim.power_cycle(off_seconds=1.0, timer_start=20_536_380)
        return at

    result = run(cut, before=0.5, timer_start=TIMER_MODULUS - round(5.0 * TICKS_PER_SECOND))
    check(result)
    status = result.clock.status()
    assert status.restarts == {'start': 1, 'reset': 1}
    assert status.rollovers == 0


def test_stall_keeps_the_fit():
    result = run(lambda sim, sup, system: sim.stall(1.5))
    check(result)
    status = result.clock.status()
    # The first record after the stall may be read late by a busy host: the fit may then
    # start afresh from it (a resync), never as if the device had restarted.
    assert status.restarts.get('start') == 1
    assert set(status.restarts) <= {'start', 'resync'}, status.restarts
    assert status.gaps >= 1


#: One stall per stream, in turn: every stream meets a stall, short and long ones alike.
STALLS = (0.1, 3.0)


@pytest.mark.parametrize(('code', 'seconds'),
                         [(s.code, STALLS[i % len(STALLS)])
                          for i, s in enumerate(streams.STREAMS)],
                         ids=[s.name for s in streams.STREAMS])
def test_a_stall_at_the_streams_line_max_rate_keeps_every_stamp_true(code, seconds):
    """
    Every stream at the highest rate its line allows, 0..3 ms of jitter, a stall.

    The first record after the stall may come late (the jitter, a busy
    host): the fit goes on, or starts afresh, quietly, when it came later
    than 5 ms, and then stamps that first record at its read time (23-32 ms
    late were seen on the 2-core machine at a load average of 5 to 9, so
    the grace is bounded at 0.1 s here). From 0.5 s after the return every
    stamp is within 1 ms again. The device never restarted.
    """
    rate = round(line_budget.max_rate(code, 115200, True), 1)
    result = run(lambda sim, sup, system: sim.stall(seconds), before=3.0, after=3.0,
                 stream=code, data_rate_hz=rate, faults=FaultConfig(jitter_ms=3.0))
    check(result, early_tolerance=0.1)
    assert 'reset' not in result.clock.status().restarts


#: One gap per stream, in turn: every stream meets a queue, the gaps span 0.1 to 3 s.
QUEUE_GAPS = (0.1, 0.3, 1.0, 3.0)


@pytest.mark.parametrize(('code', 'gap'),
                         [(s.code, QUEUE_GAPS[i % len(QUEUE_GAPS)])
                          for i, s in enumerate(streams.STREAMS)],
                         ids=[s.name for s in streams.STREAMS])
def test_a_queue_on_a_line_at_its_limit_is_told_from_lost_time(code, gap):
    """
    The base station's line at the stream's limit, its radio back 50 ms late after a stall.

    The records sampled meanwhile queue behind the first on the line and
    reach the host late, each a little less (the simulator's ``line_queue``
    and ``radio_hold_s``), read as a host reads them: not one wire time
    apart to the tenth of a millisecond. The queue takes about a second to
    drain. Their residuals on the line before the gap fall, the line comes
    back after the queue's first records, and from 0.5 s after the return
    every stamp is within 1 ms (before, the fit started afresh from the
    queue's head and followed the queue out: 25 ms off after the grace).
    The fit was kept, but where a loaded host had read every record of the
    first seconds late, so that the first after the gap came early on a
    line set too high: that one starts afresh, as before (clock.md).
    """
    rate = round(line_budget.max_rate(code, 115200, True), 1)
    result = run(lambda sim, sup, system: sim.stall(gap), before=3.0, after=gap + 3.0,
                 stream=code, data_rate_hz=rate, faults=FaultConfig(jitter_ms=1.0),
                 line_queue=True, radio_hold_s=0.050, limit_to_line_rate=True)
    check(result, early_tolerance=0.1)
    assert 'reset' not in result.clock.status().restarts


def test_noise_and_another_sensor_on_the_line_from_power_up_keep_the_stamps_true():
    """
    Garbage, corrupted packets and another sensor's packets take the line from the start.

    0xCC at 100 Hz (80 % of the line); a third of the packets have garbage
    before them and a fifth another sensor's packet, on the base station's
    line (``line_queue``): queues form and drain, and corrupted packets make
    gaps. Every stamp after the first 0.5 s is within 1 ms, with no trend;
    before, a record that came 22 ms late behind a queue as the timer rolled
    over (3.8 s in) restarted the fit, whose stamps followed the queue out.
    """
    faults = FaultConfig(garbage_probability=0.3, corrupt_checksum_probability=0.05,
                         corrupt_length_probability=0.02, foreign_probability=0.2,
                         jitter_ms=1.0)
    result = run(None, before=15.0, after=0.0, faults=faults, line_queue=True)
    check(result)
    assert 'reset' not in result.clock.status().restarts


def pause_the_stream(sim, sup, system):
    """Do what a managed node's deactivate (0xFA, port kept) and activate 1 s later do."""
    sup.stop_streaming()
    time.sleep(1.0)
    sup.start_streaming()


@pytest.mark.parametrize('fault', [
    # The base station unplugged: the wireless sensor's timer ran on meanwhile.
    pytest.param(lambda sim, sup, system: sim.unplug(1.0), id='unplug_and_replug'),
    pytest.param(lambda sim, sup, system: sim.set_rate(200.0), id='rate_change'),
    pytest.param(pause_the_stream, id='stream_stopped_and_started_again'),
])
def test_the_fit_is_kept_through(fault):
    result = run(fault)
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
