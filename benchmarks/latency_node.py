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
The real driver process, timed from inside: every sample's path, and the collector.

Runs ``i3dmgx2_driver.ros.main.main()`` (the very code ``ros2 run`` runs) in
a process of its own, with observers added from outside: the node's
``on_published`` hook notes, for every Imu message, the record's timer, the
time its last byte was read and ``time.time()`` right after ``publish()``
returned; ``gc.callbacks`` notes every collection and how long it took. With
``--stages`` the hot path is timed stage by stage (select returned, read
returned, parsed, stamped, packed, published) by thin wrappers around the
functions that do each step; they cost about a microsecond a sample, so
lever comparisons run without them. Prints ``ready`` after the first message;
on SIGTERM, SIGINT or end of standard input the node shuts down as it always
does and the rows are written as JSON to ``--out``.

``--no-<lever>`` switches off one of the driver's own measures that are not
parameters (``LEVERS``: the frozen start-up heap, the fast reconnect, the
prompt reopen), for A/B runs; the parameter ``realtime_priority`` is passed
as ``-p`` as usual. Two levers measured and left out of the driver can be
put in: ``--reader-cpu N`` pins the reader thread to CPU N,
``--switch-interval S`` sets the interpreter lock switch interval.
The JSON also holds every port open (time) for the reconnect benchmark.

Usage: ``latency_node.py [--stages] [--no-gc-freeze] --out OUT.json --ros-args -p ...``.
"""

import argparse
import functools
import gc
import json
import os
from pathlib import Path
import select
import signal
import sys
import threading
import time
import types

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from i3dmgx2_driver.codec.parser import SensorStreamParser  # noqa: E402
from i3dmgx2_driver.device import port as port_module  # noqa: E402
from i3dmgx2_driver.device import realtime  # noqa: E402
from i3dmgx2_driver.device.clock import DeviceClock  # noqa: E402
from i3dmgx2_driver.device.link import DeviceLink  # noqa: E402
from i3dmgx2_driver.device.port import SerialPort  # noqa: E402
from i3dmgx2_driver.ros import driver_core, imu_node  # noqa: E402
from i3dmgx2_driver.ros import main as node_main  # noqa: E402
from i3dmgx2_driver.ros.conversions import MessageFactory  # noqa: E402

#: Stage marks, in path order: index in the marks list -> name; then the reader thread's
#: CPU time when select() returned (its CPU time after publish() is noted with each row).
STAGES = ('select', 'read', 'parse', 'stamp', 'pack', 'cpu_select')
_SELECT, _READ, _PARSE, _STAMP, _PACK, _CPU_SELECT = range(len(STAGES))


def _without_gc_freeze() -> None:
    realtime.freeze_startup_heap = lambda: 0


def _supervisor_without(**switches: bool) -> None:
    driver_core.DeviceConfig = functools.partial(driver_core.DeviceConfig, **switches)


#: The driver's own measures that an A/B run may switch off: flag -> how.
LEVERS = {'gc-freeze': _without_gc_freeze,
          'fast-reconnect': lambda: _supervisor_without(fast_reconnect=False),
          'prompt-reopen': lambda: _supervisor_without(prompt_reopen=False)}


def _timed(function, marks: list[float], index: int, clock=time.time):
    """Wrap ``function`` so that the time it returned lands in ``marks[index]``."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        result = function(*args, **kwargs)
        marks[index] = clock()
        return result
    return wrapper


def install_stage_timers(marks: list[float]) -> None:
    """Put the stage wrappers in place (before the node is created)."""
    timed = _timed(select.select, marks, _SELECT)

    def timed_select(*args):
        result = timed(*args)
        marks[_CPU_SELECT] = time.thread_time()
        return result

    timed_select = types.SimpleNamespace(select=timed_select)
    port_module.select = timed_select

    class _TimedOs:
        read = staticmethod(_timed(os.read, marks, _READ))

        def __getattr__(self, name):
            return getattr(os, name)

    port_module.os = _TimedOs()
    SensorStreamParser.feed = _timed(SensorStreamParser.feed, marks, _PARSE)
    DeviceClock.stamp = _timed(DeviceClock.stamp, marks, _STAMP)
    MessageFactory.imu_cdr = _timed(MessageFactory.imu_cdr, marks, _PACK)


