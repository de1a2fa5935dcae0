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
How true the stamps stay: event by event, and stream by stream when nothing goes wrong.

Event by event (``--events``): the simulated sensor streams 0xCC at 100 Hz
through the real supervisor, link and parser, stamped as the node stamps
(harness/stamp_runs.py); each event of issue #23 is applied while it
streams. For each: the worst stamp error after the grace period (0.5 s after
the stream's return), against the steady offset before the event; the rate
error (trend of the error after the grace, ppm); the time to settle (from
the stream's return to the last stamp more than 1 ms off); and the worst in
the grace. The power cycle 0.4 s before the rollover is also written as a
CSV (``--plot-csv``) for ``plot --stamp-errors``.

Stream by stream (``--streams``): every stream at 100 Hz and at the highest
rate its line budget allows, with radio-like delays (2 ms latency, the wire
time at 115200 baud, a random 0..5 ms more), ``--stream-seconds`` each: the
standard deviation of the stamp error after 10 s ("settled") and after 60 s,
the worst |error - median| after 10 s, and the error's trend after 10 s (a
drift learnt late or wrong shows there). ``--record FILE`` keeps every run's
recording (timer, read time, system clock offset, truth of each record);
``--replay FILE`` stamps those recordings again, offline, through the clock
as it is now, and reports the same figures: two versions of the clock judged
on the very same delays.

A queue after a gap (``--queues``): every stream at the highest rate its
line allows, the base station's line modelled (``line_queue``: one packet
at a time), a stall of 0.1, 0.3, 1 or 3 s after which the radio's first
packet comes 6, 20 or 50 ms late (``radio_hold_s``) and the records sampled
meanwhile queue behind it; and 0xCC at 100 Hz with garbage and another
sensor's packets on the line from the start. For each: the worst stamp
error from 0.5 s after the return, the worst in the grace, and whether the
fit was kept (a queue is not lost time; on a loaded host a young fit may
start afresh for another reason, clock.md).

The stamp's cost (``--cost``): the time ``SampleClock.stamp`` takes per
record in the reader thread, on a made-up 100 Hz stream, the system clock's
offset read as the node reads it: the hot path's share of the clock.

Through the node (``--node``): the simulated device in a process of its own
delays every 0xCC packet at 100 Hz by 2 ms of radio, the 7.6 ms the packet
takes on the wire and a random 0..5 ms more (USB, kernel, scheduler), its
timer 40 ppm fast; the node in this process stamps with ``time_source:
device`` (the fit) and, in a second run, ``host`` (the read time), a minute
each. The standard deviation of ``stamp - true sample time`` over all
samples and after the first 5 s (the first stamp can only be the read time
less the wire time, and the fit needs a few one-second windows), and the
mean, which in device mode is the radio latency no host can see. Target:
<= 50 us in device mode (host stamping: about 5 ms / sqrt(12) = 1.4 ms).
"""

import dataclasses
import pickle
import random
import statistics
import sys
import time

from bench_common import InProcessNode, percentile, report, Result, standard_args, std_dev
from harness.processes import isolate_ros_domain, SimProcess
from harness.stamp_runs import check_series, errors, GRACE, restamp, Run, run, TOLERANCE

from i3dmgx2_driver.codec import line_budget, streams
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.device.sample_clock import SampleClock
from i3dmgx2_driver.simulator.faults import FaultConfig
from i3dmgx2_driver.tools.stamp_plot import write_stamp_errors

#: Timer at power-up for runs that cut power near the rollover: it comes 9 s in.
NEAR_ROLLOVER_START = TIMER_MODULUS - round(9.0 * TICKS_PER_SECOND)


def _wait_timer(sim, before_rollover: float, timeout: float = 10.0) -> None:
    """Return when the sensor's timer is ``before_rollover`` s before its rollover."""
    target = TIMER_MODULUS - round(before_rollover * TICKS_PER_SECOND)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        truth = sim.truth
        if truth and truth[-1].timer is not None and truth[-1].timer >= target - 196_608:
            return
        time.sleep(0.002)


