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
The noise tool listening to a running node: its Imu topic for some minutes.

A progress bar on stderr says the time left and the white noise so far
(N of each gyro axis, from what came); Ctrl-C (or SIGTERM) ends the
listening early and the tool analyses what came. The subscription is best
effort (``qos_profile_sensor_data``), which matches the driver's reliable
publisher and never slows it; the field comes from the sibling ``mag``.
"""

import math
import sys
import time

import numpy as np

from . import allan
from .imu_samples import from_rows, imu_row, Samples, xyz
from .sources import listening

#: Seconds between two updates of the progress bar, and of its estimate.
PROGRESS_S = 1.0
ESTIMATE_S = 10.0
BAR = 30


def progress(elapsed: float, total: float, count: int, estimate: str) -> str:
    """Return one line of the progress bar: the bar, the time left, the estimate so far."""
    done = min(1.0, elapsed / total) if total > 0 else 1.0
    left = max(0.0, total - elapsed)
    bar = '#' * round(done * BAR) + '-' * (BAR - round(done * BAR))
    return f'\r[{bar}] {int(left // 60):3d}:{int(left % 60):02d} left, {count} samples{estimate}'


def _estimate(samples: Samples | None) -> str:
    """Return the gyro's white noise so far, for the progress bar."""
    if samples is None or samples.time.size < 64:
        return ''
    dev = allan.overlapping_adev(samples.gyro, 1.0 / samples.rate_hz)
    terms = allan.read_terms(dev, samples.time.size / samples.rate_hz)
    values = ' '.join(f'{axis.white.value:.2e}' for axis in terms
                      if math.isfinite(axis.white.value))
    return f', gyro N {values} rad/s/√Hz' if values else ''


def listen(topic: str, seconds: float) -> Samples:
    """Listen to ``topic`` for ``seconds`` (or until Ctrl-C); return what came."""
    rows: list[tuple[float, ...]] = []
    fields: list[tuple[float, float, float]] = []

    def samples() -> Samples | None:
        # Copies (the spinner thread appends); None before the second message.
        got, mag = rows[:], np.array(fields[:])
        return (from_rows(got, mag if mag.shape[0] > 2 else None, source)
                if len(got) > 1 else None)

    with listening('i3dmgx2_noise', topic, lambda msg: rows.append(imu_row(msg)),
                   lambda msg: fields.append(xyz(msg.magnetic_field))) as (node, stopped):
        source = f'{node.resolve_topic_name(topic)} (live)'
        start = time.monotonic()
        estimate, next_estimate = '', start + ESTIMATE_S
        while (elapsed := time.monotonic() - start) < seconds and not stopped.wait(PROGRESS_S):
            if time.monotonic() >= next_estimate:
                estimate = _estimate(samples())
                next_estimate += ESTIMATE_S
            print(progress(elapsed, seconds, len(rows), estimate), end='',
                  file=sys.stderr, flush=True)
    found = samples()
    if found is None:
        raise ValueError(f'no message on {source}: is the driver running?')
    return found
