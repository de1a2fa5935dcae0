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
fitted to the *lower envelope* of (host read time - device time): the least
delay over each one-second window is nearly constant, the mean is not.

The line is a weighted least-squares line through every window's least
delay, and every weight changes smoothly, so that the line never jumps:

- **Odd windows weigh little.** A window a busy host delayed lies far above
  the others; one whose packet was read unusually early, below them. A
  window's weight falls with its distance from the line fitted a window
  before (beyond ``BAND`` times the windows' scatter, as the fourth power
  of the ratio): however many there are, they barely move the line, and
  there is no threshold at which one flips in or out.
- **The line leans on the low windows.** A window's least delay has a sharp
  floor and a loose top, so a window above the line weighs
  1 / (1 + (distance / scatter) ** 2): the line follows the floor rather
  than the mean (on six recorded runs, 15.0 us of settled noise on average
  where the plain weights gave 16.7).
- **Old windows fade out.** The history holds ``HISTORY`` windows; the
  oldest ``TAPER`` of them weigh less the older they are, down to nothing
  as they leave. A window that leaves moves the line by nothing.
- **The drift is learnt early.** The slope is fitted from ``MIN_SPAN_S`` of
  windows on, held towards 0 by a prior (``SLOPE_PRIOR_S2``: a window's
  scatter of about 100 us against a crystal's drift of up to 100 ppm) that
  matters over the first seconds only.
- **The height.** The line is put ``DEPTH`` times the windows' weighted
  scatter below their weighted mean: under nearly every packet, and moving
  only as smoothly as the mean and the scatter do. A packet that comes in
  under it anyway is stamped at its read time; only two in a row (the
  delay shrank) lower the line at once, so that one packet read unusually
  early does not drag the stamps after it down.

The line it replaced rested on the two windows of the lower convex hull that
spanned the points' mean time (Moon, Skelly and Towsley, 1999), refitted
through the windows near it and set at a low quantile: each time a window
entered or left the hull, or crossed the band or the quantile, the line
jumped, and its slope was taken as 0 for the first 4 s (docs/timestamps.md
has the figures before and after). The slope is the device clock's drift.

The host clock given here must be one that nothing steps (the monotonic
clock): :class:`~.sample_clock.SampleClock` feeds it and moves its stamps to
the system clock. Which device time a raw timer value stands for, and when
the fit must start afresh, is decided there too (docs/clock.md).

Usable from the very first message (the first stamp is the read time less
the wire time), it only gets better, it never runs backwards, and it never
stamps a sample later than it was read.
"""

from collections import deque
import math
import statistics

from ..codec.records import TICKS_PER_SECOND

#: Envelope points (one-second windows) the line is fitted to: two minutes. A longer
#: baseline pins the drift better (the stamp is the line extrapolated to now, about half
#: the history past the points' mean time); the crystal's drift must stay nearly constant
#: over it, which it does over minutes.
HISTORY = 120

#: The oldest this many windows of a full history fade out: a window's weight is 1 until
#: it is HISTORY - TAPER windows old, then falls linearly to 0 at HISTORY, when it leaves.
TAPER = 30

#: Span (s of device time) and number of envelope points before the line is fitted at
#: all; until then the least delay seen so far is the offset and the drift is 0.
MIN_SPAN_S = 2.0
MIN_POINTS = 3

#: The slope's prior, as (window scatter / drift scale) squared, in s^2: 100 us of
#: scatter against 100 ppm. Added to the weighted sum of squared times (times the windows'
#: mean weight), it holds a slope from two or three noisy windows near 0 (over 1-2 s,
#: +-100 us of scatter is hundreds of ppm: extrapolated, a stamp 1 ms off in one measured
#: run of an early fit); after ten seconds it shrinks the slope by about 1 %, after a
#: minute by nothing one could measure.
SLOPE_PRIOR_S2 = 1.0

#: Envelope points further from the line than BAND times the windows' weighted scatter
#: (plus BAND_FLOOR_S) weigh (limit / distance) ** 4: above, windows a busy host delayed;
#: below, a window whose one packet was read unusually early (it widened the scatter, and
#: so lowered the line, by 110 us on a made-up stream when it counted in full). The floor
#: keeps a line that is still learning its drift from shutting out the windows that
#: would correct it.
BAND = 3.0
BAND_FLOOR_S = 50e-6

#: The line's height: this many weighted standard deviations of the envelope points below
#: their weighted mean. Lower puts fewer packets under the line, but the scatter's own
#: noise moves the line DEPTH times as much (2 gave 19.3 us of settled noise on recorded
#: runs where 1 gave 16.7).
DEPTH = 1.0

#: How near the samples come to the line: the least residual over each block of this much
#: device time, the last NEAR_BLOCKS blocks, their median. What a gap's probation expects
#: of the records after it: near the line within a block's time, as they came before. A
#: host that reads on the scheduler's tick (its cores busy) reads every sample up to a tick
#: late, and in 0.3 s none may come within 1 ms of the line, before a gap or after it.
NEAR_S = 0.3
NEAR_BLOCKS = 9

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
        self.window, self.history = window, history
        self._points: deque[tuple[float, float]] = deque(maxlen=history)
        self.reset()

    def reset(self) -> None:
        """Forget the estimate: the device's timer restarted, or it is another device."""
        self._points.clear()
        self._bucket: int | None = None
        self._bucket_min: tuple[float, float] = (0.0, 0.0)
        self._origin: float | None = None
        #: The line's offset and drift; the windows' scatter about the last fit's weighted
        #: mean line (offset at t = 0, ``_centre``): what the next fit weighs them by.
        self._offset = self._drift = self._scatter = 0.0
        self._centre: float | None = None  # None: no fit yet
        self._last_stamp = float('-inf')
        #: Whether the last sample came in under the line.
        self._under = False
        #: The least residuals of the last blocks of NEAR_S, and the block being filled.
        self._near_blocks: deque[float] = deque(maxlen=NEAR_BLOCKS)
        self._near_block: int | None = None
        self._near_least = 0.0
        self.samples = 0

    @property
    def drift_ppm(self) -> float:
        """How much faster the host clock runs than the device's, in ppm."""
        return self._drift * 1e6

    @property
    def near(self) -> float:
        """
        How near the line (s) the samples came over a block of ``NEAR_S``, as a rule.

        The median of the last blocks' least residuals (0 before the first
        fit has closed a block): about 0.1 ms for a host that reads each
        sample as it comes, up to a scheduler's tick for one whose cores are
        busy.
        """
        return statistics.median(self._near_blocks) if self._near_blocks else 0.0

    def residual(self, ticks: int, host_time: float, wire_time: float = 0.0) -> float:
        """
        Return how far (s) a sample would sit above the line, without adding it.

        Zero or a little above for a sample of the device the line was fitted
        to (its delay is at least the envelope's); far off either way for a
        timer that restarted. Only meaningful once a sample was stamped since the reset.
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
        excess = latest - device
        # The envelope: the least excess of each window; a window closed fits the line.
        bucket = int(t // self.window)
        if bucket != self._bucket:
            if self._bucket is not None:
                self._points.append(self._bucket_min)
                self._fit()
            self._bucket = bucket
            self._bucket_min = (t, excess)
        elif excess < self._bucket_min[1]:
            self._bucket_min = (t, excess)
        if self._centre is None:
            # Until there is a line, the running minimum is the best offset.
            if self.samples == 0 or excess < self._offset + self._drift * t:
                self._offset = excess - self._drift * t
            stamp = device + self._offset + self._drift * t
        else:
            stamp = device + self._offset + self._drift * t
            # How near the line the samples come: the least residual of each block.
            residual = latest - stamp
            block = int(t // NEAR_S)
            if block != self._near_block:
                if self._near_block is not None:
                    self._near_blocks.append(self._near_least)
                self._near_block = block
                self._near_least = residual
            elif residual < self._near_least:
                self._near_least = residual
        if stamp > latest:
            # The line says this sample was taken after it was read. One such
            # packet is stamped at its read time and no more: a packet read
            # unusually early would otherwise drag every stamp after it down
            # until the next fit (by 277 us on a made-up stream). Two in a row
            # say the envelope is too high (the delay shrank): lowered at once.
            if self._under:
                self._offset -= stamp - latest
            self._under = True
            stamp = latest
        else:
            self._under = False
        if stamp <= self._last_stamp:
            stamp = self._last_stamp + MIN_STEP
        self._last_stamp = stamp
        self.samples += 1
        return stamp

    def keep_after(self, other: 'DeviceClock') -> None:
        """Stamp nothing at or before ``other``'s last stamp (it stamped in between)."""
        self._last_stamp = max(self._last_stamp, other._last_stamp)

    def _fit(self) -> None:
        """Fit the line to the envelope points (module docstring: weights, slope, height)."""
        points = self._points
        n = len(points)
        if n < MIN_POINTS or points[-1][0] - points[0][0] < MIN_SPAN_S:
            return
        if self._centre is None:
            # The first fit weighs the windows by their distance from their median
            # (drift 0), the scatter their median distance from it (as a std).
            centre, drift = statistics.median(e for _, e in points), 0.0
            scatter = 1.4826 * statistics.median(abs(e - centre) for _, e in points)
        else:
            centre, drift, scatter = self._centre, self._drift, self._scatter
        limit = BAND * scatter + BAND_FLOOR_S
        fading = self.history - TAPER
        # Plain loops, once a window: a generator would be a call per point.
        weighted = []
        total = sum_t = sum_e = 0.0
        for index, (t, e) in enumerate(points):
            age = n - 1 - index
            w = 1.0 if age < fading else (self.history - age) / TAPER
            above = e - (centre + drift * t)
            off = abs(above)
            if above > 0.0:
                w /= 1.0 + (above / (scatter + BAND_FLOOR_S)) ** 2
            if off > limit:
                w *= (limit / off) ** 4
            weighted.append((w, t, e))
            total += w
            sum_t += w * t
            sum_e += w * e
        mean_t, mean_e = sum_t / total, sum_e / total
        stt = ste = 0.0
        for w, t, e in weighted:
            stt += w * (t - mean_t) ** 2
            ste += w * (t - mean_t) * (e - mean_e)
        # The prior weighs as one window of average weight: busy windows, weighing little,
        # do not let it hold the slope at 0 (a floor that rose, once the old windows left).
        slope = ste / (stt + SLOPE_PRIOR_S2 * total / n)
        centre = mean_e - slope * mean_t
        variance = 0.0
        for w, t, e in weighted:
            variance += w * (e - centre - slope * t) ** 2
        variance /= total
        self._centre = centre
        self._scatter = math.sqrt(variance)
        self._drift = slope
        self._offset = centre - DEPTH * self._scatter
