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
The Allan deviation of a sensor at rest, and the three noise terms read off it.

numpy, not allantools: the overlapping Allan deviation of evenly spaced
rate samples is the second difference of their running sum, one
vectorised line per tau, and numpy is already a dependency of the tools.
allantools computes the same estimator (its ``oadev``) but one axis per
call, adds a dependency the robot's image does not need, and offers none
of the reading off (N, B, K, their support) this module is for.

The deviation is taken at octave-spaced tau (1, 2, 4... samples) up to half
the recording, for each axis at once. The terms, IEEE Std 952's:

- N, the white noise density: the -1/2 slope line read at tau = 1 s;
- K, the rate random walk: the +1/2 slope line read at tau = 3 s;
- B, the bias instability: the flat minimum of the deviation and its tau,
  less what the two slopes still add there, over sqrt(2 ln 2 / pi) (0.664).

The two slope lines come from one least-squares fit of the Allan variance
``N^2 / tau + F + K^2 tau / 3``, each tau weighted by the clusters behind it,
so that neither line is read off a stretch the other still bends. Each
figure says how many clusters (the recording over its tau) stand behind it,
and the figures the recording is too short for are marked, with how long it
would have to be.
"""

import math
from typing import NamedTuple

import numpy as np

#: The flat level of flicker noise in the Allan deviation, per unit bias instability.
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
#: Clusters a tau must have to be fitted, and for its minimum to count as B's.
MIN_CLUSTERS = 4
#: Clusters behind B's tau for B to be trusted: the minimum must not be the noise
#: of a few clusters at the end of the curve.
B_CLUSTERS = 8
#: tau (s) at which the white noise and the random walk lines are read.
N_TAU = 1.0
K_TAU = 3.0


class Deviation(NamedTuple):
    """Overlapping Allan deviation of several axes at the same taus."""

    tau: np.ndarray        # (t,) s
    adev: np.ndarray       # (t, axes)
    clusters: np.ndarray   # (t,) recording / tau, rounded down


class Term(NamedTuple):
    """One noise term of one axis, and what stands behind it."""

    value: float
    #: Clusters behind it: the recording over the tau it is read at.
    clusters: int
    #: None when trusted; else why not, and how long a recording would do.
    short: str | None = None


class AxisNoise(NamedTuple):
    """The three terms of one axis."""

    white: Term              # N
    bias_instability: Term   # B
    bias_tau: float          # tau (s) of B's flat minimum
    random_walk: Term        # K


def octave_taus(samples: int) -> np.ndarray:
    """Return 1, 2, 4... samples, up to a third of the recording (two clusters overlap)."""
    m = [1]
    while m[-1] * 2 <= (samples - 1) // 3:
        m.append(m[-1] * 2)
    return np.array(m if samples >= 4 else [], dtype=np.int64)


def overlapping_adev(y: np.ndarray, dt: float) -> Deviation:
    """
    Return the overlapping Allan deviation of rate samples ``y`` (n, axes), ``dt`` apart.

    The running sum ``theta`` turns each tau into one second difference:
    ``sigma^2 = mean((theta[k+2m] - 2 theta[k+m] + theta[k])^2) / (2 tau^2)``.
    """
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    n = y.shape[0]
    theta = np.zeros((n + 1, y.shape[1]))
    np.cumsum((y - y.mean(axis=0)) * dt, axis=0, out=theta[1:])
    ms = octave_taus(n)
    adev = np.empty((ms.size, y.shape[1]))
    for i, m in enumerate(ms):
        d = theta[2 * m:] - 2.0 * theta[m:-m] + theta[:-2 * m]
        adev[i] = np.sqrt(np.einsum('ij,ij->j', d, d) / d.shape[0]) / (math.sqrt(2.0) * m * dt)
    return Deviation(ms * dt, adev, n // ms if ms.size else ms)


def _fit(tau: np.ndarray, avar: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """
    Return (a, f, c) of ``avar ~ a / tau + f + c tau``, all >= 0, least squares on relative error.

    Each tau weighs as the square root of its clusters (the relative error of
    an Allan variance falls as one over it). Non-negative by trying each
    subset of the three terms: three unknowns, seven subsets.
    """
    basis = np.stack([1.0 / tau, np.ones_like(tau), tau], axis=1) / avar[:, None]
    weight = np.sqrt(clusters.astype(float))
    a_matrix = basis * weight[:, None]
    target = weight
    best, best_cost = np.zeros(3), math.inf
    for mask in range(1, 8):
        cols = [j for j in range(3) if mask >> j & 1]
        coef, *_ = np.linalg.lstsq(a_matrix[:, cols], target, rcond=None)
        if np.any(coef < 0):
            continue
        full = np.zeros(3)
        full[cols] = coef
        cost = float(np.sum((a_matrix @ full - target) ** 2))
        if cost < best_cost:
            best, best_cost = full, cost
    return best


def _minutes(seconds: float) -> str:
    return f'{seconds / 60:.0f} min' if seconds >= 120 else f'{seconds:.0f} s'


def read_terms(dev: Deviation, duration: float) -> list[AxisNoise]:
    """Read N, B (and its tau) and K off each axis of ``dev``, for a recording ``duration`` s."""
    usable = dev.clusters >= MIN_CLUSTERS
    tau, clusters = dev.tau[usable], dev.clusters[usable]
    out = []
    for axis in range(dev.adev.shape[1]):
        sigma = dev.adev[usable, axis]
        if tau.size < 3 or not np.all(sigma > 0):
            nothing = Term(math.nan, 0, f'too short: record at least {_minutes(60)}')
            out.append(AxisNoise(nothing, nothing, math.nan, nothing))
            continue
        a, f, c = _fit(tau, sigma ** 2, clusters)
        white = Term(math.sqrt(a / N_TAU), int(duration // N_TAU),
                     None if a > 0 and duration >= 10 * N_TAU
                     else f'too short: record at least {_minutes(10 * N_TAU)}')
        # B: the minimum among the taus with enough clusters, less the two slopes there.
        trusted = clusters >= B_CLUSTERS
        low = int(np.argmin(np.where(trusted, sigma, np.inf)))
        tau_b = float(tau[low])
        floor = sigma[low] ** 2 - a / tau_b - c * tau_b
        floor = floor if floor > 0 else f
        last = int(np.nonzero(trusted)[0][-1])
        short_b = None
        if low == last:
            short_b = (f'too short: the deviation still falls at tau {tau_b:.3g} s; record '
                       f'at least {_minutes(4 * B_CLUSTERS * tau_b)}')
        bias = Term(math.sqrt(floor) / FLICKER_FLOOR, int(duration // tau_b), short_b)
        # K: seen when the random walk outgrows the flat floor within the fitted taus.
        tau_k = float(tau[-1])
        short_k = None
        if c <= 0:
            short_k = (f'too short: no +1/2 slope by tau {tau_k:.3g} s; record at least '
                       f'{_minutes(4 * duration)}')
        elif c * tau_k < max(f, floor):
            cross = max(f, floor) / c
            short_k = (f'too short: the random walk outgrows the floor at tau {cross:.3g} s; '
                       f'record at least {_minutes(2 * MIN_CLUSTERS * cross)}')
        walk = Term(math.sqrt(c * K_TAU), int(clusters[-1]), short_k)
        out.append(AxisNoise(white, bias, tau_b, walk))
    return out


def uncertainty(clusters: int) -> float:
    """Return the relative 1-sigma error of an Allan deviation over ``clusters`` clusters."""
    return 1.0 / math.sqrt(2.0 * (clusters - 1)) if clusters > 1 else math.inf


class Still(NamedTuple):
    """Whether the sensor stayed still, and where it did not."""

    moved: bool
    #: (start s, end s, largest step) of each stretch that moved.
    stretches: list[tuple[float, float, float]]


def movement(time: np.ndarray, values: np.ndarray, threshold: float,
             window: float = 1.0) -> Still:
    """
    Find the windows whose mean leaves the recording's median by more than ``threshold``.

    A sensor at rest keeps each one-second mean within its noise of the
    others: a bias walking over an hour moves it by a fraction of the
    thresholds the tool uses (gyro 0.01 rad/s, accelerometer 0.1 m/s^2);
    a hand, a step or a door moves it by more.
    """
    if time.size < 2:
        return Still(False, [])
    bins = ((time - time[0]) // window).astype(np.int64)
    counts = np.bincount(bins)
    keep = counts > 0
    stretches = []
    means = np.stack([np.bincount(bins, weights=values[:, j])[keep] / counts[keep]
                      for j in range(values.shape[1])], axis=1)
    step = np.abs(means - np.median(means, axis=0)).max(axis=1)
    starts = np.nonzero(keep)[0] * window
    for index in np.nonzero(step > threshold)[0]:
        begin = float(starts[index])
        if stretches and begin - stretches[-1][1] <= window:
            first, _, worst = stretches[-1]
            stretches[-1] = (first, begin + window, max(worst, float(step[index])))
        else:
            stretches.append((begin, begin + window, float(step[index])))
    return Still(bool(stretches), stretches)


class Gaps(NamedTuple):
    """Records missing from a stream, found in its sample times."""

    missing: int
    longest: float
    count: int


def find_gaps(time: np.ndarray) -> Gaps:
    """Count the records missing between samples: steps over 1.5 periods (the median step)."""
    if time.size < 3:
        return Gaps(0, 0.0, 0)
    steps = np.diff(time)
    period = float(np.median(steps))
    late = steps > 1.5 * period
    missing = int(np.sum(np.round(steps[late] / period) - 1)) if period > 0 else 0
    return Gaps(missing, float(steps.max()) if late.any() else 0.0, int(late.sum()))
