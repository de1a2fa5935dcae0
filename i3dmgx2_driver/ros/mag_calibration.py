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
The magnetometer's calibration as the node applies it: ``soft_iron · (field - hard_iron)``.

Iron that moves with the sensor shifts the field it reads (hard iron) and
squeezes it (soft iron); ``ros2 run i3dmgx2_driver magcal`` fits both
(docs/magcal.md). The node corrects the field in the sensor's own axes (x
forward, y right, z down), whatever ``frame_convention`` publishes, before
the field is turned into the published frame. The correction is built once,
when the parameters are read: at the defaults there is none (None), so
nothing runs and the messages stay as they were, byte for byte; loaded, it
is one call a reading, in plain Python (the hot path has no numpy).

``mag_hard_iron`` (3 values, tesla) and ``mag_soft_iron`` (9, row-major)
give one calibration for every sensor, or one per address (3 and 9 per
sensor, in the order of ``addresses``), as ``streams`` and ``data_rates`` do.
"""

from collections.abc import Callable, Sequence
import math
from typing import Any

HARD_IRON = 'mag_hard_iron'
SOFT_IRON = 'mag_soft_iron'
ZERO = (0.0, 0.0, 0.0)
IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
#: How far a soft-iron matrix may be from symmetric, relative to its largest term.
SYMMETRY = 1e-6
Correction = Callable[[Sequence[float]], tuple[float, float, float]]


def field_correction(hard_iron: Sequence[float], soft_iron: Sequence[float],
                     tesla_per_unit: float) -> Correction | None:
    """Return the correction of a field read in units of ``tesla_per_unit``; None: none."""
    if tuple(hard_iron) == ZERO and tuple(soft_iron) == IDENTITY:
        return None
    hx, hy, hz = (h / tesla_per_unit for h in hard_iron)
    a, b, c, d, e, f, g, h, i = soft_iron

    def correct(field: Sequence[float]) -> tuple[float, float, float]:
        x, y, z = field[0] - hx, field[1] - hy, field[2] - hz
        return (a * x + b * y + c * z, d * x + e * y + f * z, g * x + h * y + i * z)

    return correct


def is_loaded(settings: Any) -> bool:
    """Whether ``settings`` (a MessageSettings) correct the field: the diagnostics say so."""
    return field_correction(settings.mag_hard_iron, settings.mag_soft_iron, 1.0) is not None


def is_matrix_list(values: Sequence[float]) -> bool:
    """Whether ``values`` are 3x3 matrices, each symmetric (SYMMETRY) and positive definite."""
    if not values or len(values) % 9:
        return False
    for k in range(0, len(values), 9):
        a, b, c, d, e, f, g, h, i = values[k:k + 9]
        tolerance = SYMMETRY * max(abs(v) for v in values[k:k + 9])
        symmetric = abs(b - d) <= tolerance and abs(c - g) <= tolerance and abs(f - h) <= tolerance
        # Sylvester: every leading minor positive (NaN fails every comparison).
        if not (symmetric and a > 0 and a * e - b * d > 0
                and a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) > 0):
            return False
    return True


def is_offset_list(values: Sequence[float]) -> bool:
    """Whether ``values`` are finite offsets, three per sensor."""
    return bool(values) and not len(values) % 3 and all(math.isfinite(v) for v in values)


def one_sensors(values: Sequence[float], size: int, index: int) -> tuple[float, ...]:
    """Return sensor ``index``'s ``size`` values: the only ones, or its own of one per sensor."""
    start = 0 if len(values) == size else index * size
    return tuple(float(v) for v in values[start:start + size])


def per_sensor_problem(hard_iron: Sequence[float], soft_iron: Sequence[float],
                       sensors: int) -> str | None:
    """Refuse a calibration given for some sensors but not one each (or one for all)."""
    for name, values, size in ((HARD_IRON, hard_iron, 3), (SOFT_IRON, soft_iron, 9)):
        if len(values) not in (size, size * sensors):
            return (f'parameter {name!r} must give {size} values for all sensors or {size} '
                    f'per sensor ({sensors} addresses), got {len(values)}')
    return None