def _power_cycle_near_rollover(sim, sup, system) -> float:
    _wait_timer(sim, 0.4)
    cut = time.time()
    sim.power_cycle(off_seconds=1.0, timer_start=20_536_380)
    return cut


def _swap_sensor(sim, sup, system) -> None:
    sim.unplug(1.0)
    sim.power_cycle(timer_start=1_234_567_890)


def _pause(sim, sup, system) -> None:
    sup.stop_streaming()
    time.sleep(1.0)
    sup.start_streaming()


def _step(seconds: float):
    def step(sim, sup, system) -> None:
        system.step = seconds
    return step


#: (label, event, extra simulator settings, whether the event starts a new fit).
EVENTS = [
    ('timer rollover', None, {'timer_start': NEAR_ROLLOVER_START}),
    ('power cycle, off 1 s, timer far from rollover',
     lambda sim, sup, system: sim.power_cycle(off_seconds=1.0, timer_start=20_536_380), {}),
    ('power cycle, off 1 s, 0.4 s before rollover', _power_cycle_near_rollover,
     {'timer_start': NEAR_ROLLOVER_START}),
    ('stall (radio out of range) 1.5 s', lambda sim, sup, system: sim.stall(1.5), {}),
    ('stall 20 s', lambda sim, sup, system: sim.stall(20.0), {}),
    ('unplug/replug (base station reset) 1 s', lambda sim, sup, system: sim.unplug(1.0), {}),
    ('reconnect finds another sensor', _swap_sensor, {}),
    ('rate change 100 -> 200 Hz', lambda sim, sup, system: sim.set_rate(200.0), {}),
    ('stream stopped 1 s (deactivate/activate)', _pause, {}),
    ('system clock stepped +1 s', _step(1.0), {}),
    ('system clock stepped -1 s', _step(-1.0), {}),
]


def event_rows(after: float, plot_csv: str | None) -> list[Result]:
    """Run every event; return the table rows."""
    rows = []
    for label, event, sim in EVENTS:
        stepped = label.startswith('system clock')
        result = run(event, before=4.0, after=after + (20.0 if 'stall 20' in label else 0.0),
                     **sim)
        series = errors(result)
        event_time = None if stepped or event is None else result.event_time
        try:
            figures = check_series(series, event_time, label)
            verdict = True
        except AssertionError as failure:
            figures, verdict = None, False
            print(f'{label}: {failure}', file=sys.stderr)
        status = result.clock.status()
        restarts = ', '.join(f'{k} {v}' for k, v in sorted(status.restarts.items()))
        if figures is None:
            rows.append(Result(label, 'FAILED (see stderr)', '', False))
            continue
        back = figures['back']
        steady = figures['steady']
        grace = [abs(e - steady) for t, e in series if back is not None and back <= t
                 < back + GRACE]
        late = [t for t, e in series if back is not None and t >= back
                and abs(e - steady) > TOLERANCE]
        settle = (max(late) - back) if late else 0.0
        rows.append(Result(
            label,
            f'{figures["worst"] * 1e3:.3f} ms; {figures["trend_ppm"]:+.1f} ppm; settled '
            f'{settle:.2f} s; grace worst '
            f'{(max(grace) if grace else 0.0) * 1e3:.2f} ms; fit: {restarts}; rollovers '
            f'{status.rollovers}',
            '<= 1 ms after 0.5 s', verdict))
        if plot_csv and event is _power_cycle_near_rollover:
            write_stamp_errors(plot_csv, series, [(result.event_time, 'power off 1 s')])
            print(f'(stamp errors written to {plot_csv})', flush=True)
    return rows


