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
The long soak of ``benchmarks/soak.py --every-stream``, for about a minute in CI.

Same code (harness/long_soak.py), same checks but the slopes (a minute is too
short to fit a leak): three legs (the full stream and one without the
magnetometer on managed nodes that live the whole run, one with it on a plain
node), each at its line-budget maximum rate through every fault, then the
managed nodes shut down from a random state. The pieces the verdict rests on
(the legs, the slope fit) are checked first, fast.
"""

import os
import tempfile

from harness.long_soak import LongSoak, LongSoakConfig, plan_legs
from harness.process_sampler import halves_per_hour, process_sample, rss_kinds, \
    slope_per_hour
from i3dmgx2_driver.codec import line_budget, streams
import pytest


def test_legs_go_round_every_stream_at_its_line_budget_maximum():
    legs = plan_legs(LongSoakConfig(legs=18, plain_every=3))
    assert [leg.stream for leg in legs] == [s.name for s in streams.STREAMS] * 3
    assert [leg.kind for leg in legs[:3]] == ['managed', 'managed', 'plain']
    assert sum(leg.kind == 'plain' for leg in legs) == 6
    # Within three rounds every stream runs on both kinds of node.
    for stream in streams.STREAMS:
        assert {leg.kind for leg in legs if leg.stream == stream.name} == {'managed', 'plain'}
    for leg in legs:
        code = streams.BY_NAME[leg.stream].code
        fits = line_budget.max_rate(code, 115200, wireless=True)
        assert fits - 0.1 <= leg.rate_hz <= fits
        assert streams.line_budget(streams.BY_NAME[leg.stream], leg.rate_hz, 115200, True).fits


def test_an_hour_goes_round_every_stream_three_times():
    assert len(plan_legs(LongSoakConfig(minutes=60.0))) >= 3 * len(streams.STREAMS)
    assert len(plan_legs(LongSoakConfig(minutes=0.1))) == 1


def test_slope_is_per_hour_and_ignores_a_constant():
    # 1 MiB every 3600 s -> 1 MiB/h; exact on a line, whatever the offset.
    assert slope_per_hour([(t, 50.0 + t / 3600.0) for t in range(0, 600, 5)]) \
        == pytest.approx(1.0)
    assert slope_per_hour([(t, 7.0) for t in range(10)]) == 0.0
    assert slope_per_hour([(0.0, 1.0), (1.0, 2.0)]) is None


def test_a_warm_up_slows_by_halves_and_a_leak_keeps_its_pace():
    leak = [(t, 50.0 + t / 3600.0) for t in range(0, 3600, 30)]
    assert halves_per_hour(leak) == pytest.approx((1.0, 1.0))
    # Grows 2 MiB/h for half an hour, then holds: by halves, 2 then 0.
    warm = [(t, 50.0 + 2.0 * min(t, 1800) / 3600.0) for t in range(0, 3601, 30)]
    first, second = halves_per_hour(warm)
    assert first == pytest.approx(2.0) and second == pytest.approx(0.0, abs=1e-9)
    assert halves_per_hour(leak[:5]) is None


def test_rss_kinds_add_up_to_rss_and_a_gone_process_gives_none():
    rss, fds, threads = process_sample(os.getpid())
    anon, file, shmem = rss_kinds(os.getpid())
    assert anon > 0 and file > 0 and shmem >= 0 and fds > 0 and threads >= 1
    # Read a moment apart: the sum is RSS to within what this test allocates meanwhile.
    assert abs(anon + file + shmem - rss) < 4096
    with open('/proc/sys/kernel/pid_max') as handle:
        never = int(handle.read())  # pids stay below it
    assert process_sample(never) is None and rss_kinds(never) is None


@pytest.mark.slow
@pytest.mark.alone
def test_soak_every_stream_short(tmp_path, monkeypatch):
    # Every temporary file of the run (node logs, counters, the simulator's link) under
    # tmp_path: each plain node's log was left behind (one a run, until 2026-11-27).
    monkeypatch.setattr(tempfile, 'tempdir', str(tmp_path))
    cfg = LongSoakConfig(minutes=1.0, legs=3, leg_minutes=0.2, quiet=3.0,
                         event_gap=(0.3, 1.0), seed=7, log=None)
    result = LongSoak(cfg).run()
    assert result.ok, result.report
    assert not list(tmp_path.iterdir()), sorted(p.name for p in tmp_path.iterdir())
    # A managed node lives on after its leg and counts what it reads while inactive: those
    # two checks are the plain node's only, in the verdict and in the report.
    for name in ('clean exit on SIGINT', 'nothing left unpublished'):
        legs = {c.name.split(')')[0] for c in result.checks if c.name.endswith(f': {name}')}
        assert legs and all('(plain ' in leg for leg in legs), legs
