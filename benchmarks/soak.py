#!/usr/bin/env python3
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
Soak and fault campaign: the real node against every fault of the simulator.

Runs the node process on a simulated base station for ``--minutes`` of random
faults (line noise, corrupted and foreign packets, drops, lost commands,
jitter, stalls, unplug and replug, power cycles, firmware quirks) at an
accelerated ``--rate``, then checks that it is alive, that its memory did
not grow, that every valid record it could read was published exactly once
and nothing else was, and that its counters reconcile with the simulator's
ground truth. Prints the report with its rules; exits 1 if any check fails.

    python benchmarks/soak.py --minutes 10 --rate 500 --seed 1

``--every-stream`` runs the long soak instead (``harness/long_soak.py``):
every stream in turn at its line-budget maximum rate, in legs of 2.5
minutes, managed node processes that live the whole run
(configure / activate / deactivate / cleanup at every leg) and a plain
node every third leg, the slopes of RSS, descriptors and threads; for an
hour:

    python benchmarks/soak.py --every-stream --minutes 60 --seed 1
"""

import argparse
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.campaign_verdict import CampaignConfig  # noqa: E402, RUF100 - after the path
from harness.long_soak import LongSoak, LongSoakConfig, run_campaign  # noqa: E402, RUF100
from harness.processes import BENCHMARK_DOMAINS, reserve_ros_domain  # noqa: E402, RUF100


def main(argv: list[str] | None = None) -> int:
    """Run the campaign; print the report; return 0 if every check passed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--minutes', type=float, default=10.0,
                        help='length of the fault phase (default 10)')
    parser.add_argument('--rate', type=float, default=500.0,
                        help='simulated data rate in Hz (default 500, beyond the device)')
    parser.add_argument('--seed', type=int, default=1, help='seed of the faults and the data')
    parser.add_argument('--every-stream', action='store_true',
                        help='the long soak: every stream, both node kinds, slopes')
    args = parser.parse_args(argv)
    if args.minutes <= 0 or args.rate <= 0:
        parser.error('--minutes and --rate must be positive')
    # A domain of its own, outside the tests', so that a soak never hears (or is
    # heard by) tests running on the same machine.
    reserve_ros_domain(BENCHMARK_DOMAINS)
    if args.every_stream:
        result = LongSoak(LongSoakConfig(minutes=args.minutes, seed=args.seed)).run()
    else:
        result = run_campaign(CampaignConfig(minutes=args.minutes, rate_hz=args.rate,
                                             seed=args.seed))
    print(result.report, flush=True)
    return 0 if result.ok else 1


if __name__ == '__main__':
    sys.exit(main())
