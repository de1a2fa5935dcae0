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
The inertial sensors' own noise, term by term, as an Allan deviation reads it back.

Three terms per axis of gyro and accelerometer (IEEE Std 952 names):

- white noise, density N: each sample gets ``N / sqrt(dt)``;
- bias instability B: flicker (1/f) noise whose Allan deviation is flat at
  ``B * sqrt(2 ln 2 / pi)`` (0.664 B). 1/f noise has no finite state, so it
  is made as the sum of first-order Gauss-Markov processes whose time
  constants are spaced by ``FLICKER_RATIO`` from ``FLICKER_SHORTEST_S`` to
  ``FLICKER_LONGEST_S``, each of variance ``B^2 ln(ratio) / pi``: their
  Lorentzian spectra sum to ``B^2 / (pi f)`` (one-sided) over that band, flicker's;
- rate random walk K: the bias walks by ``K * sqrt(dt)`` a sample.

The model keeps its state (the walk, the Gauss-Markov processes), so that
:meth:`NoiseModel.draw` continues where the last call ended: a running
simulator takes a few samples at a time, the still capture an hour in
blocks, and both get the same process. Everything is numpy and vectorised,
an hour at 250 Hz (900,000 samples, 6 axes) in about a second.

Units are the device's (rad/s and g), as everywhere in the simulator.
The defaults are those of the real records (test/fixtures/
gx2_real_0xcc_records.txt: four sets of 300 to 1000 records of a sensor at
rest, polled at 3 Hz over 100 to 620 s); docs/noise.md shows how each was
read. The 3DM-GX2 datasheet gives no noise density, bias instability or
random walk (docs/parameters.md), so where the records only bound a term
the default is taken inside that bound.
"""

import dataclasses
import math

import numpy as np

Vector3 = tuple[float, float, float]

#: Spacing of the Gauss-Markov time constants that make the flicker noise.
FLICKER_RATIO = 2.0
#: Shortest and longest time constant (s): the flicker is flat from a few times the
#: shortest to a fraction of the longest. Half a sample at 250 Hz: from 0.06 s the floor
#: missing under it biased an hour's N by a few times its scatter, and much shorter ones
#: add white noise (issue 56).
FLICKER_SHORTEST_S = 2.0 ** -9
FLICKER_LONGEST_S = 4096.0
#: Samples drawn at once: the Gauss-Markov processes take 16 columns per axis.
BLOCK = 1 << 15
#: exp(-dt / T) of a chunk's worth of samples may shrink to this before the AR(1)
#: closed form loses precision (a factor of e^20 between its terms).
_AR1_SPAN = 20.0


@dataclasses.dataclass(frozen=True)
class NoiseConfig:
    """
    The noise terms of one sensor, per axis x, y, z, in the device's units.

    Defaults: white noise from the sample-to-sample scatter of the real
    records (its standard deviation over sqrt(2)) at the factory 100 Hz;
    bias instability and random walk inside the bounds the records' Allan
    deviation sets (docs/noise.md, "The simulator's noise").
    """

    #: Gyro white noise density (rad/s/sqrt(Hz)): records' 1.75, 1.48, 1.35 mrad/s a sample.
    gyro_white: Vector3 = (1.75e-4, 1.48e-4, 1.35e-4)
    #: Gyro bias instability (rad/s): the records' deviation over white at 85 s, 0.1 mrad/s.
    gyro_bias_instability: Vector3 = (1.5e-4, 1.0e-4, 0.75e-4)
    #: Gyro rate random walk (rad/s^2/sqrt(Hz)): below the records' bound (no rise by 85 s).
    gyro_random_walk: Vector3 = (4.3e-5, 2.9e-5, 2.2e-5)
    #: Accelerometer white noise density (g/sqrt(Hz)): records' 0.23, 0.22, 0.25 mg a sample.
    accel_white: Vector3 = (2.3e-5, 2.2e-5, 2.5e-5)
    #: Accelerometer bias instability (g): the records' floor, 50, 24 and 60 ug at 10-40 s.
    accel_bias_instability: Vector3 = (3.0e-5, 2.5e-5, 3.0e-5)
    #: Accelerometer random walk (g/s/sqrt(Hz)): the records' bound on x and y (3 ug/s).
    accel_random_walk: Vector3 = (8.8e-6, 7.2e-6, 8.8e-6)

    def __post_init__(self) -> None:
        """Reject a term that is no noise, naming it."""
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if len(value) != 3 or not all(math.isfinite(v) and v >= 0 for v in value):
                raise ValueError(f'{field.name} must be three finite values >= 0 '
                                 f'(x, y, z), got {value!r}')

    def terms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return white, bias instability and random walk as (6,) arrays: gyro xyz, accel xyz."""
        return (np.array(self.gyro_white + self.accel_white),
                np.array(self.gyro_bias_instability + self.accel_bias_instability),
                np.array(self.gyro_random_walk + self.accel_random_walk))


