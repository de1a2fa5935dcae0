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
Sample stamps that stay true through every event that touches the device clock.

:class:`~.clock.DeviceClock` fits a line from the device timer to the host
clock; this class decides, record by record, which device time a raw 32-bit
timer value stands for, and so whether the line still holds. The model is
written down in docs/clock.md; in short:

- The line is fitted against the host's *monotonic* clock, which nothing
  steps. A stamp is the line's monotonic time plus the system clock's
  offset from it, read when the stamp is made: when NTP or chrony steps the
  system clock, the stamps follow at once, as every other node's do, and the
  fit is not disturbed.
- After a gap in the records (a stall, a reconnect, a stream restarted, a
  power cycle, a rollover) the record's timer is read as the device time
  that best matches what the monotonic clock says elapsed (whole rollovers
  included), and that device time must land on the line: within
  ``CONTINUE_EARLY_S`` before it and ``CONTINUE_LATE_S`` after it (plus
  the drift estimate's error over the gap). Then the line goes on: a
  rollover, a stall or a reconnect to a sensor that kept its timer changes
  nothing. Otherwise the timer restarted (a power cycle, a brown-out, another
  sensor): the fit starts afresh from this record. The timer value alone
  cannot tell a rollover from a restart just before one; what elapsed can.
- A gap that was taken as continuing is watched for ``PROBATION_S``: if no
  record in that time comes within ``CONFIRM_S`` of the line (beyond how near
  the records came before: the fit's ``near``, a scheduler's tick on a busy
  host), the device lost time after all (a restart whose timer happened to
  fit), and the fit starts afresh.
- A queue draining after a gap is not lost time. A line run near its limit
  holds the records that follow a gap in a queue (the radio's link coming
  back, garbage or another sensor's packets taking the line), and they reach
  the host late, each a little less than the one before: the line carries
  them faster than they were sampled. A restarted timer's offset is a step
  that stays. So a record that comes after a gap later than
  ``CONTINUE_LATE_S`` starts a fresh fit but the line it replaced is kept:
  each record after it is placed on that line too, and once one comes
  within ``CONFIRM_S`` of it (as near), or from ``QUEUE_RECORDS`` on, the
  residuals on it fall (a slope against device time, by least squares or the
  median of the slopes between every two, that stands out of their scatter by
  ``QUEUE_SIGMAS`` standard errors; ``QUEUE_WATCH`` records are watched), the lateness
  was a queue's: the old line comes back and stamps the rest of the queue
  true, on probation until the queue has drained at that fall. Otherwise
  the fresh fit stands. (Until the records tell, the fresh fit stamps them:
  a power cycle whose timer lands a few tens of milliseconds after the
  line, near a rollover, is stamped true from its first record, and a
  queue's first records within the grace.) Records read at once (the host
  was away) count as the last of them, the least late; and a probation's
  time is the records' device time, which a reader away does not use up.

Not thread-safe: the caller stamps from one thread (the reader) or holds a lock.
"""

from collections import deque
from collections.abc import Callable
import copy
from dataclasses import dataclass, field
import enum
import statistics
import time
from typing import NamedTuple

from .clock import DeviceClock, NEAR_S
from ..codec.records import TICKS_PER_SECOND
from ..codec.timer import TIMER_MODULUS

#: Device time (s) between two records past which the second is checked against the line.
GAP_S = 0.1
#: How far (s) a record after a gap may come before the line and still continue it: the
#: line lies on the low edge of the delays (the 5 % quantile of the one-second minima), so
#: only its own error, tens of microseconds, puts a record below it.
CONTINUE_EARLY_S = 0.003
#: How far (s) after the line it may come: no further than the stamps may be off in the
#: first half second after any start, so that a restart whose timer happens to fit
#: costs no more than a fresh start would. A read delayed more than this (a busy host)
#: restarts the fit, which then settles as after any start.
CONTINUE_LATE_S = 0.005
#: A record further than this (s) from the line, or before it, says the timer restarted:
#: no read comes that late. Nearer, a late read and a restart cannot be told apart.
RESET_S = 0.5
#: A record further than this (s) *before* the line says the timer restarted. Nearer, the
#: line may be what is off: after a start on a loaded host, every record so far may have
#: been read late (tens of ms were measured), and a record read on time after a gap then
#: comes that much early. A restarted timer lands this close before the line by chance only.
EARLY_RESET_S = 0.05
#: Added to both per second of gap: what a drift error of 100 ppm makes of it.
GAP_DRIFT = 100e-6
#: How long (s) a continued gap is watched, and how close (s) to the line some record
#: in that time must come for the continuation to stand: nearer than the records came in
#: as much time before the gap (the fit's ``near``, up to a scheduler's tick on a host
#: whose cores are busy), plus CONFIRM_S.
PROBATION_S = NEAR_S
CONFIRM_S = 0.001
#: Records after a late record after a gap whose residuals may first tell a queue from a step.
QUEUE_RECORDS = 16
#: How many records after it are watched for a queue's fall (the trail holds this many, and
#: the line before the gap is given up when they have come without one). A host whose cores
#: are busy reads on the scheduler's tick (4 or 10 ms): the residuals saw-tooth by up to a
#: tick about the fall, which then stands out of their scatter only over more records than
#: QUEUE_RECORDS (the standard error falls as the records' span to the power 1.5): at the
#: streams' highest rates, a 50-ms queue read on a 10-ms tick stands out after about 30.
QUEUE_WATCH = 64
#: The longest (s of device time) a draining queue holds a probation open: a queue of
#: 50 ms on a line with 1 % of it free drains in 5 s.
QUEUE_DRAIN_S = 5.0
#: The robust slope (the median of the slopes between every two records: a square of the
#: trail's length to compute) is taken every this many records, the least-squares one at
#: every record: at most 0.1 ms a record on average, 0.5 ms on the one that takes it.
ROBUST_EVERY = 4
#: The least fall (s per s of device time) of the residuals that may be a queue's: the
#: line carries a queue away with what it has free (a stream's line budget keeps 5 % of
#: it free at its highest rate; a line run past that margin, less).
QUEUE_FALL = 0.001
#: And the fall must stand out of the residuals' own scatter: a least-squares slope this
#: many standard errors below zero. The records of a restarted timer scatter about a step
#: that stays (radio jitter, read times): their slope is that far below zero about once
#: in ten thousand; a queue's, read with 1 ms of jitter, is ten and more standard errors.
QUEUE_SIGMAS = 5.0
#: Reads of the system clock's offset from the monotonic one (see system_clock_offset):
#: at most this many, until two monotonic reads around the wall clock's lie within
#: OFFSET_GOOD_S (about 0.2 us apart when nothing interrupts the thread).
OFFSET_TRIES = 4
OFFSET_GOOD_S = 20e-6


class Restart(str, enum.Enum):
    """Why the fit started afresh."""

    #: The first record after the clock was made or cleared.
    START = 'start'
    #: The device timer restarted (a power cycle) or jumped: found by what elapsed.
    RESET = 'reset'
    #: A record after a gap sat a little off the line: a late read, or a restart whose
    #: timer nearly fitted; starting afresh is right for both.
    RESYNC = 'resync'
    #: The supervisor reconnected to a sensor it knows to be another one.
    RECONNECT = 'reconnect'


def system_clock_offset() -> float:
    """
    Return the system (ROS) clock minus the monotonic clock, in seconds.

    Read as a pair with the monotonic clock on either side, so that the
    offset is good to a fraction of a microsecond. A thread preempted between
    the reads would put the offset off by half the time it was away (a
    millisecond and more on a busy host, seen as single stamps that far off),
    so the pair is read again, up to ``OFFSET_TRIES`` times, until the reads
    lie within ``OFFSET_GOOD_S`` of each other, and the tightest pair is
    taken. This is the seam through which a test steps the clock the stamps
    follow.
    """
    best_span = float('inf')
    best = 0.0
    for _ in range(OFFSET_TRIES):
        before = time.monotonic()
        wall = time.time()
        after = time.monotonic()
        if after - before < best_span:
            best_span = after - before
            best = wall - 0.5 * (before + after)
        if best_span <= OFFSET_GOOD_S:
            break
    return best


def records_lost(step: int, expected: int) -> int:
    """Return the records lost between two ``step`` ticks apart, ``expected`` ticks a record."""
    return max(0, round(step / expected) - 1)


@dataclass(frozen=True)
class ClockStatus:
    """What the stamping clock has been through, for /diagnostics."""

    samples: int = 0
    #: How much faster the host clock runs than the device's (ppm).
    drift_ppm: float = 0.0
    #: Restarts of the fit by reason (Restart values), the first start included.
    restarts: dict[str, int] = field(default_factory=dict)
    #: Timer rollovers the fit went through (2^32 ticks, every ~218 s).
    rollovers: int = 0
    #: Gaps (stalls, reconnects, pauses) the fit went through unchanged.
    gaps: int = 0
    #: The reason of the last restart ('' before the first record).
    last_restart: str = ''
    #: Monotonic time (s) of the last record that found the device reset (None: never).
    last_reset_at: float | None = None


class _Replaced(NamedTuple):
    """The fit a late record after a gap started afresh from, kept while a queue may explain it."""

    fit: DeviceClock
    #: Ticks on the replaced fit minus ticks on the new one.
    shift: int
    last_restart: str


def _drained(device_time: float, residual: float, fall: float) -> float:
    """
    Return the device time by which a queue ``residual`` s late, falling at ``fall``, has drained.

    Twice over (the fall is known to a fifth at five standard errors, a
    line's free share may shrink), at most ``QUEUE_DRAIN_S``, and a
    probation after: the records must come near the line by then. Before,
    a probation ran out 0.3 s after the residuals last fell clearly: a
    reader away a moment or read on a busy host's tick blurred the fall for
    longer, and the fit restarted from a queued record (35 ms off).
    """
    return device_time + min(2.0 * max(residual, 0.0) / fall, QUEUE_DRAIN_S) + PROBATION_S


def _near_line(fit: DeviceClock, residual: float) -> bool:
    """Whether a record ``residual`` s above ``fit``'s line came as near it as records do."""
    return residual <= CONFIRM_S + max(0.0, fit.near)


class _Trail:
    """
    The residuals of the records since a gap, and whether they fall as a draining queue's do.

    (device time, residual) on the line the late record after the gap
    replaced, or on the line while on probation: the last ``QUEUE_WATCH``.
    Records read together (closer than half a wire time: no line brings two
    that close) waited in a buffer while the host was away, each by as long
    as it came before the read; the last of them least, and it alone stands
    for them. A reader descheduled for 0.1 s mid-queue otherwise put a lump
    of residuals up to 0.1 s high, falling at one second a second within
    itself, into the queue's gentle fall, and hid it from both slopes.
    """

    def __init__(self) -> None:
        self._points: deque[tuple[float, float]] = deque(maxlen=QUEUE_WATCH)
        self.clear()

    def __len__(self) -> int:
        return len(self._points)

    def clear(self) -> None:
        self._points.clear()
        #: Records added since the trail was last cleared (when to take the robust slope).
        self._added = 0
        #: When the last record added was read (monotonic s).
        self._last_read = float('-inf')

    def add(self, device_time: float, residual: float, read_time: float,
            wire_time: float) -> None:
        if self._points and read_time - self._last_read <= 0.5 * wire_time:
            self._points[-1] = (device_time, residual)  # read with the one before
        else:
            self._points.append((device_time, residual))
        self._last_read = read_time
        self._added += 1

    def fall(self) -> float | None:
        """
        Return how fast (s per s) the residuals fall, where they fall as a draining queue's do.

        None where they do not. At least ``QUEUE_RECORDS`` of them, whose
        slope against device time is below ``-QUEUE_FALL`` and
        ``QUEUE_SIGMAS`` standard errors below zero: by least squares, or
        (every ``ROBUST_EVERY`` records) by the median of the slopes between
        every two with the residuals' median absolute
        deviation as their scatter (one step among them, a reply or a burst of
        noise taking the line in the middle of the queue, moves that little
        where it hides a least-squares slope in its scatter).
        """
        n = len(self._points)
        if n < QUEUE_RECORDS:
            return None
        points = list(self._points)
        mean_t = sum(t for t, _ in points) / n
        stt = sum((t - mean_t) ** 2 for t, _ in points)
        if stt <= 0.0:
            return None
        mean_r = sum(r for _, r in points) / n
        slope = sum((t - mean_t) * (r - mean_r) for t, r in points) / stt
        scatter = sum((r - mean_r - slope * (t - mean_t)) ** 2 for t, r in points) / (n - 2)
        if slope < -QUEUE_FALL and slope * slope * stt > QUEUE_SIGMAS ** 2 * scatter:
            return -slope
        if (self._added - QUEUE_RECORDS) % ROBUST_EVERY:
            return None
        slope = statistics.median([(r2 - r1) / (t2 - t1) for k, (t1, r1) in enumerate(points)
                                   for t2, r2 in points[k + 1:] if t2 > t1])
        if slope >= -QUEUE_FALL:
            return None
        rest = [r - slope * t for t, r in points]
        centre = statistics.median(rest)
        spread = 1.4826 * statistics.median(abs(x - centre) for x in rest)
        return -slope if slope * slope * stt > QUEUE_SIGMAS ** 2 * spread * spread else None


class SampleClock:
    """
    Turn (raw timer, monotonic read time) into a stamp on the system clock.

    ``offset`` returns the system clock minus the monotonic clock now
    (:func:`system_clock_offset` by default). After each :meth:`stamp`,
    :attr:`ticks_since_last` the device ticks since the record before, as
    the timer counted them (rollovers included), or None where the timer
    did not run on from it (the first record, a reset, another sensor):
    what packet loss is counted from, across a resync too. :attr:`ticks` is
    the record's device time in ticks since the current
    fit started (for loss counting) and :attr:`restarted` says whether that
    record started a fit afresh (its reason in :attr:`last_restart`).
    """

    def __init__(self, offset: Callable[[], float] = system_clock_offset,
                 fit: DeviceClock | None = None) -> None:
        self._system_offset = offset
        self.fit = fit or DeviceClock()
        self._restarts: dict[str, int] = {}
        self.rollovers = self.gaps = 0
        self.last_restart = ''
        self._last_reset_at: float | None = None
        self.clear()

    def clear(self, reason: Restart = Restart.START) -> None:
        """Start the next record afresh, for ``reason`` (a new configuration, another sensor)."""
        self._pending = reason
        self._check_next = self.restarted = False
        self._last_raw: int | None = None
        self._last_host = self._probation_best = 0.0
        #: The device time (s, the fit's ticks) at which a probation ends: counted in the
        #: records' time, not the host's, so that a reader away longer than a probation
        #: (a busy host) does not run it out before the records it then reads are judged.
        self._probation_end: float | None = None
        #: The records since the last gap: whether they fall as a queue's do.
        self._trail = _Trail()
        self._replaced: _Replaced | None = None
        self.ticks = 0
        self.ticks_since_last: int | None = None

    def link_changed(self, same_device: bool = True) -> None:
        """
        Check the next record against the line (or restart): a new link is up.

        ``same_device`` False: the sensor is known to be another one, whose
        timer has nothing to do with the line.
        """
        if same_device:
            self._check_next = True
        else:
            self.clear(Restart.RECONNECT)

    def stamp(self, raw_timer: int, read_time: float, wire_time: float = 0.0) -> float:
        """
        Return the system-clock time (s) at which the record was sampled.

        ``read_time`` is the monotonic time its last byte was read,
        ``wire_time`` how long the packet takes on the line.
        """
        host = read_time - wire_time
        self.restarted = False
        last = self._last_raw
        if last is None:
            self._restart(self._pending, raw_timer)
        else:
            step = raw_timer - last
            # The steady case, in place (what _follow would find): the timer ran on by
            # less than a gap, no rollover, the host lost no time, nothing on watch.
            if step >= 0 and step / TICKS_PER_SECOND <= GAP_S \
                    and host - self._last_host - step / TICKS_PER_SECOND <= RESET_S \
                    and not self._check_next and self._replaced is None \
                    and self._probation_end is None:
                self.ticks_since_last = step
                self.ticks += step
            else:
                self._follow(raw_timer, host, read_time, wire_time)
        self._last_raw, self._last_host = raw_timer, host
        return self.fit.stamp(self.ticks, read_time, wire_time) + self._system_offset()

    def _follow(self, raw: int, host: float, read_time: float, wire_time: float) -> None:
        """Place ``raw`` on the current fit, or restart the fit if it cannot be placed."""
        step = (raw - self._last_raw) % TIMER_MODULUS
        elapsed = host - self._last_host
        wraps = max(0, round((elapsed * TICKS_PER_SECOND - step) / TIMER_MODULUS))
        ticks = self.ticks + step + wraps * TIMER_MODULUS
        turns = wraps + (raw < self._last_raw)  # the rollovers in between
        # A gap in device time (a stall, a pause), or host time lost beyond what a busy
        # host delays a read by (a restart whose timer happened to continue): a reader
        # that was merely late sees the next tick count and needs no check.
        gap = (step / TICKS_PER_SECOND > GAP_S
               or elapsed - step / TICKS_PER_SECOND > RESET_S)
        # A rollover between two records that follow each other is one: only one across
        # host time (a restart whose timer landed just past the old one's wrap) is checked,
        # so that a record late behind a queue as the timer wraps restarts nothing.
        checked = gap or self._check_next or (turns > 0 and elapsed > GAP_S)
        if not checked:
            self.rollovers += turns
        if checked:
            self._replaced = None
            off = self.fit.residual(ticks, read_time, wire_time)
            slack = GAP_DRIFT * max(elapsed, 0.0)
            if not -CONTINUE_EARLY_S - slack <= off <= CONTINUE_LATE_S + slack:
                # Far off either way, the timer restarted. Nearer, it may have run on and
                # the line be what is off: a late read, or a young fit whose first
                # records all came late (a loaded host), so that a record on time now
                # comes early. Starting afresh is right for both; only the first is a
                # reset of the device, and only the second keeps counting the loss.
                if off > RESET_S or off < -EARLY_RESET_S:
                    self._restart(Restart.RESET, raw, host)
                    return
                # Late, it may be the head of a queue on the line: the fit it replaces is
                # kept until the records that follow tell (see _resume).
                replaced = (_Replaced(copy.deepcopy(self.fit), ticks - raw, self.last_restart)
                            if off > 0.0 else None)
                self._restart(Restart.RESYNC, raw, host, since=ticks - self.ticks)
                if replaced is not None:
                    self._replaced = replaced
                    self._trail.add(ticks / TICKS_PER_SECOND, off, read_time, wire_time)
                return
            if gap or self._check_next:
                self.gaps += 1
                self._probation_end = ticks / TICKS_PER_SECOND + PROBATION_S
                self._probation_best = off
                self._trail.clear()
                self._trail.add(ticks / TICKS_PER_SECOND, off, read_time, wire_time)
            self._check_next = False
            self.rollovers += turns
        elif self._replaced is not None:
            replaced = self._replaced
            on_old = ticks + replaced.shift
            off = replaced.fit.residual(on_old, read_time, wire_time)
            self._trail.add(on_old / TICKS_PER_SECOND, off, read_time, wire_time)
            near = _near_line(replaced.fit, off)
            fall = None if near else self._trail.fall()
            if near or fall is not None:
                # The records caught up with the line before the gap, or fall towards it
                # as a queue's do: a queue, drained or draining.
                self._resume(on_old / TICKS_PER_SECOND, off, fall)
                ticks = on_old
            elif len(self._trail) == QUEUE_WATCH:
                self._replaced = None  # a step that stays: the fresh fit stands
        elif self._probation_end is not None:
            off = self.fit.residual(ticks, read_time, wire_time)
            self._probation_best = min(self._probation_best, off)
            self._trail.add(ticks / TICKS_PER_SECOND, off, read_time, wire_time)
            fall = self._trail.fall()
            if fall is not None:
                # A queue is draining: its records are late by what it still holds, and
                # the time to come near the line counts from when it has drained.
                self._probation_end = max(self._probation_end,
                                          _drained(ticks / TICKS_PER_SECOND, off, fall))
            if ticks / TICKS_PER_SECOND >= self._probation_end:
                self._probation_end = None
                if not _near_line(self.fit, self._probation_best):
                    # No record since the gap came near the line: the device lost time.
                    self._restart(Restart.RESYNC, raw, host, since=ticks - self.ticks)
                    return
        self.ticks_since_last = ticks - self.ticks
        self.ticks = ticks

    def _resume(self, device_time: float, off: float, fall: float | None) -> None:
        """
        Go back to the fit a late record after a gap replaced: it was a queue's head.

        The records since caught up with that fit (one came near it, or their
        residuals on it fell as a draining queue's do), so the lateness was
        the queue's, not lost device time: the line before the gap stamps
        them true, where the new fit, started from queued records, would
        follow the queue out. The gap is then a gap, on probation as any
        other (``fall`` None: a record came near the line) or until the
        queue has drained (``fall``: how fast its residuals fall); the restart
        is undone in the counts.
        """
        replaced, self._replaced = self._replaced, None
        replaced.fit.keep_after(self.fit)
        self.fit = replaced.fit
        self.ticks += replaced.shift
        self._restarts[Restart.RESYNC] -= 1  # counted by the restart this undoes
        if not self._restarts[Restart.RESYNC]:
            del self._restarts[Restart.RESYNC]
        self.last_restart = replaced.last_restart
        self.gaps += 1
        self._probation_end = (device_time + PROBATION_S if fall is None
                               else _drained(device_time, off, fall))
        self._probation_best = off

    def _restart(self, reason: Restart, raw: int, host: float = 0.0,
                 since: int | None = None) -> None:
        self.clear()  # the record's raw timer and host time are kept by stamp()
        self.fit.reset()
        self.ticks, self.ticks_since_last, self.restarted = raw, since, True
        self.last_restart = reason.value
        self._restarts[reason.value] = self._restarts.get(reason.value, 0) + 1
        if reason is Restart.RESET:
            self._last_reset_at = host

    def status(self) -> ClockStatus:
        """Return a snapshot of the clock's state (safe to hand to another thread)."""
        return ClockStatus(
            samples=self.fit.samples, drift_ppm=self.fit.drift_ppm,
            restarts=dict(self._restarts), rollovers=self.rollovers, gaps=self.gaps,
            last_restart=self.last_restart, last_reset_at=self._last_reset_at)