def settled_figures(series: list[tuple[float, float]]) -> dict:
    """Return the settled std (after 10 s and 60 s), worst after 10 s and trend (ppm)."""
    start = series[0][0]
    after10 = [(t, e) for t, e in series if t - start >= 10.0]
    late = [e for t, e in series if t - start >= 60.0]
    values = [e for _, e in after10]
    centre = statistics.median(values)
    return {
        'std10': statistics.pstdev(values),
        'std60': statistics.pstdev(late) if len(late) > 2 else float('nan'),
        'worst10': max(abs(e - centre) for e in values),
        'trend10': statistics.linear_regression([t for t, _ in after10], values).slope * 1e6,
        'n': len(values)}


def figures_row(label: str, series: list[tuple[float, float]]) -> Result:
    """One row of the stream table: the settled figures against the targets."""
    f = settled_figures(series)
    return Result(
        label,
        f'settled std {f["std10"] * 1e6:.1f} us (after 60 s: {f["std60"] * 1e6:.1f} us); '
        f'worst {f["worst10"] * 1e6:.0f} us; trend {f["trend10"]:+.2f} ppm (after 10 s, '
        f'n={f["n"]})',
        'std <= 20 us, trend <= 5 ppm', f['std10'] <= 20e-6 and abs(f['trend10']) <= 5.0)


def stream_choices() -> list[tuple[streams.Stream, float]]:
    """Every stream at 100 Hz and at the highest rate its line budget allows."""
    choices = []
    for stream in streams.STREAMS:
        choices.append((stream, 100.0))
        highest = line_budget.max_rate(stream.code, 115200, True)
        if highest and round(highest, 1) != 100.0:
            choices.append((stream, round(highest, 1)))
    return choices


def stream_rows(seconds: float, record: str | None) -> list[Result]:
    """Settled stamp error per stream at 100 Hz and at its highest rate."""
    rows = []
    recordings = []
    for stream, rate in stream_choices():
        result = run(None, before=seconds, after=0.0, stream=stream.code, data_rate_hz=rate,
                     latency_s=0.002, wire_baud=115200, faults=FaultConfig(jitter_ms=5.0))
        label = f'{stream.label} at {rate:g} Hz, radio-like delays'
        rows.append(figures_row(label, errors(result)))
        print(f'{label}: {rows[-1].value}', flush=True)
        recordings.append((label, _recording(result)))
    if record:
        with open(record, 'wb') as out:
            pickle.dump(recordings, out)
        print(f'(recordings written to {record})', flush=True)
    return rows


def _recording(result: Run) -> Run:
    """Return the run without its clock and log: what --replay needs."""
    return dataclasses.replace(result, clock=None, log=[])


def replay_rows(path: str) -> list[Result]:
    """Stamp recorded runs again through the clock as it is now; the same figures."""
    with open(path, 'rb') as source:
        recordings = pickle.load(source)
    return [figures_row(f'{label} (recorded)', errors(restamp(result)))
            for label, result in recordings]


#: The stalls and the radio's late return the queue table runs through.
QUEUE_GAPS = (0.1, 0.3, 1.0, 3.0)
QUEUE_HOLDS = (0.006, 0.020, 0.050)


