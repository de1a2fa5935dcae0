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
What only the benchmarks share: the node in-process, latencies, their options, the table.

Every benchmark runs the simulated device in a process of its own
(``harness.processes.SimProcess``), as a real device is, and reads its
ground truth when it stops: the time each packet's last byte was written and
the time its sample was taken, keyed by the device timer. The node runs
either in the benchmark's process (:class:`InProcessNode`, to time
``publish()`` from inside) or as the real executable (``harness.processes.
NodeProcess``, to measure its CPU; :class:`TimedNodeProcess`, timed from
inside). Subscribers run in another process (``harness.processes.
SubscriberProcess``). The processes are ``harness/``'s, which the tests
use too; importing this module puts the repository on the path for them.
The statistics (percentiles, summaries) are the benchmarks' alone: here.

Benchmarks print numbers; they never fail on speed.
"""

from collections.abc import Callable
from importlib import metadata
import json
import math
import os
from pathlib import Path
import platform
import sys
import tempfile
import threading
import time
from typing import Any, NamedTuple

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
OUTPUT_DIR = BENCH_DIR / 'output'
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from harness.processes import (  # noqa: E402 - the repository is on the path from here on
    ADDRESS, BENCHMARK_DOMAINS, NodeProcess, reserve_ros_domain, ros_env, TruthEntry,
)
from i3dmgx2_driver.codec import layouts, line_budget  # noqa: E402
from i3dmgx2_driver.device import hot_path  # noqa: E402
from i3dmgx2_driver.device.hot_path import QuietObserver  # noqa: E402
# A benchmark's ROS domain is never one a test run draws (harness.processes.TEST_DOMAINS):
# a benchmark's node still publishing must not reach the tests running beside it.
reserve_ros_domain(BENCHMARK_DOMAINS)

#: Highest rate of 0xCC packets (88 bytes through the base station) a 115200-baud line
#: carries (11,520 bytes/s), from the codec's layout table.
LINE_MAX_RATE_HZ = (line_budget.line_bytes_per_second(115200)
                    / line_budget.packet_size(layouts.ACCEL_ANG_RATE_MAG_ORIENTATION, True))


class Result(NamedTuple):
    """One row of the results table; ``met`` is None for a figure with no target."""

    metric: str
    value: str
    target: str = ''
    met: bool | None = None


# -- statistics: one percentile for everything that reports one (interpolated, q in 0..100) --

def percentile(values: list[float], q: float) -> float:
    """Return the q-th percentile of the values, q in 0..100, interpolated; NaN for none."""
    if not values:
        return math.nan
    ordered = sorted(values)
    position = (len(ordered) - 1) * q / 100.0
    low = math.floor(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (position - low)


class Summary(NamedTuple):
    """Count, mean, p50, p99 and max of a sample."""

    n: int
    mean: float
    p50: float
    p99: float
    max_: float

    def ms(self) -> str:
        """Format as milliseconds: ``p50 / p99 / max``."""
        return (f'{self.p50 * 1e3:.3f} / {self.p99 * 1e3:.3f} / {self.max_ * 1e3:.3f} ms '
                f'(n={self.n})')


def summarise(values: list[float]) -> Summary:
    """Summarise a sample (NaN everywhere when it is empty)."""
    if not values:
        return Summary(0, math.nan, math.nan, math.nan, math.nan)
    return Summary(len(values), sum(values) / len(values), percentile(values, 50),
                   percentile(values, 99), max(values))


def std_dev(values: list[float]) -> float:
    """Return the population standard deviation (NaN for fewer than two values)."""
    if len(values) < 2:
        return math.nan
    mean = sum(values) / len(values)
    return math.sqrt(sum((v - mean) ** 2 for v in values) / len(values))


# -- the machine and the table ---------------------------------------------------------------

def machine_info() -> list[tuple[str, str]]:
    """CPU, cores, OS, Python, rclpy and RMW: what the numbers depend on."""
    cpu = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as handle:
            for line in handle:
                if line.startswith('model name'):
                    cpu = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    rclpy_version = 'unknown'
    for name in ('ros-jazzy-rclpy', 'ros-rclpy', 'rclpy'):
        try:
            rclpy_version = metadata.version(name)
            break
        except metadata.PackageNotFoundError:
            pass
    rmw = os.environ.get('RMW_IMPLEMENTATION') or 'rmw_fastrtps_cpp (default)'
    return [
        ('CPU', cpu),
        ('cores', str(os.cpu_count())),
        ('OS', f'{platform.system()} {platform.release()}'),
        ('Python', platform.python_version()),
        ('rclpy', rclpy_version),
        ('RMW', rmw),
    ]


class OtherLoad:
    """
    How much CPU everything but this process and its children used meanwhile.

    Benchmarks share the machine: this tells whether other work was running.
    The whole machine's busy time comes from /proc/stat; this process's and
    its waited-for children's from os.times().
    """

    def __init__(self) -> None:
        self._start = (self._machine_busy(), self._own(), time.monotonic())

    @staticmethod
    def _machine_busy() -> float:
        try:
            with open('/proc/stat') as handle:
                fields = [int(v) for v in handle.readline().split()[1:]]
        except (OSError, ValueError):
            return math.nan
        idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
        return (sum(fields[:8]) - idle) / os.sysconf('SC_CLK_TCK')

    @staticmethod
    def _own() -> float:
        times = os.times()
        return times.user + times.system + times.children_user + times.children_system

    def cores(self) -> float:
        """Average number of cores other processes kept busy since construction."""
        busy0, own0, wall0 = self._start
        wall = time.monotonic() - wall0
        other = (self._machine_busy() - busy0) - (self._own() - own0)
        return max(other, 0.0) / wall if wall > 0 else math.nan


def markdown_table(results: list[Result]) -> str:
    """Return the results as a Markdown table: metric, value, target, met?."""
    lines = ['| metric | value | target | met? |', '|---|---|---|---|']
    for result in results:
        met = {True: 'yes', False: '**no**', None: '-'}[result.met]
        lines.append(f'| {result.metric} | {result.value} | {result.target or "-"} | {met} |')
    return '\n'.join(lines)


def machine_table() -> str:
    """Return the machine information as a Markdown table."""
    lines = ['| machine | |', '|---|---|']
    lines += [f'| {name} | {value} |' for name, value in machine_info()]
    return '\n'.join(lines)


class RunNote:
    """
    What a long benchmark run says under its table: its command, its length, its load.

    Made when the run starts (the load average and the other processes'
    CPU are measured from then); ``text()`` once it is over.
    """

    def __init__(self, script: str, argv: list[str] | None) -> None:
        self._command = f'python benchmarks/{script} {" ".join(argv or sys.argv[1:])}'.rstrip()
        self._other = OtherLoad()
        self._load_before = os.getloadavg()[0]
        self._started = time.monotonic()

    def text(self, detail: str = '') -> str:
        """Return the note's line, ``detail`` (what was run, how long each) after the command."""
        minutes = (time.monotonic() - self._started) / 60.0
        return (f'- `{self._command}`: {detail}{minutes:.1f} min; load average (1 min) '
                f'{self._load_before:.2f} before, {os.getloadavg()[0]:.2f} after; other '
                f'processes kept {self._other.cores():.2f} of {os.cpu_count()} cores busy on '
                f'average.')


