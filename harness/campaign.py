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
The soak and fault campaign: the real node against a simulator that misbehaves.

The node runs as its own process (``harness/instrumented_node.py``: the
real node, with its counters written to a file) on a simulated base station
whose faults change at random all through the run: line noise (garbage, with
and without 0xAA bytes), corrupted checksums and lengths, packets from a
foreign sensor, radio drops and lost commands, jitter, stalls short and long,
unplug and replug, sensor power cycles (streaming again at once, or not), the
sensor ignoring its first request to stream or wanting a polled request
first. A real rclpy subscriber (reliable, deep history) records what the
node publishes. Afterwards every published message is matched, by its exact
values, to the simulator's ground truth, and the node's counters are
reconciled with what the simulator wrote.

Used by ``benchmarks/soak.py`` (ten minutes) and ``test/test_soak_short.py``
(about half a minute in CI). :func:`run_campaign` does everything and returns
the checks and a printable report; the rules are stated in the report.
"""

import bisect
import collections
import dataclasses
import itertools
import json
import os
import random
import shutil
import statistics
import struct
import sys
import tempfile
import threading
import time
from typing import NamedTuple

from harness.instrumented_node import STATS_ENV
from harness.processes import isolate_ros_domain, Listener, NodeProcess, ros_env
from harness.run_config import FaultedNodeConfig
from i3dmgx2_driver.codec.commands import decode_record
from i3dmgx2_driver.codec.errors import CodecError
from i3dmgx2_driver.codec.framing import HEADER_SIZE
from i3dmgx2_driver.codec.layouts import LAYOUTS
from i3dmgx2_driver.codec.orientation import ENU
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.streams import parse as parse_stream, STREAMS
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
from i3dmgx2_driver.ros.conversions import MessageFactory, STANDARD_GRAVITY
from i3dmgx2_driver.simulator import FaultConfig, PtySimulator, SimulatorConfig
from sensor_msgs.msg import Imu

NODE_COMMAND = (sys.executable, '-m', 'harness.instrumented_node')
_KEY = struct.Struct('<6d')
_QUAT = struct.Struct('<4d')
_MARKS = (0xAA, 0x21)


@dataclasses.dataclass
class CampaignConfig(FaultedNodeConfig):
    """
    How long, how fast and how rough the campaign is.

    The seed, address, node timeouts, fault pacing and log: ``FaultedNodeConfig``.
    """

    #: Length of the fault phase (min); a quiet phase follows.
    minutes: float = 10.0
    #: Calculation rate the simulator streams at (its rate_hz override: beyond the device);
    #: None: the rate the node sets with ``data_rate`` (EEPROM divider), at most what the
    #: line carries (the simulator skips a record the line is still busy for, as the device).
    rate_hz: float | None = 500.0
    #: The stream the node asks for, and its data_rate parameter (0: leave the device's).
    stream: str = 'full'
    data_rate: float = 0.0
    #: Warm-up (s) before the RSS baseline: this share of the run, at least ``warmup_min``.
    warmup_fraction: float = 0.15
    warmup_min: float = 10.0
    #: Most RSS growth allowed from the end of warm-up to the end of the run.
    rss_limit: float = 0.10
    #: How long before a close or an unplug a record may still be legitimately unread (s).
    unread_margin: float = 0.5
    #: How far (s) a stamp may be from the steady offset (the median of stamp - true
    #: sample time): within ``stamp_grace`` s of the stream's start or return (a gap,
    #: or the sensor's timer restarted), ``stamp_early_tolerance``; after it,
    #: ``stamp_tolerance`` (issue #23: time stays true through every fault).
    stamp_tolerance: float = 0.001
    stamp_early_tolerance: float = 0.005
    stamp_grace: float = 0.5
    #: Include long stalls (longer than the node's stall recovery: it reopens the port).
    long_stalls: bool = True


def rate_text(cfg: CampaignConfig) -> str:
    """Say what the simulator streams and how fast, for the logs and the report."""
    if cfg.rate_hz is None:
        return (f'stream {cfg.stream!r} at data_rate {cfg.data_rate:g} Hz (the divider the '
                f'node writes; the line rate honoured)')
    return f'stream {cfg.stream!r} at {cfg.rate_hz:g} Hz (simulator rate override)'


class FaultEvent(NamedTuple):
    """One fault the campaign injected."""

    kind: str
    start: float
    end: float
    detail: str


class Sent(NamedTuple):
    """What the campaign keeps of one truth entry (compact: a run has 10^5 of them)."""

    index: int
    write_time: float | None
    valid: bool
    fault: str | None
    address: int
    source: str
    #: Exact published values (accel ENU m/s^2, rate ENU rad/s) of a 0xCC record, packed.
    key: bytes | None
    #: The values a corrupted 0xCC packet would publish if a parser accepted it.
    bad_key: bytes | None
    quat: bytes | None
    timer: int | None
    sample_time: float
    #: 0xAA and 0x21 bytes in the packet (each can become a spurious parser event).
    marks: int
    size: int
    #: Command byte of the record (None: not a streamable record).
    code: int | None = None


def imu_key(accel, rate) -> bytes:
    """Pack what the node publishes for a record, computed exactly as the node does."""
    g = STANDARD_GRAVITY
    return _KEY.pack(accel[0] * g, -accel[1] * g, -accel[2] * g,
                     rate[0], -rate[1], -rate[2])


#: For each stream's record type: the node's own message factory (ENU) and the record's
#: size in a packet, so that every stream's published values are computed as the node does.
_FACTORIES = {
    stream.record_type: (MessageFactory('imu_link', ENU, 0.0, 0.0, 0.0, 0.0, stream),
                         LAYOUTS[stream.code].record_size, stream.code)
    for stream in STREAMS}


def imu_values(record) -> tuple[bytes, bytes] | None:
    """Return the packed (acceleration, rate) and orientation the node publishes, or None."""
    made = _FACTORIES.get(type(record))
    if made is None:
        return None
    factory = made[0]
    key = _KEY.pack(*factory.linear_acceleration(record), *factory.angular_velocity(record))
    return key, _QUAT.pack(*factory.orientation(record)[0])


def compact(entry) -> Sent:
    """Keep the parts of a SentRecord the checks need."""
    record = entry.record
    key = bad_key = quat = code = None
    values = imu_values(record)
    if values is not None:
        key, quat = values
        code = _FACTORIES[type(record)][2]
        if entry.fault == 'checksum':
            size = _FACTORIES[type(record)][1]
            try:
                bad = imu_values(decode_record(entry.packet[HEADER_SIZE:HEADER_SIZE + size]))
                bad_key = bad[0] if bad is not None else None
            except CodecError:
                bad_key = None
    marks = sum(1 for byte in entry.packet if byte in _MARKS)
    return Sent(entry.index, entry.write_time, entry.valid, entry.fault, entry.address,
                entry.source, key, bad_key, quat, entry.timer, entry.sample_time, marks,
                len(entry.packet), code)


class Subscriber(Listener):
    """The harness's rclpy listener, keeping each Imu message's values, stamp and orientation."""

    def __init__(self, depth: int = 10000, topics: tuple[str, ...] = ('imu/raw_data',)) -> None:
        self.rows: list[tuple[bytes, int, bytes, float]] = []
        self._topics = topics
        super().__init__(dict.fromkeys(topics, Imu), depth=depth)

    def _store(self, topic: str, msg: Imu) -> None:
        la, av, o = msg.linear_acceleration, msg.angular_velocity, msg.orientation
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.rows.append((_KEY.pack(la.x, la.y, la.z, av.x, av.y, av.z), stamp,
                          _QUAT.pack(o.x, o.y, o.z, o.w), time.time()))

    @property
    def count(self) -> int:
        """Messages received so far."""
        return len(self.rows)

    def publishers(self) -> int:
        """Return how many publishers of the topic this subscriber's node knows of."""
        return sum(self.node.count_publishers(topic) for topic in self._topics)


