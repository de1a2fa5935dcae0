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
The long soak's settings and its legs: what the run will do, before it runs.

Kept apart from the run (``long_soak.py``) so that the plan can be checked
fast, without a simulator or a node (``test/test_soak_every_stream.py``).
"""

import dataclasses
from typing import NamedTuple

from harness.run_config import FaultedNodeConfig
from i3dmgx2_driver.codec import line_budget
from i3dmgx2_driver.codec.streams import STREAMS

BAUD = 115200
#: Seconds a leg takes besides its faults and quiet phase (transitions, draining), roughly.
LEG_OVERHEAD = 15.0


@dataclasses.dataclass
class LongSoakConfig(FaultedNodeConfig):
    """
    How long, how rough, and what counts as a pass.

    The seed, address, node timeouts, fault pacing (the quiet phase: at the
    end of each leg) and log: ``FaultedNodeConfig``.
    """

    #: Length of the whole run (min): legs follow one another until it is over.
    minutes: float = 60.0
    #: Length of each leg's fault phase (min); a quiet phase follows.
    leg_minutes: float = 2.5
    #: How many legs (None: as many as fit in ``minutes``).
    legs: int | None = None
    #: The streams the legs go round (names; empty: every stream).
    streams: tuple[str, ...] = ()
    #: Every this many legs, the plain node runs the leg instead of a managed one (0: never);
    #: shifted by one leg each round of the streams.
    plain_every: int = 3
    #: Seconds from the end of a fault to the next message received, at most.
    recovery_limit: float = 1.0
    #: Slopes are fitted from this many seconds after the start of each process.
    slope_after: float = 300.0
    #: Slopes are asserted only for runs at least this long (min).
    slope_min_minutes: float = 30.0
    #: Most RSS slope allowed (MiB per hour), and descriptors / threads (per hour).
    rss_slope_limit: float = 1.0
    count_slope_limit: float = 1.0
    #: Seconds between samples of RSS, descriptors and threads.
    sample_period: float = 5.0


class Leg(NamedTuple):
    """One stream, one node kind, one stretch of faults."""

    number: int
    stream: str
    rate_hz: float
    kind: str


def plan_legs(cfg: LongSoakConfig) -> list[Leg]:
    """Return the legs: the streams in turn, each at its line-budget maximum rate."""
    leg_seconds = cfg.leg_minutes * 60.0 + cfg.quiet + LEG_OVERHEAD
    count = cfg.legs or max(1, round(cfg.minutes * 60.0 / leg_seconds))
    chosen = [s for s in STREAMS if not cfg.streams or s.name in cfg.streams]
    legs = []
    for number in range(count):
        stream = chosen[number % len(chosen)]
        rate = line_budget.max_rate(stream.code, BAUD, wireless=True)
        # Shifted by one each round of the streams, so that every stream meets both kinds.
        turn = number + number // len(chosen)
        plain = cfg.plain_every and (turn + 1) % cfg.plain_every == 0
        # Rounded down to 0.1 Hz: the parameter's text must map to the same divider.
        legs.append(Leg(number, stream.name, int(rate * 10) / 10.0,
                        'plain' if plain else 'managed'))
    return legs