def report(title: str, results: list[Result], notes: list[str] = (),
           output: str | None = None, other_load: OtherLoad | None = None) -> str:
    """Print the results (and machine) as Markdown; also write them to ``output``."""
    notes = list(notes)
    if other_load is not None:
        notes.append(f'Other processes kept {other_load.cores():.2f} of {os.cpu_count()} '
                     f'cores busy on average during the run.')
    text = '\n'.join([f'## {title}', '', machine_table(), '', markdown_table(results), '',
                      *[f'- {note}' for note in notes]]).rstrip() + '\n'
    return emit(text, output)


def emit(text: str, output: str | None) -> str:
    """Print a finished report; also write it to ``output`` under benchmarks/output/."""
    print(text, flush=True)
    if output:
        OUTPUT_DIR.mkdir(parents=True, exist_ok=True)
        path = OUTPUT_DIR / output  # an absolute ``output`` stays as it is
        path.write_text(text)
        shown = path.relative_to(REPO) if path.is_relative_to(REPO) else path
        print(f'(written to {shown})', flush=True)
    return text


# -- the node in this process ----------------------------------------------------------------

class Published(NamedTuple):
    """One Imu message as the node published it, and when publish() returned."""

    timer: int
    read_time: float
    stamp: float
    stamp_sec: int
    stamp_nanosec: int
    time: float


