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
Timestamp quality: the published stamp against the true sample time.

The simulated device delays every packet by a fixed latency (2 ms of radio,
and the 7.6 ms an 88-byte packet takes on a 115200-baud line) and by a
random 0..5 ms more (USB, kernel, scheduler), and its timer runs 40 ppm
fast. With ``time_source: device`` the node maps the timer onto the host
clock (device/clock.py: lower envelope of host - device time, drift
fitted); with ``host`` it stamps the read time. The error of each stamp is
``stamp - true sample time``; its standard deviation is the figure of merit
(target: <= 50 us in device mode; host stamping: about 5 ms / sqrt(12) =
1.4 ms). It is given over all samples and after the first seconds: the
first stamp can only be the read time less the wire time (up to 5 ms off),
and the estimate needs a few one-second windows to settle, so the figure
over a whole run depends on its length. The mean is reported too: in device
mode it is the simulated radio latency, which no host-side estimate can see.
"""

from bench_common import InProcessNode, Result, run_benchmark
from harness.percentiles import percentile, std_dev
from harness.processes import isolate_ros_domain, SimProcess

#: Standard deviation of (stamp - sample time) in device mode (s).
TARGET_STD_S = 50e-6
#: Random extra delay of each packet, 0..JITTER_MS (uniform).
JITTER_MS = 5.0
#: Simulated radio latency (s), the part of the delay no estimate can see.
RADIO_LATENCY_S = 0.002
#: Time an 88-byte packet takes on a 115200-baud 8N1 line (s).
WIRE_TIME_S = 88 * 10 / 115200
#: Seconds after which the estimate counts as settled (for the second figure).
SETTLE_S = 5.0


def errors(time_source: str, seconds: float) -> list[tuple[float, float]]:
    """Stream for ``seconds``; return (seconds since the first sample, stamp error)."""
    import time
    sim = SimProcess(rate_hz=100.0, latency_s=RADIO_LATENCY_S, wire_baud=115200,
                     faults={'jitter_ms': JITTER_MS})
    node = None
    try:
        node = InProcessNode(sim.port, time_source=time_source)
        if not node.wait_published(1, timeout=20.0):
            raise RuntimeError('the node published nothing within 20 s')
        time.sleep(seconds)
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


def run(seconds: float) -> list[Result]:
    """Measure in device and host mode; return the table rows."""
    isolate_ros_domain()
    device = errors('device', seconds)
    host = errors('host', seconds)
    results = []
    every = [e for _, e in device]
    settled = [e for t, e in device if t >= SETTLE_S]
    std_all = std_dev(every)
    results.append(Result(
        'timestamp error std dev, device time, 0-5 ms random read delay (all samples)',
        f'{std_all * 1e6:.1f} us (n={len(every)})', f'<= {TARGET_STD_S * 1e6:.0f} us',
        std_all <= TARGET_STD_S))
    if settled:
        std_settled = std_dev(settled)
        results.append(Result(
            f'timestamp error std dev, device time, after the first {SETTLE_S:g} s',
            f'{std_settled * 1e6:.1f} us (n={len(settled)})', f'<= {TARGET_STD_S * 1e6:.0f} us',
            std_settled <= TARGET_STD_S))
    mean = sum(every) / len(every) if every else float('nan')
    spread = [abs(e - mean) for e in every]
    results.append(Result(
        'timestamp error, device time: mean offset; p99 / max |error - mean|',
        f'{mean * 1e3:+.3f} ms; {percentile(spread, 99) * 1e6:.0f} / '
        f'{max(spread, default=float("nan")) * 1e6:.0f} us'))
    host_errors = [e for _, e in host]
    host_mean = sum(host_errors) / len(host_errors) if host_errors else float('nan')
    results.append(Result(
        'timestamp error std dev, host time (read time), same delays',
        f'{std_dev(host_errors) * 1e6:.0f} us (n={len(host_errors)}); mean offset '
        f'{host_mean * 1e3:+.3f} ms'))
    return results


def main() -> None:
    """Run from the command line."""
    run_benchmark(__doc__, (60.0, 15.0), run, 'Timestamps', 'timestamps.md', lambda seconds: [
        f'{seconds:g} s per time source at 100 Hz; simulated delay: '
        f'{RADIO_LATENCY_S * 1e3:g} ms radio + {WIRE_TIME_S * 1e3:.2f} ms on the wire + '
        f'0..{JITTER_MS:g} ms random; device clock 40 ppm fast.',
        f'Device-time mean offset: the {RADIO_LATENCY_S * 1e3:g} ms radio latency, '
        f'which the host cannot observe.'])


if __name__ == '__main__':
    main()