class TruthCollector(threading.Thread):
    """Move the simulator's truth into compact form as it is produced."""

    def __init__(self, sim: PtySimulator) -> None:
        super().__init__(name='soak-truth', daemon=True)
        self.sim = sim
        self.entries: list[Sent] = []
        self.missed = 0
        self._next = 0
        self._halt = threading.Event()
        self._lock = threading.Lock()

    def collect(self) -> None:
        """Take whatever is new in the simulator's truth."""
        with self._lock:
            fresh = [e for e in self.sim.truth if e.index >= self._next]
            for entry in fresh:
                if entry.index != self._next:
                    self.missed += entry.index - self._next
                self.entries.append(compact(entry))
                self._next = entry.index + 1

    def run(self) -> None:
        """Collect twice a second until stopped."""
        while not self._halt.wait(0.5):
            self.collect()

    def stop(self) -> None:
        """Stop and take the rest."""
        self._halt.set()
        self.join(5.0)
        self.collect()


class FaultDriver(threading.Thread):
    """Inject random faults into the simulator until told to stop."""

    WEIGHTS = (('unplug', 2.0), ('stall_short', 1.5), ('stall', 2.0), ('stall_long', 0.4),
               ('noise', 3.0), ('quirks', 1.0), ('power_cycle', 1.0))

    def __init__(self, sim: PtySimulator, cfg: CampaignConfig, rng: random.Random) -> None:
        super().__init__(name='soak-faults', daemon=True)
        self.sim = sim
        self.cfg = cfg
        self.rng = rng
        self.events: list[FaultEvent] = []
        #: Power-up times of the sensor's power cycles (simulator wall clock).
        self.power_ups: list[float] = []
        self.unsafe_garbage_bytes = 0
        self.unsafe_garbage_bursts = 0
        self._unsafe = False
        self._garbage_mark = (0, 0)
        self._halt = threading.Event()
        kinds = [k for k, _ in self.WEIGHTS if cfg.long_stalls or k != 'stall_long']
        self._kinds = kinds
        self._weights = [w for k, w in self.WEIGHTS if k in kinds]

    def run(self) -> None:
        """Draw and inject events until stopped."""
        low, high = self.cfg.event_gap
        # Every kind once first, in random order, so that a short run meets them all.
        first = list(self._kinds)
        self.rng.shuffle(first)
        while not self._halt.wait(self.rng.uniform(low, high)):
            kind = first.pop() if first else self.rng.choices(self._kinds, self._weights)[0]
            getattr(self, '_' + kind)()

    def stop(self) -> None:
        """Stop injecting, then switch every fault off and plug the port back."""
        self._halt.set()
        self.join(15.0)
        self._account_garbage()
        start = time.time()
        self.sim.set_faults(FaultConfig())
        self.sim.stall(0.0)
        if not self.sim.plugged:
            self.sim.replug()
        self._unsafe = False
        self.events.append(FaultEvent('all_off', start, time.time(), ''))

    def _sleep(self, seconds: float) -> None:
        self._halt.wait(seconds)

    def _account_garbage(self) -> None:
        stats = self.sim.stats
        now = (stats.garbage_bytes, stats.garbage_bursts)
        if self._unsafe:
            self.unsafe_garbage_bytes += now[0] - self._garbage_mark[0]
            self.unsafe_garbage_bursts += now[1] - self._garbage_mark[1]
        self._garbage_mark = now

    def _unplug(self) -> None:
        seconds = self.rng.uniform(0.2, 2.5)
        start = time.time()
        self.sim.unplug(None)
        detail = f'{seconds:.2f} s'
        if self.rng.random() < 0.3:
            detail += ', sensor power-cycled meanwhile: ' + self._power_cycle_now(
                self.rng.random() < 0.7)
        self._sleep(seconds)
        self.sim.replug()
        self.events.append(FaultEvent('unplug', start, time.time(), detail))

    def _stall_for(self, kind: str, low: float, high: float) -> None:
        seconds = self.rng.uniform(low, high)
        start = time.time()
        self.sim.stall(seconds)
        self._sleep(seconds)
        self.events.append(FaultEvent(kind, start, start + seconds, f'{seconds:.2f} s'))

    def _stall_short(self) -> None:
        self._stall_for('stall_short', 0.05, 0.25)

    def _stall(self) -> None:
        self._stall_for('stall', 0.4, 3.0)

    def _stall_long(self) -> None:
        self._stall_for('stall_long', 4.5, 7.0)

    def _noise(self) -> None:
        rng = self.rng

        def maybe(high: float) -> float:
            return 0.0 if rng.random() < 0.3 else rng.uniform(0.0, high)

        self._account_garbage()
        changes = {
            'garbage_probability': maybe(0.2), 'garbage_safe': rng.random() < 0.5,
            'garbage_max_bytes': rng.randint(1, 16),
            'corrupt_checksum_probability': maybe(0.05),
            'corrupt_length_probability': maybe(0.05), 'foreign_probability': maybe(0.05),
            'drop_probability': maybe(0.05), 'command_loss_probability': maybe(0.3),
            'jitter_ms': maybe(5.0),
        }
        start = time.time()
        self.sim.set_faults(**changes)
        self._unsafe = changes['garbage_safe'] is False and changes['garbage_probability'] > 0
        detail = ', '.join(f'{k}={v:.3g}' if isinstance(v, float) else f'{k}={v}'
                           for k, v in changes.items())
        self.events.append(FaultEvent('noise', start, start, detail))

    def _quirks(self) -> None:
        start = time.time()
        polled_first = self.rng.random() < 0.5
        self.sim.set_faults(ignore_first_continuous=False)
        self.sim.set_faults(ignore_first_continuous=True, needs_polled_first=polled_first)
        self.events.append(FaultEvent('quirks', start, start,
                                      f'ignore first continuous, polled first={polled_first}'))

    def _power_cycle_now(self, streaming: bool) -> str:
        """
        Power-cycle the sensor; return how its timer restarted.

        A real timer restarts from zero, which is behind where it was unless
        the sensor had run for more than half the timer's range (about 109 s)
        since it last wrapped: then zero is *ahead* of it modulo 2^32, and only
        the host's clock can tell a restart from a jump forward. The simulated
        timer restarts at ``clock.timer_start``: set here to 1..100 s behind or
        ahead of the timer now, half the time each, so that short runs meet
        both cases.
        """
        ahead = self.rng.random() < 0.5
        offset = self.rng.uniform(1.0, 100.0) * TICKS_PER_SECOND * (1 if ahead else -1)
        with self.sim.lock:
            clock = self.sim.sensor.clock
            clock.timer_start = (clock.timer_at(time.time()) + round(offset)) % TIMER_MODULUS
        self.sim.power_cycle()
        with self.sim.lock:
            self.power_ups.append(self.sim.sensor.clock.power_up_time)
        if streaming:
            self.sim.set_faults(already_streaming=False)
            self.sim.set_faults(already_streaming=True)
        return (f'timer restarted {offset / TICKS_PER_SECOND:+.1f} s from where it was, '
                + ('streaming at once' if streaming else 'polled'))

    def _power_cycle(self) -> None:
        start = time.time()
        detail = self._power_cycle_now(self.rng.random() < 0.5)
        self.events.append(FaultEvent('power_cycle', start, start, detail))


