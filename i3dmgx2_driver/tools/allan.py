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
of the reading off (N, B, K, how sure each is) this module is for.

The deviation is taken at octave-spaced tau (1, 2, 4... samples), for each
axis at once, over one stretch or several still stretches whose squared
differences are pooled (a tilt between them must not enter a difference).
The terms, IEEE Std 952's, come from one weighted least-squares fit of the
Allan variance ``N^2 / tau + (0.664 B)^2 + K^2 tau / 3``:

- N, the white noise density: the -1/2 slope line read at tau = 1 s;
- B, the bias instability: the flat floor, over sqrt(2 ln 2 / pi) (0.664);
- K, the rate random walk: the +1/2 slope line read at tau = 3 s.

Each tau weighs as one over the variance of its estimate, from its
equivalent degrees of freedom for the fitted mix of the three noises
(Howe, Allan and Barnes' approximations for white, flicker and random
walk FM), so that a term's 1-sigma is the fit's covariance, not the
fit's agreement with itself. A term is trusted when that 1-sigma is
within ``TRUSTED``; else it is marked, with an upper bound read off the
deviation itself and the length that would do.
"""

import math
from typing import NamedTuple

import numpy as np

#: The flat level of flicker noise in the Allan deviation, per unit bias instability.
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
#: Clusters a tau must have to be fitted (and to bound a term).
MIN_CLUSTERS = 4
#: tau (s) at which the white noise and the random walk lines are read.
N_TAU = 1.0
K_TAU = 3.0
#: Relative 1-sigma a term may have and be trusted.
TRUSTED = 0.4
#: K is trusted only from a fit that reaches this tau (s): under it, the slow part of a
#: flicker floor bends like a walk, and a K that came out high looks sure (at 2 minutes,
#: 7 of the 8 K under 40 % were further than 2-sigma off; the many-seed check).
K_MIN_TAU = 30.0
#: The fit's covariance ignores that the octave taus' estimates share samples
#: (correlated, positively, the more the longer the tau); these factors on N's, B's and
#: K's sigma make up for it, set by the many-seed check (benchmarks/noise_hour.py --seeds).
CORRELATION = np.array([1.6, 2.0, 2.0])
#: The three terms: their names, the tau each is read at, their shape in the Allan deviation.
TERMS = ('white', 'bias_instability', 'random_walk')


class Deviation(NamedTuple):
    """Overlapping Allan deviation of several axes at the same taus."""

    tau: np.ndarray        # (t,) s
    adev: np.ndarray       # (t, axes)
    clusters: np.ndarray   # (t,) samples / tau, rounded down, summed over the stretches
    samples: np.ndarray    # (t,) samples of the stretches behind each tau


class Short(NamedTuple):
    """Why a term is not trusted, and how long a recording would do (s; None: unknown)."""

    why: str
    record_s: float | None

    def __str__(self) -> str:
        """Return the advice as the table prints it."""
        return self.why + (f'; record at least {minutes(self.record_s)}' if self.record_s else '')


class Term(NamedTuple):
    """One noise term of one axis, how sure it is, and what stands behind it."""

    value: float
    #: Clusters behind it: the recording over the tau it is read at.
    clusters: int
    #: None when trusted; else why not, and how long a recording would do.
    short: Short | None = None
    #: The figure's relative 1-sigma after the fit (inf: not resolved).
    error: float = math.inf
    #: An upper bound (97.7 %), read off the deviation: what a file may hold when not trusted.
    bound: float = math.nan


class AxisNoise(NamedTuple):
    """The three terms of one axis."""

    white: Term              # N
    bias_instability: Term   # B
    bias_tau: float          # tau (s) of the deviation's minimum
    random_walk: Term        # K


def octave_taus(samples: int) -> np.ndarray:
    """Return 1, 2, 4... samples, up to a third of the recording (two clusters overlap)."""
    # bit_length: the count of the powers of two up to the third.
    return 2 ** np.arange(((samples - 1) // 3).bit_length() if samples >= 4 else 0, dtype=np.int64)


def overlapping_adev(y: np.ndarray, dt: float,
                     stretches: list[tuple[int, int]] | None = None) -> Deviation:
    """
    Return the overlapping Allan deviation of rate samples ``y`` (n, axes), ``dt`` apart.

    The running sum ``theta`` turns each tau into one second difference:
    ``sigma^2 = mean((theta[k+2m] - 2 theta[k+m] + theta[k])^2) / (2 tau^2)``,
    the mean pooled over the ``stretches`` (index ranges; all of ``y`` by
    default) long enough for that tau.
    """
    y = np.atleast_2d(np.asarray(y, dtype=float).T).T     # (n,) as one axis: (n, 1)
    stretches = stretches or [(0, y.shape[0])]
    ms = octave_taus(max((stop - start for start, stop in stretches), default=0))
    total, count = np.zeros((ms.size, y.shape[1])), np.zeros(ms.size)
    clusters, samples = np.zeros(ms.size, dtype=np.int64), np.zeros(ms.size, dtype=np.int64)
    for start, stop in stretches:
        part = y[start:stop]
        theta = np.zeros((part.shape[0] + 1, y.shape[1]))
        np.cumsum((part - part.mean(axis=0)) * dt, axis=0, out=theta[1:])
        for i, m in enumerate(ms[ms <= (part.shape[0] - 1) // 3]):
            d = theta[2 * m:] - 2.0 * theta[m:-m] + theta[:-2 * m]
            total[i] += np.einsum('ij,ij->j', d, d)
            count[i] += d.shape[0]
            clusters[i] += part.shape[0] // m
            samples[i] += part.shape[0]
    adev = np.sqrt(total / np.maximum(count, 1)[:, None]) / (math.sqrt(2.0) * ms * dt)[:, None]
    return Deviation(ms * dt, adev, clusters, samples)


def _edf(m: np.ndarray, n: np.ndarray) -> np.ndarray:
    """
    Return the degrees of freedom of an overlapping Allan variance: white, flicker, walk FM.

    Howe, Allan and Barnes (1981), as Stable32 and allantools' ``edf_simple``:
    ``n`` samples (n + 1 phase points), ``m`` of them a tau. Rows: the three noises.
    """
    p = n + 1.0
    white = (3.0 * (p - 1) / (2 * m) - 2.0 * (p - 2) / p) * 4 * m ** 2 / (4 * m ** 2 + 5)
    flicker = np.where(m == 1, 2.0 * (p - 2) / (2.3 * p - 4.9),
                       5.0 * p ** 2 / (4 * m * (p + 3 * m)))
    walk = (p - 2) / m * ((p - 1) ** 2 - 3 * m * (p - 1) + 4 * m ** 2) / (p - 3) ** 2
    return np.maximum(np.stack([white, flicker, walk]), 1.0)


def _nonnegative_fit(basis: np.ndarray, avar: np.ndarray, var: np.ndarray) -> np.ndarray:
    """Return the coefficients >= 0 of ``basis @ coef ~ avar`` weighted by 1 / ``var``."""
    a_matrix, target = basis / np.sqrt(var)[:, None], avar / np.sqrt(var)
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


def _fitted(dev: Deviation, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the taus fitted (clusters enough), their Allan variance and degrees of freedom."""
    usable = dev.clusters >= MIN_CLUSTERS
    m, n = np.round(dev.tau[usable] / dev.tau[0]), dev.samples[usable].astype(float)
    return dev.tau[usable], dev.adev[usable, axis] ** 2, _edf(m, n)


