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

"""The stamp check: every stamp true to its sample time through every fault (issue #23)."""

import statistics

from harness.campaign_config import CampaignConfig
from harness.campaign_truth import Sent
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import TIMER_MODULUS


def stamp_verdict(matched: list[tuple[Sent, tuple]], cfg: CampaignConfig) -> tuple[bool, str]:
    """
    Judge the stamp errors as a series: steady after every start and return.

    A return is a published record sampled more than 0.1 s after the one
    before it, or whose timer does not follow from that one's (the sensor
    restarted): the stamps may start afresh there, within
    ``stamp_early_tolerance`` for ``stamp_grace`` s.

    The first record of a start or return is stamped at its read time (the
    fresh fit has nothing else): its error is how late the node's reader got
    to it, which a loaded host (a thread waiting for the interpreter's lock,
    up to its 5-ms switch interval) makes late at the node's start. Only for
    that record, how much later than usual it reached the subscriber is
    allowed on top; every later record of the grace has the strict limit.
    """
    if not matched:
        return True, 'no stamps to judge'
    series = [(sent.sample_time, row[1] * 1e-9 - sent.sample_time, sent.timer)
              for sent, row in matched]
    # How late each record left the simulator after its sample time (the line's queue).
    delays = [(sent.write_time or sent.sample_time) - sent.sample_time for sent, _ in matched]
    # How late each reached the subscriber after its sample time (the node's reader among it).
    arrivals = [row[3] - sent.sample_time for sent, row in matched]
    steady = statistics.median(e for _, e, _ in series)
    usual = statistics.median(delays)
    usual_arrival = statistics.median(arrivals)
    grace_from = series[0][0]
    # In a grace the stamps start from the first records' arrival: one the simulator wrote
    # late (its thread descheduled on a loaded machine) moves them by as much, and no
    # receiver could know better then. That lateness is allowed on top, in that grace.
    grace_late = max(0.0, delays[0] - usual)
    returns = 0
    worst = worst_early = 0.0
    bad = []
    previous = None
    for (t, e, timer), delay, arrival in zip(series, delays, arrivals, strict=True):
        first = previous is None
        if previous is not None:
            dt = t - previous[0]
            steps = ((timer - previous[2]) % TIMER_MODULUS / TICKS_PER_SECOND
                     if timer is not None and previous[2] is not None else dt)
            if dt > 0.1 or abs(steps - dt) > 0.05:
                grace_from = t
                grace_late = max(0.0, delay - usual)
                returns += 1
                first = True
        previous = (t, e, timer)
        off = abs(e - steady)
        early = t - grace_from < cfg.stamp_grace
        if early:
            worst_early = max(worst_early, off)
        else:
            worst = max(worst, off)
        read_late = max(0.0, arrival - usual_arrival) if first else 0.0
        limit = (cfg.stamp_early_tolerance + max(grace_late, read_late) if early
                 else cfg.stamp_tolerance)
        if off > limit:
            bad.append(f'{off * 1e3:.2f} ms at {t - series[0][0]:.2f} s'
                       + (' (in a grace)' if early else '')
                       + f' written {delay * 1e3:.1f} ms after its sample time'
                       + (f', received {arrival * 1e3:.1f} ms after it' if first else ''))
    detail = (f'stamp - true sample time: steady {steady * 1e3:+.3f} ms; worst off it '
              f'{worst * 1e3:.3f} ms after the {cfg.stamp_grace:g}-s graces (limit '
              f'{cfg.stamp_tolerance * 1e3:g}), {worst_early * 1e3:.2f} ms in them (limit '
              f'{cfg.stamp_early_tolerance * 1e3:g}, plus how much later than usual the '
              f"simulator wrote the grace's first record, and for that record, how much "
              f'later than usual it was received); {returns} returns; '
              f'{len(bad)} stamps over' + (f', e.g. {"; ".join(bad[:5])}' if bad else ''))
    return not bad, detail