def read_rss_kib(pid: int) -> int | None:
    """Return the VmRSS of a process (KiB), None if it is gone."""
    try:
        with open(f'/proc/{pid}/status') as handle:
            for line in handle:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def read_json(path: str) -> dict | None:
    """Return a node's counters file, None while it is missing or half written."""
    try:
        with open(path) as handle:
            return json.load(handle)
    except (OSError, ValueError):
        return None


@dataclasses.dataclass
class RunData:
    """Everything a run produced, for the analysis."""

    cfg: CampaignConfig
    truth: list[Sent]
    truth_missed: int
    messages: list[tuple[bytes, int, bytes, float]]
    events: list[FaultEvent]
    node_stats: dict
    sim_stats: dict
    host_log: list
    rss: list[tuple[float, int]]
    warmup_end: float
    fault_end: float
    alive_at_end: bool
    exit_code: int | None
    exit_seconds: float
    recovered: int
    unsafe_garbage_bytes: int
    unsafe_garbage_bursts: int
    divider: int
    power_ups: list[float]
    node_output: str
    started: float
    #: When the node stopped reading for good, if known (a managed node's deactivate);
    #: None: its last port event, or the end of the faults.
    end: float | None = None


def run_campaign(cfg: CampaignConfig) -> 'CampaignResult':
    """Run the whole campaign; return its checks and report."""
    log = cfg.log or (lambda text: None)
    isolate_ros_domain()
    workdir = tempfile.mkdtemp(prefix='i3dmgx2-soak-')
    stats_path = os.path.join(workdir, 'node_stats.json')
    duration = cfg.minutes * 60.0
    sim = PtySimulator(SimulatorConfig(
        address=cfg.address, seed=cfg.seed, rate_hz=cfg.rate_hz,
        limit_to_line_rate=cfg.rate_hz is None,
        truth_limit=int((cfg.rate_hz or 400.0) * 60) + 20000))
    sim.start()
    # The port is missing until the subscriber has matched the node's publisher:
    # nothing published can then be lost in discovery, and the node starts by
    # retrying to open a port that is not there.
    sim.unplug(None)
    collector = TruthCollector(sim)
    collector.start()
    subscriber = Subscriber()
    params = {'port': sim.port, 'address': cfg.address, 'read_timeout': cfg.read_timeout,
              'reconnect_interval': cfg.reconnect_interval,
              'qos_overrides./imu/raw_data.publisher.depth': 1000,
              'qos_overrides./imu/raw_data.publisher.reliability': 'reliable',
              'temperature_period': cfg.temperature_period,
              'stream': cfg.stream, 'data_rate': float(cfg.data_rate)}
    node = NodeProcess(params, command=NODE_COMMAND, env=ros_env({STATS_ENV: stats_path}))
    rss: list[tuple[float, int]] = []
    driver = FaultDriver(sim, cfg, random.Random(cfg.seed * 7919 + 1))
    try:
        deadline = time.monotonic() + 60.0
        while subscriber.publishers() < 1 and time.monotonic() < deadline:
            if node.proc.poll() is not None:
                raise RuntimeError(f'the node exited at start:\n{node.output()}')
            time.sleep(0.1)
        time.sleep(1.0)
        sim.replug()
        deadline = time.monotonic() + 60.0
        while subscriber.count == 0 and time.monotonic() < deadline:
            time.sleep(0.1)
        if subscriber.count == 0:
            raise RuntimeError(f'no message within 60 s:\n{node.output()}')
        started = time.time()
        log(f'streaming; domain {os.environ.get("ROS_DOMAIN_ID")}, node pid {node.proc.pid}, '
            f'{cfg.minutes:g} min of faults at {rate_text(cfg)}, seed {cfg.seed}')
        warmup_end = started + max(cfg.warmup_min, cfg.warmup_fraction * duration)
        fault_end = started + duration
        driver.start()
        next_report = started + 60.0
        while time.time() < fault_end and node.proc.poll() is None:
            sample = read_rss_kib(node.proc.pid)
            if sample is not None:
                rss.append((time.time(), sample))
            if time.time() >= next_report:
                next_report += 60.0
                log(f'  {time.time() - started:5.0f} s: {subscriber.count} messages, '
                    f'{len(driver.events)} fault events, RSS {sample} KiB')
            time.sleep(1.0)
        driver.stop()
        before = subscriber.count
        quiet_end = time.time() + cfg.quiet
        while time.time() < quiet_end and node.proc.poll() is None:
            sample = read_rss_kib(node.proc.pid)
            if sample is not None:
                rss.append((time.time(), sample))
            time.sleep(0.5)
        recovered = subscriber.count - before
        alive = node.proc.poll() is None
        exit_code, exit_seconds = node.stop(timeout=15.0)
        final = None
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            final = read_json(stats_path)
            if final and final.get('final'):
                break
            time.sleep(0.1)
        final = final or {}
        published = final.get('stats', {}).get('published')
        deadline = time.monotonic() + 15.0
        while published is not None and subscriber.count < published \
                and time.monotonic() < deadline:
            time.sleep(0.1)
        collector.stop()
        data = RunData(
            cfg=cfg, truth=collector.entries, truth_missed=collector.missed,
            messages=list(subscriber.rows), events=list(driver.events), node_stats=final,
            sim_stats=sim.stats.as_dict(), host_log=sim.host_log, rss=rss,
            warmup_end=warmup_end, fault_end=fault_end, alive_at_end=alive,
            exit_code=exit_code, exit_seconds=exit_seconds, recovered=recovered,
            unsafe_garbage_bytes=driver.unsafe_garbage_bytes,
            unsafe_garbage_bursts=driver.unsafe_garbage_bursts,
            divider=sim.sensor.eeprom.get(0xFCA2, 512), power_ups=list(driver.power_ups),
            node_output=node.output(),
            started=started)
    finally:
        # Each step on its own: a failure in one must not leave the node process behind.
        for step in (lambda: driver.is_alive() and driver.stop(), node.close,
                     subscriber.close, lambda: collector.is_alive() and collector.stop(),
                     sim.stop, lambda: shutil.rmtree(workdir, ignore_errors=True)):
            try:
                step()
            except Exception as exc:  # keep cleaning up; say what went wrong
                print(f'soak cleanup: {type(exc).__name__}: {exc}', file=sys.stderr)
    return analyse(data)


