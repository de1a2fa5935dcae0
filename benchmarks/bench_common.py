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
What only the benchmarks share: the node timed from inside, latencies, the machine, the note.

The timed benchmarks run the simulated device in a process of its own
(``harness.processes.SimProcess``), as a real device is, and read its
ground truth when it stops: the time each packet's last byte was written and
the time its sample was taken, keyed by the device timer. The node runs as
the real executable with its hot-path timings on (:class:`TimedNodeProcess`),
subscribers in another process (``harness.processes.SubscriberProcess``).
The processes are ``harness/``'s, which the tests use too; importing this
module puts the repository on the path for them. The statistics
(percentiles, summaries) are the benchmarks' alone: here.

Benchmarks print numbers; they never fail on speed.
"""

from importlib import metadata
import json
import math
import os
from pathlib import Path
import platform
import sys
import tempfile
import time
from typing import Any, NamedTuple

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
OUTPUT_DIR = BENCH_DIR / 'output'
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from harness.processes import (  # noqa: E402 - the repository is on the path from here on
    ADDRESS, BENCHMARK_DOMAINS, NodeProcess, reserve_ros_domain, ros_env,
)
from i3dmgx2_driver.codec import layouts, line_budget  # noqa: E402
# A benchmark's ROS domain is never one a test run draws (harness.processes.TEST_DOMAINS):
# a benchmark's node still publishing must not reach the tests running beside it.
reserve_ros_domain(BENCHMARK_DOMAINS)

#: Highest rate of 0xCC packets (88 bytes through the base station) a 115200-baud line
#: carries (11,520 bytes/s), from the codec's layout table.
LINE_MAX_RATE_HZ = (line_budget.line_bytes_per_second(115200)
                    / line_budget.packet_size(layouts.ACCEL_ANG_RATE_MAG_ORIENTATION, True))
#: A USB-serial adapter in low-latency mode hands the host what it holds once a USB frame (s).
USB_FRAME_S = 1e-3


def line_pieces(line: str) -> dict[str, Any]:
    """
    Return the simulator's settings for how the port hands over a packet (SimulatorConfig).

    ``pty``: the simulator's own, each packet in one to three pieces at once;
    ``usb``: as a USB-serial adapter in low-latency mode does at 115200 baud,
    a piece a USB frame (about 11.5 bytes), so a 0xCC packet in eight pieces.
    """
    if line == 'pty':
        return {}
    per_frame = line_budget.line_bytes_per_second(115200) * USB_FRAME_S
    pieces = math.ceil(
        line_budget.packet_size(layouts.ACCEL_ANG_RATE_MAG_ORIENTATION, True) / per_frame)
    return {'chunks': (pieces, pieces), 'chunk_gap_s': USB_FRAME_S}


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


def _machine_busy() -> float:
    """Return the whole machine's busy CPU seconds so far (/proc/stat); NaN if unreadable."""
    try:
        with open('/proc/stat') as handle:
            fields = [int(v) for v in handle.readline().split()[1:]]
    except (OSError, ValueError):
        return math.nan
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return (sum(fields[:8]) - idle) / os.sysconf('SC_CLK_TCK')


def _own() -> float:
    """Return the CPU seconds of this process and its waited-for children so far."""
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


def machine_table() -> str:
    """Return the machine information as a Markdown table."""
    lines = ['| machine | |', '|---|---|']
    lines += [f'| {name} | {value} |' for name, value in machine_info()]
    return '\n'.join(lines)


class RunNote:
    """
    What a benchmark run says under its table: its command, its length, its load.

    Benchmarks share the machine: the note tells whether other work was
    running. Made when the run starts (the load average and the CPU the rest
    of the machine used, its busy time less this process's and its
    children's, are measured from then); ``text()`` once it is over.
    """

    def __init__(self, script: str, argv: list[str] | None) -> None:
        self._command = f'python benchmarks/{script} {" ".join(argv or sys.argv[1:])}'.rstrip()
        self._load_before = os.getloadavg()[0]
        self._start = (_machine_busy(), _own(), time.monotonic())

    def text(self, detail: str = '') -> str:
        """Return the note's line, ``detail`` (what was run, how long each) after the command."""
        busy0, own0, wall0 = self._start
        wall = time.monotonic() - wall0
        other = max((_machine_busy() - busy0) - (_own() - own0), 0.0) / wall if wall else 0.0
        return (f'- `{self._command}`: {detail}{wall / 60.0:.1f} min; load average (1 min) '
                f'{self._load_before:.2f} before, {os.getloadavg()[0]:.2f} after; other '
                f'processes kept {other:.2f} of {os.cpu_count()} cores busy on average.')


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


def stamp_key(sec: int, nanosec: int) -> int:
    """Return a stamp as integer nanoseconds, for matching."""
    return sec * 1_000_000_000 + nanosec


class TimedNodeProcess(NodeProcess):
    """
    The driver process with its hot-path timings on (device/hot_path.py).

    The node as ``ros2 run`` starts it, or another ``script`` that records
    the same timings (``floor_node.py``), told by ``I3DMGX2_TIMINGS`` where
    to write them; ``params`` are its ROS parameters. Returns once it has
    frozen its start-up heap. After :meth:`stop`, ``rows`` holds one tuple
    per Imu message (hot_path.ROW_FIELDS), ``collections`` every garbage
    collection (generation, start, duration), ``reader`` the reader thread's
    scheduling policy, priority and CPUs, ``full_collection`` how long a full
    collection took at the end (s). ``observed``: the node runs as
    ``harness/instrumented_node.py`` runs it, and ``opens`` holds the time of
    every open of the port, as that observer of the rig's noted it.
    ``stages``: its parse and stamp marked too (hot_path.STAGES_ENV). Not
    ``timed``: the node alone, nothing recorded (its CPU is all a run reads),
    returned once it streams; ``tree``: the driver of another checkout.
    """

    def __init__(self, port: str, script: str = '', timed: bool = True,
                 tree: Path | None = None, observed: bool = False, stages: bool = False,
                 **params: Any) -> None:
        from harness.instrumented_node import STATS_ENV
        from i3dmgx2_driver.device.hot_path import STAGES_ENV, TIMINGS_ENV

        params = {'port': port, 'address': ADDRESS, **params}
        command = [sys.executable, str(BENCH_DIR / script)] if script else None
        env: dict[str, str] = {}
        self.out_path = self.stats_path = None
        if timed:
            handle, self.out_path = tempfile.mkstemp(prefix='i3dmgx2-bench-', suffix='.json')
            os.close(handle)
            env[TIMINGS_ENV] = self.out_path
            if stages:
                env[STAGES_ENV] = '1'
        if observed:
            command = [sys.executable, '-m', 'harness.instrumented_node']
            handle, self.stats_path = tempfile.mkstemp(prefix='i3dmgx2-stats-', suffix='.json')
            os.close(handle)
            env[STATS_ENV] = self.stats_path
        super().__init__(params, command=command, tree=tree, env=ros_env(env or None))
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
        self.full_collection = document['full_collection']
        if self.stats_path is not None:
            with open(self.stats_path) as handle:
                events = json.load(handle).get('port_events', [])
            os.unlink(self.stats_path)
            self.opens = [at for kind, at, _ in events if kind == 'open']
        return document
