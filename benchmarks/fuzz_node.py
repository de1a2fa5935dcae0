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
Fuzz the running node through its port: a hostile base station, end to end.

The node process talks to a hostile base station (``harness/hostile.py``) in
front of the simulator; attacks are armed in every phase of the dialogue and
the node is checked all the time (``harness/node_fuzz.py``): it lives,
answers, keeps publishing /diagnostics, publishes nothing the bytes did not
hold as a valid packet from its address, publishes every intact one, and
streams again once the station behaves. Prints the duration, packets,
inputs per second and findings (each with the bytes before it); exits 1 on
any finding. For 30 minutes and at least a million packets:

    python benchmarks/fuzz_node.py --minutes 30 --packets 1000000 --seed 1
"""

import argparse
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.node_fuzz import FuzzConfig, run_node_fuzz  # noqa: E402, RUF100 - after the path
from harness.processes import BENCHMARK_DOMAINS, reserve_ros_domain  # noqa: E402, RUF100


def main(argv: list[str] | None = None) -> int:
    """Run the fuzz; print the report; return 0 if nothing was found."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--minutes', type=float, default=30.0, help='at least this long')
    parser.add_argument('--packets', type=int, default=0,
                        help='and at least this many packets through the station')
    parser.add_argument('--rate', type=float, default=600.0,
                        help='simulated packets per second (default 600)')
    parser.add_argument('--seed', type=int, default=1, help='seed of the attacks and the data')
    args = parser.parse_args(argv)
    if args.minutes <= 0 or args.rate <= 0 or args.packets < 0:
        parser.error('--minutes and --rate must be positive, --packets not negative')
    reserve_ros_domain(BENCHMARK_DOMAINS)
    result = run_node_fuzz(FuzzConfig(minutes=args.minutes, packets=args.packets,
                                      rate_hz=args.rate, seed=args.seed))
    print(result.report(), flush=True)
    return 0 if result.ok else 1


if __name__ == '__main__':
    sys.exit(main())