class GcLog:
    """Every garbage collection: generation, start and duration."""

    def __init__(self) -> None:
        self.events: list[tuple[int, float, float]] = []
        self._start = 0.0

    def __call__(self, phase: str, info: dict) -> None:
        now = time.time()
        if phase == 'start':
            self._start = now
        else:
            self.events.append((info['generation'], self._start, now - self._start))


def note_port_opens(opens: list[float]) -> None:
    """Note the time right after every successful open of the port."""
    original = SerialPort.__init__

    @functools.wraps(original)
    def observed(self, *args, **kwargs) -> None:
        original(self, *args, **kwargs)
        opens.append(time.time())

    SerialPort.__init__ = observed


def pin_reader(cpu: int) -> None:
    """Make every reader thread pin itself to ``cpu`` before its first read."""
    run = DeviceLink._run

    @functools.wraps(run)
    def pinned(self) -> None:
        os.sched_setaffinity(0, {cpu})
        run(self)

    DeviceLink._run = pinned


def _thread_policy() -> dict:
    """Scheduling policy, priority and CPUs of every thread of this process."""
    out = {}
    for thread in threading.enumerate():
        tid = thread.native_id
        try:
            out[thread.name] = {'policy': os.sched_getscheduler(tid),
                                'priority': os.sched_getparam(tid).sched_priority,
                                'cpus': sorted(os.sched_getaffinity(tid))}
        except OSError:
            continue
    return out


def main() -> int:
    """Run the node with the observers; save the rows on shutdown."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1], allow_abbrev=False)
    parser.add_argument('--out', required=True)
    parser.add_argument('--stages', action='store_true', help='time each stage of the path')
    for lever in LEVERS:
        parser.add_argument(f'--no-{lever}', action='store_true',
                            help=f'switch off the {lever} measure')
    parser.add_argument('--reader-cpu', type=int, default=-1,
                        help='pin the reader thread to this CPU')
    parser.add_argument('--switch-interval', type=float, default=None,
                        help='the interpreter lock switch interval (s), instead of 5 ms')
    args, ros_args = parser.parse_known_args()
    for lever, switch_off in LEVERS.items():
        if getattr(args, f'no_{lever.replace("-", "_")}'):
            switch_off()
    # The latest time of each stage, written by the reader thread only.
    marks = [0.0] * len(STAGES)
    if args.reader_cpu >= 0:
        pin_reader(args.reader_cpu)
    if args.switch_interval is not None:
        sys.setswitchinterval(args.switch_interval)
    stages = args.stages
    if stages:
        install_stage_timers(marks)
    started = time.monotonic()
    gc_log = GcLog()
    gc.callbacks.append(gc_log)
    opens: list[float] = []
    note_port_opens(opens)
    rows: list[tuple] = []
    ready = threading.Event()

    class TimedNode(imu_node.ImuDriverNode):
        """The driver node, with the collector on its hook."""

        def __init__(self, *a, **k) -> None:
            super().__init__(*a, **k)
            self.core.on_published = self._note

        def _note(self, record, read_time: float, stamp: float, clock=time.time) -> None:
            now = clock()
            cpu = time.thread_time() if stages else 0.0
            rows.append((record.timer, read_time, now, *marks, cpu))
            if not ready.is_set():
                ready.set()
                print('ready', flush=True)

        def shutdown(self) -> None:
            policy = _thread_policy()
            # What a full collection costs now: what one would add to a sample it delays.
            gc.callbacks.remove(gc_log)
            stats_before = gc.get_stats()
            start = time.perf_counter()
            gc.collect()
            full_collection = time.perf_counter() - start
            super().shutdown()
            document = {'fields': ['timer', 'read', 'published', *STAGES, 'cpu_published'],
                        'rows': rows, 'gc': gc_log.events, 'threads': policy,
                        'gc_frozen': gc.get_freeze_count(), 'pid': os.getpid(),
                        'opens': opens, 'full_collection': full_collection,
                        'gc_stats': stats_before, 'lifetime': time.monotonic() - started}
            with open(args.out, 'w') as handle:
                json.dump(document, handle)

    node_main.ImuDriverNode = TimedNode

    def watch_stdin() -> None:
        # End of input stops the node as SIGTERM does: a benchmark that dies leaves nothing.
        sys.stdin.read()
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch_stdin, daemon=True).start()
    return node_main.main([sys.argv[0], *ros_args])


if __name__ == '__main__':
    sys.exit(main())