class _PublishedObserver(QuietObserver):
    """Hand (record, read time, stamp) of every published message to ``on_published``."""

    def __init__(self, on_published: Callable[[Any, float, float], None]) -> None:
        self._on_published = on_published
        self._read_time = 0.0

    def read(self, nbytes: int, read_time: float) -> None:
        """Keep the read's time: the records it completes are published next."""
        self._read_time = read_time

    def published(self, record: Any, stamp: float) -> None:
        """Hand the message on with the time of the read that completed it."""
        self._on_published(record, self._read_time, stamp)


class InProcessNode:
    """
    The driver node in this process, spinning as ``ros2 run`` would spin it.

    The executor runs in a thread of its own, the node's reader thread
    publishes, and ``published`` gets one entry per Imu message from the
    hot path's observer (device/hot_path.py, this process's until
    :meth:`close`), told right after ``publish()`` returned: the record's
    timer (to match the ground truth), the time the reader got its last
    byte, the stamp, and ``time.time()`` at that moment, the clock the
    simulator stamps its writes with.
    """

    def __init__(self, port: str, **params: Any) -> None:
        import rclpy
        from rclpy.executors import MultiThreadedExecutor
        from rclpy.parameter import Parameter
        from rclpy.signals import SignalHandlerOptions

        from i3dmgx2_driver.device import realtime
        from i3dmgx2_driver.ros.conversions import stamp_parts
        from i3dmgx2_driver.ros.imu_node import ImuDriverNode

        self._rclpy = rclpy
        self._stamp_parts = stamp_parts
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        params = {'port': port, 'address': ADDRESS, **params}
        self.published: list[Published] = []
        hot_path.observe(_PublishedObserver(self._on_published))
        self.node = ImuDriverNode(
            context=self.context,
            parameter_overrides=[Parameter(name, value=value) for name, value in params.items()])
        # As main.py spins it: several threads, so that a long service call holds only its own,
        # and the start-up heap frozen as main.py freezes it.
        self.executor = MultiThreadedExecutor(num_threads=4, context=self.context)
        self.executor.add_node(self.node)
        realtime.freeze_startup_heap()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name='bench-executor', daemon=True)
        self._thread.start()

    def _on_published(self, record: Any, read_time: float, stamp: float,
                      clock: Any = time.time) -> None:
        now = clock()
        sec, nanosec = self._stamp_parts(stamp)
        self.published.append(Published(record.timer, read_time, stamp, sec, nanosec, now))

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except Exception:  # the context is shut down under us at close()
                break

    def wait_published(self, count: int, timeout: float = 20.0) -> bool:
        """Wait until ``count`` messages were published."""
        deadline = time.monotonic() + timeout
        while len(self.published) < count and time.monotonic() < deadline:
            time.sleep(0.02)
        return len(self.published) >= count

    def wait_quiet(self, quiet: float = 0.5, timeout: float = 10.0) -> None:
        """Wait until nothing has been published for ``quiet`` seconds."""
        deadline = time.monotonic() + timeout
        last = -1
        while time.monotonic() < deadline:
            count = len(self.published)
            if count == last:
                return
            last = count
            time.sleep(quiet)

    def close(self) -> None:
        """Stop the device stream, the executor and the context."""
        self.node.shutdown()
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.executor.shutdown(timeout_sec=0.5)
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)
        hot_path.observe(None)