# -- analysis ---------------------------------------------------------------------------------


class Check(NamedTuple):
    """One pass/fail verdict with its evidence."""

    name: str
    ok: bool
    detail: str


@dataclasses.dataclass
class CampaignResult:
    """The verdicts and the report of one run."""

    checks: list[Check]
    report: str
    #: The run's figures by name (sent, published, received, missing, ...), for a summary.
    figures: dict = dataclasses.field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Whether every check passed."""
        return all(check.ok for check in self.checks)

    def failures(self) -> list[Check]:
        """Return the checks that failed."""
        return [check for check in self.checks if not check.ok]


class Windows:
    """When the node was reading the port, from its own port events."""

    def __init__(self, port_events: list, unplugs: list[float], end: float,
                 margin: float, settle: float = 0.05) -> None:
        by_conn: dict[int, dict] = collections.defaultdict(
            lambda: {'flush': [], 'anchor': [], 'close': None, 'open': None})
        for kind, t, conn in port_events:
            entry = by_conn[conn]
            if kind in ('flush', 'anchor'):
                entry[kind].append(t)
            else:
                entry[kind] = t
        self.flushes = sorted(t for e in by_conn.values() for t in e['flush'])
        self.opens = sorted(e['open'] for e in by_conn.values() if e['open'] is not None)
        #: Every time the node started afresh (re-anchored: its reader publishes from then on).
        self.anchors = sorted(t for e in by_conn.values() for t in e['anchor'])
        self.spans: list[tuple[float, float]] = []
        for entry in by_conn.values():
            if entry['anchor']:
                close = entry['close'] if entry['close'] is not None else end
                self.spans.append((entry['anchor'][-1], close))
        self.spans.sort()
        self.starts = [s for s, _ in self.spans]
        self.unplugs = sorted(unplugs)
        self.margin = margin
        self.settle = settle

    def read(self, t: float | None) -> bool:
        """Whether bytes written at ``t`` were surely read by the node (see the rules)."""
        if t is None:
            return False
        i = bisect.bisect_right(self.starts, t) - 1
        if i < 0:
            return False
        start, close = self.spans[i]
        if not start + self.settle <= t <= close - self.margin:
            return False
        j = bisect.bisect_left(self.unplugs, start)
        return not (j < len(self.unplugs) and self.unplugs[j] <= t + self.margin)

    def near_flush(self, t: float | None, width: float = 0.1) -> bool:
        """Whether ``t`` is within ``width`` of a flush or open of the port."""
        if t is None:
            return False
        for times in (self.flushes, self.opens):
            i = bisect.bisect_left(times, t - width)
            if i < len(times) and times[i] <= t + width:
                return True
        return False


def expected_gaps(published: list[Sent], windows: Windows, divider: int,
                  power_ups: list[float]) -> tuple[int, int]:
    """
    Return the (lost, device resets) the node should count over the published records.

    Two consecutive published records straddle a power-up of the sensor or
    do not. If they do, the node counts a device reset, whether or not it
    reconnected in between: its clock checks the first record of every new
    link against the fit (device/sample_clock.py). If they do not, and both
    lie between the same two anchors of the node (it forgets the last record
    at each: every connection, and again when a reconnect to a known sensor
    fell back to the full dialogue), it counts ``round(step / (384 *
    divider)) - 1`` lost records when that is positive, ``step`` being the
    timer step in ticks (its own formula, for the rate the divider gives).
    """
    expected = 384 * divider
    ups = sorted(power_ups)
    lost = resets = 0
    last = None
    span = None
    for sent in published:
        i = bisect.bisect_right(windows.anchors, sent.write_time) - 1
        if last is not None:
            j = bisect.bisect_right(ups, last.sample_time)
            if j < len(ups) and ups[j] <= sent.sample_time:
                resets += 1
            elif i == span:
                gap = round(((sent.timer - last.timer) % TIMER_MODULUS) / expected) - 1
                lost += max(gap, 0)
        span, last = i, sent
    return lost, resets


def stamp_verdict(matched: list[tuple[Sent, tuple]], cfg: CampaignConfig) -> tuple[bool, str]:
    """
    Judge the stamp errors as a series: steady after every start and return.

    A return is a published record sampled more than 0.1 s after the one
    before it, or whose timer does not follow from that one's (the sensor
    restarted): the stamps may start afresh there, within
    ``stamp_early_tolerance`` for ``stamp_grace`` s.
    """
    if not matched:
        return True, 'no stamps to judge'
    series = [(sent.sample_time, row[1] * 1e-9 - sent.sample_time, sent.timer)
              for sent, row in matched]
    # How late each record left the simulator after its sample time (the line's queue).
    delays = [(sent.write_time or sent.sample_time) - sent.sample_time for sent, _ in matched]
    steady = statistics.median(e for _, e, _ in series)
    usual = statistics.median(delays)
    grace_from = series[0][0]
    # In a grace the stamps start from the first records' arrival: one the simulator wrote
    # late (its thread descheduled on a loaded machine) moves them by as much, and no
    # receiver could know better then. That lateness is allowed on top, in that grace.
    grace_late = max(0.0, delays[0] - usual)
    returns = 0
    worst = worst_early = 0.0
    bad = []
    previous = None
    for (t, e, timer), delay in zip(series, delays, strict=True):
        if previous is not None:
            dt = t - previous[0]
            steps = ((timer - previous[2]) % TIMER_MODULUS / TICKS_PER_SECOND
                     if timer is not None and previous[2] is not None else dt)
            if dt > 0.1 or abs(steps - dt) > 0.05:
                grace_from = t
                grace_late = max(0.0, delay - usual)
                returns += 1
        previous = (t, e, timer)
        off = abs(e - steady)
        early = t - grace_from < cfg.stamp_grace
        if early:
            worst_early = max(worst_early, off)
        else:
            worst = max(worst, off)
        if off > (cfg.stamp_early_tolerance + grace_late if early else cfg.stamp_tolerance):
            bad.append(f'{off * 1e3:.2f} ms at {t - series[0][0]:.2f} s'
                       + (' (in a grace)' if early else '')
                       + f' written {delay * 1e3:.1f} ms after its sample time')
    detail = (f'stamp - true sample time: steady {steady * 1e3:+.3f} ms; worst off it '
              f'{worst * 1e3:.3f} ms after the {cfg.stamp_grace:g}-s graces (limit '
              f'{cfg.stamp_tolerance * 1e3:g}), {worst_early * 1e3:.2f} ms in them (limit '
              f'{cfg.stamp_early_tolerance * 1e3:g}, plus how much later than usual the '
              f"simulator wrote the grace's first record); {returns} returns; "
              f'{len(bad)} stamps over' + (f', e.g. {"; ".join(bad[:5])}' if bad else ''))
    return not bad, detail


def analyse(data: RunData) -> CampaignResult:
    """Match what was published with the truth; reconcile the counters; judge."""
    cfg = data.cfg
    checks: list[Check] = []
    lines: list[str] = []
    node = data.node_stats or {}
    nstats = node.get('stats', {})
    parser = node.get('parser', {})
    sup = node.get('supervisor', {})
    sim = data.sim_stats
    address = cfg.address
    end = data.end if data.end is not None else max(
        [e[1] for e in node.get('port_events', [])] + [data.fault_end])
    unplugs = [e.start for e in data.events if e.kind == 'unplug']
    windows = Windows(node.get('port_events', []), unplugs, end, cfg.unread_margin)
    first_open = windows.opens[0] - 0.1 if windows.opens else data.started

    def written(s: Sent) -> bool:
        return s.write_time is not None and s.write_time >= first_open

    def check(name: str, ok: bool, detail: str) -> None:
        checks.append(Check(name, bool(ok), detail))

    # -- alive, exit, memory --------------------------------------------------------------
    check('node alive at the end', data.alive_at_end,
          'the node process ran through every fault' if data.alive_at_end
          else 'the node process died:\n' + data.node_output[-3000:])
    check('clean exit on SIGINT', data.exit_code == 0,
          f'exit code {data.exit_code} after {data.exit_seconds:.2f} s')
    check('stream recovered after the faults', data.recovered > 0,
          f'{data.recovered} messages in the {cfg.quiet:g} s quiet phase')
    base = [kib for t, kib in data.rss if data.warmup_end <= t <= data.warmup_end + 10.0]
    tail = [kib for _, kib in data.rss[-10:]]
    if base and tail:
        b, e = statistics.median(base), statistics.median(tail)
        growth = e / b - 1.0
        peak = max(kib for _, kib in data.rss)
        check('RSS growth after warm-up', growth <= cfg.rss_limit,
              f'{b / 1024:.1f} MiB after warm-up -> {e / 1024:.1f} MiB at the end '
              f'({growth * 100:+.1f} %, limit {cfg.rss_limit * 100:.0f} %); peak '
              f'{peak / 1024:.1f} MiB; {len(data.rss)} samples')
    else:
        check('RSS growth after warm-up', False, 'not enough RSS samples')
    check('ground truth complete', data.truth_missed == 0,
          f'{len(data.truth)} truth entries, {data.truth_missed} missed by the collector')

    # -- matching -------------------------------------------------------------------------
    by_key: dict[bytes, Sent] = {}
    bad_keys: dict[bytes, Sent] = {}
    for sent in data.truth:
        if sent.key is not None:
            by_key.setdefault(sent.key, sent)
        if sent.bad_key is not None:
            bad_keys.setdefault(sent.bad_key, sent)
    seen: collections.Counter = collections.Counter()
    matched: list[tuple[Sent, tuple]] = []
    unknown = invalid = 0
    invalid_examples: list[str] = []
    for row in data.messages:
        sent = by_key.get(row[0])
        if sent is None:
            unknown += 1
            bad = bad_keys.get(row[0])
            if bad is not None and len(invalid_examples) < 5:
                invalid_examples.append(f'corrupted packet #{bad.index} ({bad.fault})')
            continue
        seen[sent.index] += 1
        matched.append((sent, row))
        if not (sent.valid and sent.address == address):
            invalid += 1
            if len(invalid_examples) < 5:
                invalid_examples.append(f'#{sent.index} ({sent.fault}, address '
                                        f'{sent.address}, {sent.source})')
    duplicates = {i: n for i, n in seen.items() if n > 1}
    # Records of another stream (a sensor power-cycled into its EEPROM auto-start) are
    # the node's to count, not to publish.
    code = parse_stream(cfg.stream).code

    def ours(s: Sent) -> bool:
        return s.key is not None and s.valid and s.address == address \
            and s.code in (None, code)

    # A polled request of the stream's own record (the start-up's two polled requests)
    # takes the first such record after it as its reply, whether the sensor answered it
    # or was streaming already (a stall ate the stop): that record is claimed, not lost.
    polled = sorted(h.time for h in data.host_log
                    if h.command is not None and h.command.code == code)
    ours_sorted = sorted((s.write_time, s.index) for s in data.truth
                         if ours(s) and s.write_time is not None)
    claimed = set()
    for p in polled:
        i = bisect.bisect_right(ours_sorted, (p, float('inf')))
        if i < len(ours_sorted):
            claimed.add(ours_sorted[i][1])
    must = [s for s in data.truth if ours(s) and windows.read(s.write_time)
            and s.index not in claimed]
    may = [s for s in data.truth if ours(s) and s.write_time is not None
           and (not windows.read(s.write_time) or s.index in claimed)]
    missing = [s for s in must if s.index not in seen]
    may_published = sum(1 for s in may if s.index in seen)
    published = nstats.get('published')
    check('every message reached the subscriber', published == len(data.messages),
          f'node published {published}, subscriber received {len(data.messages)}')
    check('every message is a record the sensor sent', unknown == 0,
          f'{unknown} messages match no record of the truth'
          + (f' ({"; ".join(invalid_examples)})' if invalid_examples else ''))
    check('no corrupted, foreign or unwritten record published', invalid == 0,
          f'{invalid} published records were not valid packets from address {address}'
          + (f': {"; ".join(invalid_examples)}' if invalid_examples else ''))
    check('no record published twice', not duplicates,
          f'{len(duplicates)} records published more than once'
          + (f', e.g. {sorted(duplicates.items())[:5]}' if duplicates else ''))
    position = {sent.index: i for i, sent in enumerate(data.truth)}

    def before(sent: Sent) -> str:
        # What the line carried just before a missing record: the faults that may explain it.
        i = position.get(sent.index, 0)
        return ', '.join(f'#{p.index} {p.source}/{p.fault or "ok"}/{p.address}'
                         for p in data.truth[max(0, i - 3):i])

    port_events = node.get('port_events', [])

    def around(sent: Sent) -> str:
        # The node's port events near a missing record: a flush or close may explain it.
        return ', '.join(f'{kind} {t - sent.write_time:+.3f}' for kind, t, _ in port_events
                         if abs(t - sent.write_time) < 1.0)

    examples = '; '.join(f'#{s.index} written {s.write_time - data.started:.3f} s after '
                         f'[{before(s)}], port events [{around(s)}]' for s in missing[:5])
    check('every valid record read by the node published', not missing,
          f'{len(must)} valid records written while the node was reading: '
          f'{len(must) - len(missing)} published, {len(missing)} missing'
          + (f' ({examples})' if missing else ''))
    order = [sent.index for sent, _ in matched]
    out_of_order = sum(1 for a, b in itertools.pairwise(order) if b <= a)
    check('published in the order sent', out_of_order == 0,
          f'{out_of_order} messages arrived before one sent earlier')
    wrong_quat = sum(1 for sent, row in matched if row[2] != sent.quat)
    check('orientation exact', wrong_quat == 0,
          f'{wrong_quat} of {len(matched)} orientations differ from the Shepperd '
          f'quaternion the codec computes from the record matrix (ENU)')
    check('stamps true through every fault', *stamp_verdict(matched, cfg))

    # -- counters -------------------------------------------------------------------------
    def count(pred, only_read: bool) -> int:
        return sum(1 for s in data.truth if pred(s)
                   and (windows.read(s.write_time) if only_read else written(s)))

    def fault_is(name: str):
        return lambda s: s.fault == name

    corrupted = [s for s in data.truth if s.fault in ('checksum', 'length') and written(s)]
    marks_corrupt = sum(s.marks - 1 for s in corrupted)
    tail_marks = sum(s.marks for s in data.truth
                     if s.write_time is not None and windows.near_flush(s.write_time))
    pings_failed = sum(1 for h in data.host_log if h.outcome == 'ping failed')
    acks_sent = [h for h in data.host_log if h.kind == 'packet']
    # Bytes that may start a spurious ACK/NACK (the parser reports no answers from
    # inside a packet that failed its checksum or length): 0xAA/0x21 garbage, and
    # the tail of a packet cut by a flush, whose start is gone.
    stray = data.unsafe_garbage_bytes + tail_marks
    rows = []

    def bounds(name: str, value: int | None, low: int, high: int, rule: str) -> None:
        ok = value is not None and low <= value <= high
        rows.append((name, value, low, high, ok, rule))
        check(f'counter {name} reconciles', ok, f'{value} in [{low}, {high}]: {rule}')

    c_read = count(fault_is('checksum'), True)
    bounds('checksum_failures', parser.get('checksum_failures'), c_read,
           count(fault_is('checksum'), False),
           'each checksum-corrupted packet the node read is one failure, no other')
    bounds('length_failures', parser.get('length_failures'),
           count(fault_is('length'), True),
           count(fault_is('length'), False) + stray + marks_corrupt,
           'each length-corrupted packet read is one; any other 0xAA byte (in 0xAA garbage, '
           'inside a corrupted packet, in a packet cut by a flush) may add one')
    bounds('foreign_frames', parser.get('foreign_frames'), count(fault_is('foreign'), True),
           count(fault_is('foreign'), False),
           'each foreign packet read is one, no other')
    bounds('good_frames', parser.get('good_frames'),
           count(lambda s: s.valid and s.address == address, True),
           count(lambda s: s.valid and s.address == address, False),
           'each valid packet from our address read (stream and replies) is one, no other')
    acks_read = sum(1 for h in acks_sent if windows.read(h.time))
    acks_all = sum(1 for h in acks_sent if h.time >= first_open)
    bounds('acks', parser.get('acks'), max(0, acks_read - data.unsafe_garbage_bursts),
           acks_all + stray,
           'each ACK the base station wrote while the node read is one (less one per 0xAA-'
           'garbage burst, whose 0x07 may follow it); each 0xAA of 0xAA-garbage or of a '
           'packet cut by a flush may add one, none inside a corrupted packet')
    bounds('nacks', parser.get('nacks'), 0,
           sim.get('nacks', 0) + pings_failed + stray,
           'NACKs written, failed-ping answers arriving late, and 0x21 bytes of 0xAA-garbage '
           'or of a packet cut by a flush are the only ones (none inside a corrupted packet)')
    bytes_read = sum(s.size for s in data.truth if windows.read(s.write_time))
    bounds('bytes_in', parser.get('bytes_in'), bytes_read, sim.get('bytes_written', 0),
           'at least every packet written while the node read, at most all bytes written')
    skipped_low = sum(s.size - s.marks for s in data.truth
                      if s.fault in ('checksum', 'length') and windows.read(s.write_time))
    bounds('bytes_skipped', parser.get('bytes_skipped'), skipped_low,
           parser.get('bytes_in', 0),
           'at least the bytes of the corrupted packets read, less their 0xAA/0x21 bytes')
    published_sorted = sorted((s for s, _ in matched if s.index not in duplicates),
                              key=lambda s: s.index)
    lost, resets = expected_gaps(published_sorted, windows, data.divider, data.power_ups)
    bounds('lost', nstats.get('lost'), lost, lost,
           f'timer steps between published records of one connection and one power-up, '
           f'as cycles of the divider ({data.divider}) less one: exact')
    bounds('device_resets', nstats.get('device_resets'), resets, resets,
           'published records of one connection on either side of a sensor power-up: exact')
    check('nothing left unpublished', nstats.get('unpublished', 0) == 0,
          f'{nstats.get("unpublished")} records dropped by a failed publish')

    # -- report ---------------------------------------------------------------------------
    kinds = collections.Counter(e.kind for e in data.events)
    lines.append('== i3dmgx2 soak and fault campaign ==')
    lines.append(f'fault phase {cfg.minutes:g} min at {rate_text(cfg)}, seed {cfg.seed}, '
                 f'node read_timeout {cfg.read_timeout:g} s, reconnect_interval '
                 f'{cfg.reconnect_interval:g} s, temperature_period '
                 f'{cfg.temperature_period:g} s, then {cfg.quiet:g} s quiet')
    lines.append('fault events: ' + ', '.join(f'{k} {n}' for k, n in sorted(kinds.items())))
    for event in data.events:
        if 'power' in event.detail or event.kind == 'power_cycle':
            lines.append(f'  {event.start - data.started:7.2f} s {event.kind}: {event.detail}')
    lines.append(f'node: {sup.get("connections")} connections ({sup.get("reconnects")} '
                 f'reconnects), {sup.get("stalls")} stalls, published {published}, '
                 f'lost {nstats.get("lost")}, device resets {nstats.get("device_resets")}, '
                 f'other records {nstats.get("other_records")}')
    lines.append('parser: ' + ', '.join(f'{k} {v}' for k, v in sorted(parser.items())))
    lines.append('simulator: ' + ', '.join(f'{k} {v}' for k, v in sorted(sim.items()) if v))
    lines.append(f'unsafe garbage (with 0xAA/0x21/0x02/0x07): {data.unsafe_garbage_bursts} '
                 f'bursts, {data.unsafe_garbage_bytes} bytes')
    lines.append(f'valid 0x{code:02X} records from address {address}: {len(must)} written '
                 f'while the node read (must be published once), {len(may)} written when it '
                 f'may not have (unplugged, flushed at a (re)open, just before a close: '
                 f'{may_published} of them published, at most once each)')
    lines.append('')
    lines.append('Reconciliation rules. "Read" means written whole at least '
                 f'{windows.settle * 1e3:.0f} ms after the node last started its reader afresh '
                 f'on a connection (after the stop-and-flush of the full start-up, or the '
                 f'flush of a reconnect to the known sensor) and at least '
                 f'{cfg.unread_margin:g} s before the close of that connection or the next '
                 f'unplug; "written" means written whole after the node '
                 f'first opened the port. A record written at any other time may be lost '
                 f'legitimately (unplugged, flushed by the stop-and-flush at a (re)open, '
                 f'unread at a close); stalls and drops are never written.')
    for name, value, low, high, ok, rule in rows:
        lines.append(f'  {"ok  " if ok else "FAIL"} {name:18s} {value!s:>9s} in '
                     f'[{low}, {high}]  -- {rule}')
    lines.append('')
    lines.append('Checks:')
    for item in checks:
        if not item.name.startswith('counter '):
            lines.append(f'  {"PASS" if item.ok else "FAIL"} {item.name}: {item.detail}')
    failed = [c for c in checks if not c.ok]
    lines.append('')
    lines.append('RESULT: ' + ('PASS' if not failed else
                               f'FAIL ({len(failed)} checks: '
                               + ', '.join(c.name for c in failed) + ')'))
    figures = {
        'sent': sum(1 for s in data.truth if ours(s) and s.write_time is not None),
        'must': len(must), 'published': published, 'received': len(data.messages),
        'missing': len(missing), 'duplicated': len(duplicates), 'corrupted': invalid + unknown,
        'lost_counted': nstats.get('lost'), 'events': len(data.events)}
    return CampaignResult(checks, '\n'.join(lines), figures)