def queue_rows() -> list[Result]:
    """Run a queue after a gap at every stream's highest rate, and noise on the line."""
    rows = []
    runs = [(f'{stream.label} at {rate:g} Hz, stall {gap:g} s, radio back {hold * 1e3:g} ms '
             f'late',
             {'event': _stall(gap), 'before': 3.0, 'after': gap + 3.0, 'stream': stream.code,
              'data_rate_hz': rate, 'radio_hold_s': hold, 'limit_to_line_rate': True,
              'faults': FaultConfig(jitter_ms=1.0)})
            for stream, rate in stream_choices() if rate != 100.0
            for gap in QUEUE_GAPS for hold in QUEUE_HOLDS]
    runs.append(('0xCC at 100 Hz, garbage, corrupted and foreign packets on the line from '
                 'the start',
                 {'event': None, 'before': 15.0, 'after': 0.0, 'faults': FaultConfig(
                     garbage_probability=0.3, corrupt_checksum_probability=0.05,
                     corrupt_length_probability=0.02, foreign_probability=0.2,
                     jitter_ms=1.0)}))
    for label, settings in runs:
        result = run(settings.pop('event'), line_queue=True, **settings)
        series = errors(result)
        try:
            figures = check_series(series, result.event_time, label, early_tolerance=1.0)
        except AssertionError as failure:
            print(f'{label}: {failure}', file=sys.stderr)
            rows.append(Result(label, 'FAILED (see stderr)', '<= 1 ms after 0.5 s', False))
            continue
        back = figures['back'] if figures['back'] is not None else series[0][0]
        grace = max(abs(e - figures['steady']) for t, e in series if back <= t < back + GRACE)
        restarts = result.clock.status().restarts
        kept = 'kept' if restarts == {'start': 1} else ', '.join(
            f'{k} {v}' for k, v in sorted(restarts.items()))
        rows.append(Result(
            label, f'{figures["worst"] * 1e3:.3f} ms after the grace; grace worst '
                   f'{grace * 1e3:.2f} ms; fit: {kept}',
            '<= 1 ms after 0.5 s', figures['worst'] <= 1e-3))
        print(f'{label}: {rows[-1].value}', flush=True)
    return rows


def _stall(seconds: float):
    return lambda sim, sup, system: sim.stall(seconds)


def cost_rows(records: int = 200_000) -> list[Result]:
    """Time SampleClock.stamp per record on a made-up 100 Hz stream (the hot path's share)."""
    rng = random.Random(5)
    ticks_per_cycle = TICKS_PER_SECOND * (1 + 40e-6) / 100.0
    wire = line_budget.wire_time(streams.DEFAULT.code, 115200, True)
    inputs = [(round(1_000_000 + k * ticks_per_cycle) % TIMER_MODULUS,
               1000.0 + k / 100.0 + 0.002 + wire + rng.uniform(0.0, 0.005))
              for k in range(records)]
    rows = []
    for label, clock in (('system clock offset read as the node reads it', SampleClock()),
                         ('the fit alone (offset 0)', SampleClock(offset=lambda: 0.0))):
        best = float('inf')
        for _ in range(3):
            clock.clear()
            began = time.perf_counter()
            for raw, read in inputs:
                clock.stamp(raw, read, wire)
            best = min(best, (time.perf_counter() - began) / records)
        rows.append(Result(f'SampleClock.stamp, {label}', f'{best * 1e6:.2f} us per record',
                           'no noticeably slower', True))
    return rows


#: Through the node: seconds per time source, the random delay's top (ms), the radio latency
#: (s), and when the fit counts as settled (s, for the second figure); the target (s).
NODE_SECONDS = 60.0
NODE_JITTER_MS = 5.0
RADIO_LATENCY_S = 0.002
NODE_SETTLE_S = 5.0
NODE_TARGET_STD_S = 50e-6


def node_errors(time_source: str) -> list[tuple[float, float]]:
    """Stream through the node; return (seconds since the first sample, stamp error)."""
    sim = SimProcess(rate_hz=100.0, latency_s=RADIO_LATENCY_S, wire_baud=115200,
                     faults={'jitter_ms': NODE_JITTER_MS})
    node = None
    try:
        node = InProcessNode(sim.port, time_source=time_source)
        if not node.wait_published(1, timeout=20.0):
            raise RuntimeError('the node published nothing within 20 s')
        time.sleep(NODE_SECONDS)
        sim.silence()
        node.wait_quiet()
    finally:
        if node is not None:
            node.close()
        sim.stop()
    sample_time = {e.timer: e.sample_time for e in sim.written_stream()}
    matched = [(sample_time[p.timer], p.stamp) for p in node.published if p.timer in sample_time]
    start = matched[0][0] if matched else 0.0
    return [(t - start, stamp - t) for t, stamp in matched]