def stamp_key(sec: int, nanosec: int) -> int:
    """Return a stamp as integer nanoseconds, for matching."""
    return sec * 1_000_000_000 + nanosec


def written_times(truth: list[TruthEntry]) -> dict[int, float]:
    """Timer -> time the packet's last byte was written, for the valid streamed packets."""
    return {e.timer: e.write_time for e in truth
            if e.source == 'stream' and e.valid and e.write_time is not None}


def write_latencies(truth: list[TruthEntry], published: list[Published]) -> list[float]:
    """Seconds from each packet's last byte written to its publish() returned."""
    written = written_times(truth)
    return [p.time - written[p.timer] for p in published if p.timer in written]


def standard_args(description: str, default_seconds: float,
                  more: Callable[[Any], None] | None = None) -> Any:
    """Parse the options every benchmark shares (--seconds); ``more`` adds its own."""
    import argparse
    parser = argparse.ArgumentParser(description=description)
    if more is not None:
        more(parser)
    parser.add_argument('--seconds', type=float, default=default_seconds,
                        help=f'measuring time per run (default {default_seconds:g} s)')
    args = parser.parse_args()
    args.other_load = OtherLoad()
    return args


class TimedNodeProcess(NodeProcess):
    """
    The driver process with its hot-path timings on (device/hot_path.py).

    The node as ``ros2 run`` starts it, or another ``script`` that records
    the same timings (``floor_node.py``), told by ``I3DMGX2_TIMINGS`` where
    to write them; ``params`` are its ROS parameters. Returns once it has
    frozen its start-up heap. After :meth:`stop`, ``rows`` holds one tuple
    per Imu message (hot_path.ROW_FIELDS), ``collections`` every garbage
    collection (generation, start, duration), ``reader`` the reader thread's
    scheduling policy, priority and CPUs, ``opens`` the time of every open of
    the port, ``full_collection`` how long a full collection took at the end (s).
    Not ``timed``: the node alone, nothing recorded (its CPU is all a run
    reads), returned once it streams; ``tree``: the driver of another checkout.
    """

    def __init__(self, port: str, script: str = '', timed: bool = True,
                 tree: Path | None = None, **params: Any) -> None:
        from i3dmgx2_driver.device.hot_path import TIMINGS_ENV

        params = {'port': port, 'address': ADDRESS, **params}
        command = [sys.executable, str(BENCH_DIR / script)] if script else None
        self.out_path = None
        if timed:
            handle, self.out_path = tempfile.mkstemp(prefix='i3dmgx2-bench-', suffix='.json')
            os.close(handle)
        super().__init__(params, command=command, tree=tree,
                         env=ros_env({TIMINGS_ENV: self.out_path} if timed else None))
        self.pid = self.proc.pid
        if not self.wait_for_output('start-up heap frozen' if timed else 'streaming 0x', 30.0):
            output = self.output()
            self.close()
            if timed:
                os.unlink(self.out_path)
            raise RuntimeError(f'{script or "the node"} did not start: {output}')
        self.rows: list[tuple] = []
        self.collections: list[tuple[int, float, float]] = []
        self.reader: dict[str, Any] = {}
        self.opens: list[float] = []
        self.full_collection = math.nan

    def stop(self, timeout: float = 15.0) -> dict:
        """Stop the process as Ctrl-C does; keep the timings it saved."""
        super().stop(timeout=timeout)
        if self.out_path is None:
            self.close()
            return {}
        try:
            with open(self.out_path) as handle:
                document = json.load(handle)
        except (OSError, ValueError) as exc:
            raise RuntimeError(f'no timings saved: {self.output()}') from exc
        finally:
            self.close()
            os.unlink(self.out_path)
        self.rows = [tuple(row) for row in document['rows']]
        self.collections = [tuple(event) for event in document['collections']]
        self.reader = document['reader']
        self.opens = document['opens']
        self.full_collection = document['full_collection']
        return document
