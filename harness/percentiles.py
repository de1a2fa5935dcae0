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
Statistics of a sample: its percentiles, and the summary the benchmarks print.

One percentile for everything that reports one: interpolated between the
two nearest ranks, ``q`` in 0..100.
"""

import math
from typing import NamedTuple


def percentile(values: list[float], q: float) -> float:
    """Return the q-th percentile of the values, q in 0..100, interpolated; NaN for none."""
    if not values:
        return math.nan
    ordered = sorted(values)
    position = (len(ordered) - 1) * q / 100.0
    low = math.floor(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (position - low)


class Summary(NamedTuple):
    """Count, mean, p50, p99 and max of a sample."""

    n: int
    mean: float
    p50: float
    p99: float
    max_: float

    def ms(self) -> str:
        """Format as milliseconds: ``p50 / p99 / max``."""
        return (f'{self.p50 * 1e3:.3f} / {self.p99 * 1e3:.3f} / {self.max_ * 1e3:.3f} ms '
                f'(n={self.n})')


def summarise(values: list[float]) -> Summary:
    """Summarise a sample (NaN everywhere when it is empty)."""
    if not values:
        return Summary(0, math.nan, math.nan, math.nan, math.nan)
    return Summary(len(values), sum(values) / len(values), percentile(values, 50),
                   percentile(values, 99), max(values))


def std_dev(values: list[float]) -> float:
    """Return the population standard deviation (NaN for fewer than two values)."""
    if len(values) < 2:
        return math.nan
    mean = sum(values) / len(values)
    return math.sqrt(sum((v - mean) ** 2 for v in values) / len(values))
