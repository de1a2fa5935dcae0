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
Device-clock timestamps: the host time at which each sample was taken.

The host's read time of a packet is the sample time plus a delay that is at
least the time the packet takes on the wire and at most that plus whatever
the USB adapter, the kernel and the scheduler add (milliseconds, random).
The device timer, by contrast, ticks evenly (±0.01 %) at the moment of each
sample. So the stamp is the device time mapped onto the host clock by a line
fitted to the *lower envelope* of (host read time - device time): the
minimum delay over each one-second window is nearly constant, the mean is
not. The line is fitted to those minima in three steps, each for a reason:

1. The edge of their lower convex hull that spans their mean time (the
   linear-programming estimate of Moon, Skelly and Towsley, 1999): the line
   below every minimum that comes closest to them on average. It ignores
   windows a busy host delayed, however many, which a least-squares line
   would not.
2. Its slope, though, rests on two points only: one odd window (a packet
   read unusually early) or a floor a few tens of microseconds lower for a
   while tilts it, and the stamp is that line extrapolated a minute past
   the points' mean time. So the slope is taken again by least squares
   through the minima near the hull line (within ``BAND`` times their
   median distance from it): every ordinary window counts, busy ones still
   do not.
3. The line's height is a low quantile (``QUANTILE``) of the minima's
   distances from that slope, not the lowest of them: one odd window moves
   a quantile by one rank, where it would move a hull by all its depth.

On recorded runs of the simulator with radio-like jitter this cut the
settled noise of the stamps most where the hull alone was worst (from 60
and 48 us to 7 and 17 us; docs/timestamps.md). The slope is the device
clock's drift.

The host clock given here must be one that nothing steps (the monotonic
clock): :class:`~.sample_clock.SampleClock` feeds it and moves its stamps to
the system clock. Which device time a raw timer value stands for, and when
the fit must start afresh, is decided there too (docs/clock.md).