def node_rows() -> list[Result]:
    """Stamp errors through the node, in device and in host mode: the rows."""
    isolate_ros_domain()
    device = node_errors('device')
    every = [e for _, e in device]
    settled = [e for t, e in device if t >= NODE_SETTLE_S]
    target = f'<= {NODE_TARGET_STD_S * 1e6:.0f} us'
    rows = [Result(f'through the node: std dev, device time, 0-{NODE_JITTER_MS:g} ms random '
                   'read delay (all samples)', f'{std_dev(every) * 1e6:.1f} us '
                   f'(n={len(every)})', target, std_dev(every) <= NODE_TARGET_STD_S),
            Result(f'through the node: std dev, device time, after the first {NODE_SETTLE_S:g} s',
                   f'{std_dev(settled) * 1e6:.1f} us (n={len(settled)})', target,
                   std_dev(settled) <= NODE_TARGET_STD_S)]
    mean = statistics.fmean(every) if every else float('nan')
    spread = [abs(e - mean) for e in every]
    rows.append(Result(
        'through the node, device time: mean offset; p99 / max |error - mean|',
        f'{mean * 1e3:+.3f} ms; {percentile(spread, 99) * 1e6:.0f} / '
        f'{max(spread, default=float("nan")) * 1e6:.0f} us'))
    host = [e for _, e in node_errors('host')]
    rows.append(Result(
        'through the node: std dev, host time (read time), same delays',
        f'{std_dev(host) * 1e6:.0f} us (n={len(host)}); mean offset '
        f'{(statistics.fmean(host) if host else float("nan")) * 1e3:+.3f} ms'))
    return rows


def main() -> None:
    """Run from the command line."""
    def more(parser) -> None:
        parser.add_argument('--events', action='store_true', help='the event table only')
        parser.add_argument('--streams', action='store_true', help='the stream table only')
        parser.add_argument('--cost', action='store_true', help='the stamp cost only')
        parser.add_argument('--node', action='store_true', help='the table through the node only')
        parser.add_argument('--queues', action='store_true',
                            help='the queue after a gap table only')
        parser.add_argument('--stream-seconds', type=float, default=None,
                            help='length of each stream run (default 130 s)')
        parser.add_argument('--record', metavar='FILE',
                            help='keep the recordings of the stream runs here (pickle)')
        parser.add_argument('--replay', metavar='FILE',
                            help='stamp recorded stream runs again through the clock as it is')
        parser.add_argument('--plot-csv', metavar='CSV',
                            help='write the near-rollover power cycle series here')

    args = standard_args(__doc__.splitlines()[1], 6.0, more)
    if args.replay:
        report('Stamp errors, recorded runs', replay_rows(args.replay),
               [f'Recordings of {args.replay} stamped again through the clock as it is.'],
               None, other_load=args.other_load)
        return
    every = not (args.events or args.streams or args.cost or args.queues or args.node)
    results = []
    if args.events or every:
        results += event_rows(args.seconds, args.plot_csv)
    if args.streams or every:
        results += stream_rows(args.stream_seconds or 130.0, args.record)
    if args.queues or every:
        results += queue_rows()
    if args.cost or every:
        results += cost_rows()
    if args.node or every:
        results += node_rows()
    report('Stamp errors', results,
           [f'Events: 0xCC at 100 Hz, {args.seconds:g} s after each event; the simulated '
            f'timer runs 40 ppm fast; stamps made as the node makes them '
            f'(harness/stamp_runs.py).',
            'Columns: worst |error - steady offset| after the grace; error trend (ppm); '
            'time from the return to the last stamp over 1 ms off; worst in the grace; '
            'why the fit started afresh.',
            f'Through the node: {NODE_SECONDS:g} s per time source at 100 Hz; simulated delay '
            f'{RADIO_LATENCY_S * 1e3:g} ms radio + 7.64 ms on the wire + 0..{NODE_JITTER_MS:g} '
            'ms random; device clock 40 ppm fast; the device-time mean offset is the radio '
            'latency, which the host cannot observe.'],
           'stamp_errors.md', other_load=args.other_load)


if __name__ == '__main__':
    main()
