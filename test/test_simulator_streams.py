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
The simulator streams every record the driver offers, at any rate, within the line.

A test can start at any record and rate: the record streams from power-up
(EEPROM auto-start) at the divider preset in the EEPROM. In line-rate mode a
record the line is still busy for is skipped, judged on the device's own
schedule: at the highest rate that fits nothing is skipped however late the
simulator's threads run, nor for the replies to commands sent meanwhile, and
beyond what the line carries the records that get through come at the line's
packet rate.
"""

import itertools
import math

from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import line_budget, streams
from i3dmgx2_driver.codec.data_rate import rate_of_divider
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.simulator import PtySimulator, SimulatorConfig
import pytest
from test_simulator import assert_host_saw_exactly_valid_truth, Host, stop_stream
from test_simulator_wired import assert_wired_host_saw_exactly_valid_truth, stop_wired_stream

pytestmark = pytest.mark.slow


def preset(stream: streams.Stream, divider: int, **config) -> PtySimulator:
    """Return a simulator that streams ``stream`` at ``divider`` from power-up."""
    return PtySimulator(SimulatorConfig(streaming_at_start=stream.code, divider=divider,
                                        seed=stream.code, limit_to_line_rate=True, **config))


@pytest.mark.parametrize('stream', streams.STREAMS, ids=lambda s: s.name)
def test_every_stream_at_the_highest_rate_that_fits_loses_nothing(stream):
    rate = line_budget.max_rate(stream.code, 115200, wireless=True)
    divider = round(51200 / rate)
    with preset(stream, divider) as sim, Host(sim) as host:
        host.pump(1.5)
        stop_stream(host)
        host.drain()
        records = host.records(stream.code)
        assert len(records) > rate  # more than a second's worth
        assert all(type(r) is stream.record_type for r in records)
        assert sim.stats.line_rate_skipped == 0
        assert_host_saw_exactly_valid_truth(host, sim)
        steps = {round(((b.timer - a.timer) % TIMER_MODULUS) / (384 * divider))
                 for a, b in itertools.pairwise(records)}
        assert steps == {1}, 'a cycle is missing'


@pytest.mark.parametrize('stream', [streams.BY_NAME['full'], streams.BY_NAME['inertial']],
                         ids=lambda s: s.name)
def test_beyond_the_line_records_are_skipped_down_to_the_line_rate(stream):
    divider = 171  # 299.4 Hz: more than the line carries for either
    line_rate = (line_budget.line_bytes_per_second(115200)
                 / line_budget.packet_size(stream.code, wireless=True))
    with preset(stream, divider) as sim, Host(sim) as host:
        host.pump(1.5)
        stop_stream(host)
        host.drain()
        streamed = [t for t in sim.truth if t.source == 'stream']
        sent = [t for t in streamed if t.write_time is not None]
        span = streamed[-1].sample_time - streamed[0].sample_time
        assert sim.stats.line_rate_skipped > 0
        # What the line let through, by the device's clock: a record goes out at the
        # first whole cycle after the line is free again, so one in every
        # ceil(packet time / period) cycles: 0xCC one in 3, 0xC2 one in 2.
        rate = rate_of_divider(divider)
        assert rate > line_rate
        every = math.ceil(line_budget.wire_time(stream.code, 115200, True) * rate)
        assert every == {0xCC: 3, 0xC2: 2}[stream.code]
        assert (len(sent) - 1) / span == pytest.approx(rate / every, rel=0.01)
        assert_host_saw_exactly_valid_truth(host, sim)


def test_replies_interleave_without_costing_a_record_of_a_stream_that_fits():
    """
    Wired inertial at 299.4 Hz fills 2.69 ms of each 3.34 ms cycle; a reply comes in between.

    Each 20-byte identifier reply takes 1.74 ms of line, sent when its command
    arrives, where the stream leaves 0.65 ms a cycle free: a reply overlaps
    the next cycle whenever that begins less than 1.74 ms after it. A stream
    record is skipped only for the stream's own previous record (docs/protocol.md §5:
    replies are interleaved with the stream), so none of the 40 costs a
    record; an accounting that let replies take the line from the stream
    skipped a record for each of the 40 when tried.
    """
    stream = streams.BY_NAME['inertial']
    with preset(stream, 171, wireless=False) as sim, Host(sim) as host:
        assert host.pump_until(lambda: len(host.records(stream.code)) >= 10)
        for i in range(40):
            reply = host.request(cmd.device_identifier(i % 4), code=lay.DEVICE_IDENTIFIER)
            assert reply.selector == i % 4
        stop_wired_stream(host)
        assert sim.stats.line_rate_skipped == 0
        assert_wired_host_saw_exactly_valid_truth(host, sim)
        steps = {round(((b.timer - a.timer) % TIMER_MODULUS) / (384 * 171))
                 for a, b in itertools.pairwise(host.records(stream.code))}
        assert steps == {1}, 'a cycle is missing'