Usable from the very first message (the first stamp is the read time less
the wire time), it only gets better, it never runs backwards, and it never
stamps a sample later than it was read.
"""

from collections import deque
from collections.abc import Sequence
import statistics

from ..codec.records import TICKS_PER_SECOND

#: Envelope points (one-second windows) the line is fitted to: two minutes. A longer
#: baseline pins the drift better (the stamp is the line extrapolated to now, half the
#: history past the points' mean time); the crystal's drift must stay nearly constant over
#: it, which it does over minutes (measured on recorded pseudo-terminal runs and made-up
#: streams: 60 windows gave 24-52 us of settled noise where 120 gave 13-23 us; with the
#: drift changing 1 ppm a minute, both stay near 10 us).
HISTORY = 120

#: Span (s of device time) the envelope points must cover before the line's slope is
#: trusted. Over a shorter baseline the slope is the envelope's noise divided by the span
#: (+-100 us over 1-2 s on a loaded host: hundreds of ppm, extrapolated to a stamp 1 ms off
#: at 2.8 s in one measured run); until then the drift is taken as 0 (a crystal against an
#: NTP-disciplined clock: tens of ppm, 0.2 ms over these seconds at most).
MIN_SPAN_S = 4.0

#: Envelope points further above the hull line than this many times their median distance
#: from it (plus BAND_FLOOR_S) are left out of the slope's least squares: windows a busy
#: host delayed. Ordinary windows scatter over one to two medians.
BAND = 3.0
BAND_FLOOR_S = 20e-6

#: The line's height: this quantile of the envelope points' distances from the fitted
#: slope (the 6th lowest of 120). Low, so that few packets come in under the line (each
#: such packet is stamped at its read time and lowers the line until the next fit).
QUANTILE = 0.05

#: Least step between two stamps: 1 us. A float64 near today's epoch (1.8e9 s) cannot
#: hold a step below 2.4e-7 s, and a message stamp counts whole nanoseconds.
MIN_STEP = 1e-6


class DeviceClock:
    """
    Map unwrapped device ticks to host seconds (offset and drift estimate).

    ``window`` is the span of device time (s) that each envelope point
    covers, ``history`` how many such points the line is fitted to.
    """

    def __init__(self, window: float = 1.0, history: int = HISTORY) -> None:
        self.window = window
        self.history = history
        self.anchors = 0
        self._points: deque[tuple[float, float]] = deque(maxlen=history)
        self.reset()

    def reset(self) -> None:
        """Forget the estimate: the device's timer restarted, or it is another device."""
        self._points.clear()
        self._bucket: int | None = None
        self._bucket_min: tuple[float, float] = (0.0, 0.0)
        self._origin: float | None = None
        self._offset = 0.0
        self._drift = 0.0
        #: Whether the line has been fitted (the points span MIN_SPAN_S).
        self._fitted = False
        self._last_stamp = float('-inf')
        self.samples = 0
        self.anchors += 1

    @property
    def offset(self) -> float:
        """Host time minus device time at the device-time origin (s)."""
        return self._offset

    @property
    def drift_ppm(self) -> float:
        """How much faster the host clock runs than the device's, in ppm."""
        return self._drift * 1e6

    @property
    def started(self) -> bool:
        """Whether a sample has been stamped since the last reset (there is a line)."""
        return self._origin is not None

    def residual(self, ticks: int, host_time: float, wire_time: float = 0.0) -> float:
        """
        Return how far (s) a sample would sit above the line, without adding it.

        Zero or a little above for a sample of the device the line was fitted
        to (its delay is at least the envelope's); far off either way for a
        timer that restarted. Only meaningful once :attr:`started`.
        """
        device = ticks / TICKS_PER_SECOND
        t = device - (self._origin if self._origin is not None else device)
        return (host_time - wire_time - device) - (self._offset + self._drift * t)

    def stamp(self, ticks: int, host_time: float, wire_time: float = 0.0) -> float:
        """
        Return the host time (s) at which the sample with ``ticks`` was taken.

        ``host_time`` is when its last byte was read, ``wire_time`` how long
        the packet takes on the line (it cannot have been sampled later than
        ``host_time - wire_time``).
        """
        device = ticks / TICKS_PER_SECOND
        latest = host_time - wire_time
        if self._origin is None:
            self._origin = device
        t = device - self._origin
        self._add(t, latest - device)
        stamp = device + self._offset + self._drift * t
        if stamp > latest:
            # The line says this sample was taken after it was read: the
            # envelope is too high (first samples, or the delay just shrank).
            self._offset -= stamp - latest
            stamp = latest
        if stamp <= self._last_stamp:
            stamp = self._last_stamp + MIN_STEP
        self._last_stamp = stamp
        self.samples += 1
        return stamp

    def _add(self, t: float, excess: float) -> None:
        bucket = int(t // self.window)
        if bucket != self._bucket:
            if self._bucket is not None:
                self._points.append(self._bucket_min)
                self._fit()
            self._bucket = bucket
            self._bucket_min = (t, excess)
        elif excess < self._bucket_min[1]:
            self._bucket_min = (t, excess)
        # Until there is a line, the running minimum is the best offset.
        if not self._fitted and (
                self.samples == 0 or excess < self._offset + self._drift * t):
            self._offset = excess - self._drift * t

    def _fit(self) -> None:
        """Fit the line to the envelope points (module docstring: hull, slope, height)."""
        points = self._points
        if len(points) < 2 or points[-1][0] - points[0][0] < MIN_SPAN_S:
            return
        self._fitted = True
        drift, offset = _hull_line(points)
        drift, offset = _floor_slope(points, drift, offset)
        distances = sorted(e - (offset + drift * t) for t, e in points)
        self._drift = drift
        self._offset = offset + distances[int(QUANTILE * (len(distances) - 1))]


def _hull_line(points: Sequence[tuple[float, float]]) -> tuple[float, float]:
    """Return (slope, intercept) of the lower-hull edge of ``points`` at their mean time."""
    # The points come in time order (one per window), so one pass builds the hull.
    hull: list[tuple[float, float]] = []
    for point in points:
        while len(hull) >= 2 and _cross(hull[-2], hull[-1], point) <= 0.0:
            hull.pop()
        hull.append(point)
    mean_t = sum(p[0] for p in points) / len(points)
    edge = next(i for i in range(1, len(hull)) if hull[i][0] >= mean_t)
    (t0, e0), (t1, e1) = hull[edge - 1], hull[edge]
    slope = (e1 - e0) / (t1 - t0)
    return slope, e0 - slope * t0


def _floor_slope(points: Sequence[tuple[float, float]], slope: float,
                 intercept: float) -> tuple[float, float]:
    """
    Return the least-squares line through the points near the given one (slope, intercept).

    Near: within BAND times the points' median distance above it. The line
    given is returned when those points span less than MIN_SPAN_S.
    """
    distances = [e - (intercept + slope * t) for t, e in points]
    limit = BAND * statistics.median(distances) + BAND_FLOOR_S
    near = [p for p, d in zip(points, distances, strict=True) if d <= limit]
    if len(near) < 3 or near[-1][0] - near[0][0] < MIN_SPAN_S:
        return slope, intercept
    fit = statistics.linear_regression([t for t, _ in near], [e for _, e in near])
    return fit.slope, fit.intercept


def _cross(a: tuple[float, float], b: tuple[float, float], c: tuple[float, float]) -> float:
    """Positive when a -> b -> c turns left (b lies below the chord a-c)."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