def fit(dev: Deviation, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """
    Return (a, f, c) of ``avar ~ a / tau + f + c tau``, all >= 0, and their 1-sigma.

    Weighted by the variance each tau's estimate has under the fitted mix
    (three rounds: the weights follow the fit), the sigma from the fit's
    covariance at the last weights.
    """
    tau, avar, edf = _fitted(dev, axis)
    basis = np.stack([1.0 / tau, np.ones_like(tau), tau], axis=1)
    var = avar ** 2 * 2.0 / edf[0]
    for _ in range(3):
        coef = _nonnegative_fit(basis, avar, var)
        parts = basis * coef
        model = np.maximum(parts.sum(axis=1), 1e-300)
        var = 2.0 * model ** 2 * np.sum(parts / model[:, None] / edf.T, axis=1)
    weighted = basis / np.sqrt(var)[:, None]
    cov = np.linalg.pinv(weighted.T @ weighted)
    return coef, np.sqrt(np.maximum(np.diag(cov), 0.0)) * CORRELATION


def upper_bound(dev: Deviation, axis: int, term: str) -> float:
    """
    Return a 97.7 % upper bound of ``term`` from the deviation alone: each term lies below it.

    At each tau the term's own line cannot exceed the deviation over the
    2-sigma low quantile of a chi-square of the term's degrees of freedom
    (Wilson and Hilferty's cube); the least of those over the fitted taus.
    """
    tau, avar, edf = _fitted(dev, axis)
    j = TERMS.index(term)
    low = np.maximum(1.0 - 2.0 / (9.0 * edf[j]) - 2.0 * np.sqrt(2.0 / (9.0 * edf[j])), 0.05) ** 3
    shape = (1.0 / tau, np.full(tau.shape, FLICKER_FLOOR ** 2), tau / K_TAU)[j]
    room = np.sqrt(avar / low / shape)
    return float(room.min()) if room.size else math.nan


def minutes(seconds: float) -> str:
    """Return a length as the advice says it."""
    if seconds >= 7200:
        return f'{seconds / 3600:.0f} h'
    return f'{seconds / 60:.0f} min' if seconds >= 120 else f'{seconds:.0f} s'


def read_terms(dev: Deviation, duration: float) -> list[AxisNoise]:
    """Read N, B (and its tau) and K off each axis of ``dev``, for a still time ``duration`` s."""
    usable = dev.clusters >= MIN_CLUSTERS
    out = []
    for axis in range(dev.adev.shape[1]):
        sigma = dev.adev[usable, axis]
        if usable.sum() < 3 or not np.all(sigma > 0):
            nothing = Term(math.nan, 0, Short('dead: its readings never change', None)
                           if sigma.size and not np.any(sigma > 0) else
                           Short('too short to fit', 60.0))
            out.append(AxisNoise(nothing, nothing, math.nan, nothing))
            continue
        coef, error = fit(dev, axis)
        tau_b = float(dev.tau[usable][int(np.argmin(sigma))])
        terms = []
        # Clusters behind each: at N's tau, at B's, at the longest the walk is fitted to.
        behind = (N_TAU, tau_b, float(dev.tau[usable][-1]))
        scales = (1.0, 1.0 / FLICKER_FLOOR ** 2, 3.0)   # from each coefficient to its term^2
        for j, (name, tau, scale) in enumerate(zip(TERMS, behind, scales, strict=True)):
            # sqrt of a coefficient: half its relative error.
            rel = error[j] / (2.0 * coef[j]) if coef[j] > 0 else math.inf
            short = None
            if not rel <= TRUSTED:
                seen = 'not resolved' if coef[j] <= 0 else f'±{rel:.0%} after the fit'
                # The sigma falls about as one over the root of the length; at most 4 times.
                short = Short(f'too short: {seen}', duration * min((rel / TRUSTED) ** 2, 16.0))
            if name == 'random_walk' and behind[2] < K_MIN_TAU:
                short = Short(short.why if short else f'too short: no tau of {K_MIN_TAU:.0f} s '
                              'fitted', max(short.record_s if short else 0.0,
                                            2 * MIN_CLUSTERS * K_MIN_TAU))
            terms.append(Term(math.sqrt(coef[j] * scale), int(duration // tau), short, rel,
                              upper_bound(dev, axis, name)))
        out.append(AxisNoise(terms[0], terms[1], tau_b, terms[2]))
    return out


def uncertainty(clusters: int) -> float:
    """Return the relative 1-sigma error of an Allan deviation over ``clusters`` clusters."""
    return 1.0 / math.sqrt(2.0 * (clusters - 1)) if clusters > 1 else math.inf


#: A step between neighbouring window means beyond this many sigma of those steps (their
#: robust spread: an hour's bias walk is in it) says the sensor moved.
STEP_SIGMA = 8.0
#: A window whose sample-to-sample steps have this many sigma (of a chi-square of its
#: count) more variance than the recording's median window: a knock the means average out.
KNOCK_SIGMA = 8.0
#: A still stretch shorter than this (s) is left out; none as long: nothing to analyse.
MIN_STILL_S = 10.0


class Still(NamedTuple):
    """Where the sensor moved, and the still stretches left to analyse."""

    #: (start s, end s, what) of each stretch that moved.
    moved: list[tuple[float, float, str]]
    #: Sample index ranges (start, stop) of the still stretches of MIN_STILL_S or more.
    stretches: list[tuple[int, int]]


def movement(time: np.ndarray, values: np.ndarray, labels: list[str], rate: float) -> Still:
    """
    Find the windows where the sensor moved, from the recording's own noise.

    Windows of a second (32 samples at least): a step between neighbouring
    means of ``STEP_SIGMA`` times the robust spread of those steps (a tilt,
    a turn), or a window whose sample-to-sample variance stands out of the
    median window's (a knock, which averages out of the means). A flagged
    window and its neighbours are left out; the rest are the still stretches.
    """
    window = max(1.0, 32.0 / rate)
    time = time - time[0]
    bins = (time // window).astype(np.int64)
    count = np.bincount(bins).astype(float)
    seen = count > 0
    means = np.stack([np.bincount(bins, weights=v) for v in values.T], axis=1)[seen]
    means /= count[seen, None]
    if means.shape[0] < 3:           # no neighbours to compare: nothing to find
        return Still([], [(0, time.size)])
    steps = np.abs(np.diff(means, axis=0))
    spread = 1.4826 * np.median(steps, axis=0)
    jump = np.where(spread > 0, steps / np.where(spread > 0, spread, 1.0), 0.0)
    square = np.stack([np.bincount(bins[1:], weights=d * d, minlength=count.size)
                       for d in np.diff(values, axis=0).T], axis=1)[seen]
    pairs = np.maximum(np.bincount(bins[1:], minlength=count.size)[seen], 1).astype(float)
    var = square / pairs[:, None]
    typical = np.median(var, axis=0)
    knock = np.where(typical > 0, (var / np.where(typical > 0, typical, 1.0) - 1.0)
                     / np.sqrt(2.0 / pairs)[:, None], 0.0)
    # A window of less than half the usual samples (the first one a live listener heard,
    # one cut by a gap) is not judged: its mean and variance are too loose for the tests.
    thin = count[seen] < 0.5 * np.median(count[seen])
    jump[thin[:-1] | thin[1:]] = 0.0
    knock[thin] = 0.0
    # A window's step score: the larger of the steps to its neighbours.
    near = np.maximum(np.pad(jump, ((1, 0), (0, 0))), np.pad(jump, ((0, 1), (0, 0))))
    scores = np.concatenate([near, knock], axis=1)
    flagged = (near.max(axis=1) > STEP_SIGMA) | (knock.max(axis=1) > KNOCK_SIGMA)
    spread_out = flagged | np.roll(flagged, 1) | np.roll(flagged, -1)
    start = np.nonzero(seen)[0] * window
    moved, stretches = [], []
    for index in np.nonzero(flagged)[0]:
        j = int(np.argmax(scores[index]))
        what = (scores[index, j], f'{labels[j % len(labels)]} '
                + ('steps' if j < len(labels) else 'shakes (a knock)'))
        begin = float(start[index])
        if moved and begin - moved[-1][1] <= window:
            moved[-1] = (moved[-1][0], begin + window, max(moved[-1][2], what))
        else:
            moved.append((begin, begin + window, what))
    moved = [(begin, end, what) for begin, end, (_, what) in moved]
    still = np.concatenate([[False], ~spread_out, [False]])
    edges = np.nonzero(np.diff(still.astype(int)))[0].reshape(-1, 2)
    for first, last in edges:
        lo, hi = np.searchsorted(time, [start[first], start[last - 1] + window])
        if time[hi - 1] - time[lo] >= MIN_STILL_S:
            stretches.append((int(lo), int(hi)))
    return Still(moved, stretches)


def find_gaps(time: np.ndarray) -> tuple[int, float, int]:
    """
    Return the records missing between samples, the longest step (s) and the gaps.

    A gap is a step over 1.5 periods (the median step).
    """
    if time.size < 3:
        return 0, 0.0, 0
    steps = np.diff(time)
    period = float(np.median(steps))
    late = steps > 1.5 * period
    missing = int(np.sum(np.round(steps[late] / period) - 1)) if period > 0 else 0
    return missing, float(steps.max()) if late.any() else 0.0, int(late.sum())