def flicker_time_constants() -> np.ndarray:
    """Return the time constants (s) of the Gauss-Markov processes that make the flicker."""
    count = round(math.log(FLICKER_LONGEST_S / FLICKER_SHORTEST_S, FLICKER_RATIO)) + 1
    return FLICKER_SHORTEST_S * FLICKER_RATIO ** np.arange(count)


def ar1(drive: np.ndarray, a: np.ndarray, start: np.ndarray) -> np.ndarray:
    """
    Return ``x[n] = a * x[n-1] + drive[n]`` for every column, from ``x[-1] = start``.

    numpy has no recursive filter; the closed form ``x[n] = a^n (start + sum
    a^-k drive[k])`` is a cumulative sum, taken over chunks short enough that
    ``a^-k`` stays within ``e^_AR1_SPAN`` of 1.
    """
    n = drive.shape[0]
    out = np.empty_like(drive)
    decay = -np.log(a)
    chunk = min(n, max(1, int(_AR1_SPAN / float(decay.max())))) if decay.max() > 0 else n
    grow = np.exp(np.arange(1, chunk + 1)[:, None] * decay)     # a^-k
    x = start.astype(float)
    for begin in range(0, n, chunk):
        size = min(chunk, n - begin)
        part = out[begin:begin + size]
        np.multiply(drive[begin:begin + size], grow[:size], out=part)
        np.cumsum(part, axis=0, out=part)
        part += x
        part /= grow[:size]
        x = part[-1]
    return out


class NoiseModel:
    """
    The noise of the six inertial axes, drawn in blocks that continue each other.

    ``seed`` makes a run reproducible. The state starts as a sensor that has
    been on for long: the Gauss-Markov processes at their stationary spread,
    the random walk at zero (a bias the sensor's own bias term already holds).
    """

    def __init__(self, config: NoiseConfig | None = None, seed: int | None = None) -> None:
        self.config = config if config is not None else NoiseConfig()
        self._rng = np.random.default_rng(seed)
        self._white, instability, self._walk_density = self.config.terms()
        self._tc = flicker_time_constants()
        # Variance of each Gauss-Markov process: their one-sided spectra sum to B^2 / (pi f),
        # whose Allan variance is 2 ln 2 B^2 / pi.
        self._gm_sigma = np.sqrt(np.log(FLICKER_RATIO) / np.pi) * instability
        self._gm = self._rng.standard_normal((self._tc.size, 6)) * self._gm_sigma
        self._walk = np.zeros(6)

    def draw(self, count: int, dt: float) -> np.ndarray:
        """Return the next ``count`` samples ``dt`` s apart: (count, 6), gyro xyz, accel xyz."""
        if count <= 0:
            return np.zeros((0, 6))
        if not dt > 0:
            raise ValueError(f'dt must be positive, got {dt!r}')
        if count > BLOCK:
            return np.concatenate([self.draw(min(BLOCK, count - begin), dt)
                                   for begin in range(0, count, BLOCK)])
        rng = self._rng
        noise = rng.standard_normal((count, 6)) * (self._white / math.sqrt(dt))
        steps = rng.standard_normal((count, 6)) * (self._walk_density * math.sqrt(dt))
        walk = self._walk + np.cumsum(steps, axis=0)
        self._walk = walk[-1]
        noise += walk
        # The Gauss-Markov processes, all (time constant, axis) pairs as columns.
        a = np.exp(-dt / self._tc)
        drive_sigma = self._gm_sigma[None, :] * np.sqrt(1.0 - a * a)[:, None]
        columns = self._tc.size * 6
        drive = rng.standard_normal((count, columns)) * drive_sigma.reshape(1, columns)
        gm = ar1(drive, np.repeat(a, 6), self._gm.reshape(columns))
        self._gm = gm[-1].reshape(self._tc.size, 6)
        noise += gm.reshape(count, self._tc.size, 6).sum(axis=1)
        return noise


class NoiseStream:
    """
    The model's samples one at a time, for a simulator that makes one record a cycle.

    Blocks of ``BUFFER`` samples are drawn at once (numpy per sample would cost
    more than the record); their spacing is the step between the two calls
    that asked last, the sensor's cycle.
    """

    BUFFER = 256

    def __init__(self, config: NoiseConfig, seed: int | None = None) -> None:
        self.model = NoiseModel(config, seed)
        self._block, self._next = np.zeros((0, 6)), 0
        #: When the last sample was asked for, and the step between the last two asks.
        self._last: float | None = None
        self._dt = 0.01

    def sample(self, t: float) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Return the (gyro, accel) errors of the sample at ``t`` (s), device units."""
        if self._last is not None and 1e-5 < t - self._last < 1.0:
            self._dt = t - self._last
        self._last = t
        if self._next >= self._block.shape[0]:
            self._block = self.model.draw(self.BUFFER, self._dt)
            self._next = 0
        row = self._block[self._next].tolist()
        self._next += 1
        return (row[0], row[1], row[2]), (row[3], row[4], row[5])
