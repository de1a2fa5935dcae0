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
The real driver node, with its counters written to a JSON file for the soak campaign.

Runs the driver node as ``ros2 run`` does (``i3dmgx2_driver.ros.main.run``),
made with the node's own means to be observed, nothing of it replaced: a ROS
timer that writes the node's ``stats``, the parser counters summed over every
connection (``supervisor.status().parser``) and the supervisor's counters to the
file named by ``$I3DMGX2_SOAK_STATS`` twice a second and once more after
shutdown; a serial port (``port_factory``) that notes the time of every open,
input flush and close; and a hot-path observer (``timings``) that notes every
link up, when the node re-anchors (its reader publishes every record from then
on). They tell the campaign when the node could read the port (records written
outside those windows may be lost legitimately). Nothing on the path of a
sample is changed.

With ``--lifecycle`` (before ``--ros-args``) it runs the managed node the
same way: each configure makes a new core, and the file holds the counters
of the last one (``configures`` says which); an activate is noted as an
anchor once it returns (records are published from then on), a deactivate
as ``deactivate`` when it begins (they are not published from then on).

With ``$I3DMGX2_TRACEMALLOC`` naming a directory, it also traces its
allocations (``tracemalloc``) and writes a snapshot there every minute
(``$I3DMGX2_TRACEMALLOC_PERIOD`` s) and at the end: ``HeapSnapshots``;
``benchmarks/heap_sites.py`` reads them.

Usage: ``I3DMGX2_SOAK_STATS=out.json python -m harness.instrumented_node
[--lifecycle] --ros-args -p port:=... -p address:=...``.
"""

import collections
from collections.abc import Callable
import gc
import json
import os
import sys
import threading
import time

from harness.glibc_heap import mallinfo2, malloc_arenas
from harness.type_cache import TypeCacheReader
from i3dmgx2_driver import lifetime
from i3dmgx2_driver.device.hot_path import QuietObserver
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.ros import main as node_main
from i3dmgx2_driver.ros.imu_node import ImuDriverNode
from i3dmgx2_driver.ros.lifecycle_node import LifecycleDriverNode

#: Environment variable naming the JSON file the counters go to.
STATS_ENV = 'I3DMGX2_SOAK_STATS'
#: How often the counters are written while the node runs (s).
DUMP_PERIOD = 0.5

#: Environment variable that sets how many port events are kept (default EVENTS_KEPT).
EVENTS_ENV = 'I3DMGX2_SOAK_EVENTS'
#: Port events kept (the newest): far more than a leg makes, so that an hour's run in
#: one process holds a bounded list rather than one that grows with every fault. A run
#: that reads no events (benchmarks/memory_curve.py) sets 0 in EVENTS_ENV: the list and
#: its copy in every write are the rig's memory, not the node's.
EVENTS_KEPT = int(os.environ.get(EVENTS_ENV, '4096'))

#: Environment variable naming a directory for heap snapshots (tracemalloc), off if unset.
TRACEMALLOC_ENV = 'I3DMGX2_TRACEMALLOC'
#: Environment variable that sets the seconds between snapshots (default TRACEMALLOC_PERIOD).
TRACEMALLOC_PERIOD_ENV = 'I3DMGX2_TRACEMALLOC_PERIOD'
TRACEMALLOC_PERIOD = 60.0
#: Frames kept of each allocation's traceback.
TRACEMALLOC_FRAMES = 25

_events: collections.deque[tuple[str, float, int]] = collections.deque(maxlen=EVENTS_KEPT)
_events_lock = threading.Lock()
_connection = [0]


def _note(kind: str, at: float | None = None) -> None:
    with _events_lock:
        _events.append((kind, time.time() if at is None else at, _connection[0]))


class ObservedPort(SerialPort):
    """A SerialPort that notes when it was opened, flushed and closed."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        with _events_lock:
            _connection[0] += 1
        _note('open')

    def flush_input(self) -> None:
        """
        Flush, and note when the flush began.

        What was written before is gone; what was written from then on may
        wait in the queue and be read after the next anchor (read_windows.py).
        """
        began = time.time()
        super().flush_input()
        _note('flush', began)

    def close(self) -> None:
        """Note the time, then close: the reader has stopped by now."""
        _note('close')
        super().close()


class ObservedLifecycleNode(LifecycleDriverNode):
    """The managed node, its activations and deactivations noted, its last core kept."""

    def __init__(self, **kwargs) -> None:
        #: The core of the last configure (kept after cleanup, for the counters).
        self.last_core = None
        self.configures = 0
        super().__init__(**kwargs)

    def on_configure(self, state):  # noqa: ANN001, ANN201 - rclpy's signature
        """Configure; keep the core made."""
        result = super().on_configure(state)
        if self.core is not None:
            self.last_core = self.core
            self.configures += 1
        return result

    def on_activate(self, state):  # noqa: ANN001, ANN201
        """Activate; note the anchor once records are published."""
        result = super().on_activate(state)
        _note('anchor')
        return result

    def on_deactivate(self, state):  # noqa: ANN001, ANN201
        """Note that publishing ends, then deactivate."""
        _note('deactivate')
        return super().on_deactivate(state)


#: Environment variable that, set to 1, adds the heaps' detail to the figures
#: (``heap_figures``): what the type cache keeps and glibc's arenas. Off by default:
#: reading the type cache holds the GIL for a few ms, which the soak's stamps would see.
HEAP_DETAIL_ENV = 'I3DMGX2_HEAP_DETAIL'
#: Environment variable that, set to S, has the node run a full collection every S
#: seconds (with the detail): the level right after it, taken often, is what the
#: node keeps alive. Off by default: the node's own collections are rare, and that
#: rarity is part of what the curve measures.
HEAP_COLLECT_ENV = 'I3DMGX2_HEAP_COLLECT_EVERY'


class HeapFigures:
    """
    What the process's heaps hold in use, beside its RSS.

    RSS also counts memory an allocator keeps after it was freed (glibc's
    arenas, CPython's 1-MiB object arenas partly used), so a slope of RSS alone
    cannot tell a leak from an allocator settling: a leak shows in these too.
    ``python_blocks``: CPython's allocated memory blocks (objects alive);
    ``malloc_in_use_kib``: the C heap in use over all arenas (None off glibc),
    ``malloc_mmapped_kib`` the part of it in chunks of their own mapping (one
    large buffer shows there). With ``detail``: ``type_cache_names``, the
    blocks CPython's type cache alone keeps (bounded, ``harness/type_cache.py``;
    None where it cannot be read), ``malloc_arenas``, glibc's arenas, and the
    blocks and the type cache's names right after the last full collection
    (``after_full_gc``, with ``full_collections`` so far), and
    ``threads_started``, the Python threads the process started so far (each
    new one rebuilds ``threading``'s table of running threads in the next of
    glibc's arenas: docs/soak.md, "The end of the curve"): the blocks at any
    moment also count garbage in reference cycles that waits for the collector,
    which comes and goes by thousands; right after a full collection none of it
    is left, so a level that rises there is objects kept. Taken by a callback
    of the collector's own (``gc.callbacks``): the node's collections, not one
    this rig runs.
    """

    def __init__(self, detail: bool, collect_every: float = 0.0) -> None:
        self._type_cache = TypeCacheReader() if detail else None
        self._detail = detail
        self._collect_every = collect_every
        self._next_collect = time.monotonic() + collect_every
        self._after_full_gc: dict = {'full_collections': 0, 'blocks': None, 'type_cache': None}
        self._threads_started = threading.active_count()
        self._thread_start = start = threading.Thread.start

        def counted_start(thread: threading.Thread) -> None:
            self._threads_started += 1
            start(thread)

        self._counted_start = counted_start
        if detail:
            gc.callbacks.append(self._collected)
            threading.Thread.start = counted_start

    def close(self) -> None:
        """Take the callback off the collector and the count off threads (as in a test)."""
        if self._collected in gc.callbacks:
            gc.callbacks.remove(self._collected)
        if threading.Thread.start is self._counted_start:
            threading.Thread.start = self._thread_start

    def _collected(self, phase: str, info: dict) -> None:
        if phase == 'stop' and info['generation'] == 2:
            self._after_full_gc = {
                'full_collections': self._after_full_gc['full_collections'] + 1,
                'blocks': sys.getallocatedblocks(),
                'type_cache': self._type_cache.names_kept()}

    def __call__(self) -> dict:
        """Return the figures now."""
        figures = {'python_blocks': sys.getallocatedblocks(), 'malloc_in_use_kib': None,
                   'malloc_mmapped_kib': None}
        info = mallinfo2()
        if info is not None:
            figures['malloc_in_use_kib'] = (info.uordblks + info.hblkhd) // 1024
            figures['malloc_mmapped_kib'] = info.hblkhd // 1024
        if self._detail:
            if self._collect_every and time.monotonic() >= self._next_collect:
                self._next_collect += self._collect_every
                gc.collect()  # the callback takes the figures right after it
            figures['type_cache_names'] = self._type_cache.names_kept()
            figures['malloc_arenas'] = malloc_arenas()
            figures['after_full_gc'] = dict(self._after_full_gc)
            figures['threads_started'] = self._threads_started
        return figures


heap_figures = HeapFigures(os.environ.get(HEAP_DETAIL_ENV) == '1',
                           float(os.environ.get(HEAP_COLLECT_ENV, '0')))


def _snapshot(node, final: bool) -> dict:
    core = node.core if node.core is not None else getattr(node, 'last_core', None)
    if core is None:
        return {'time': time.time(), 'final': final, 'pid': os.getpid(), 'configures': 0,
                'heap': heap_figures()}
    stats = core.records.stats
    device = core.supervisor.status()
    with _events_lock:
        events = list(_events)
    return {
        'time': time.time(),
        'final': final,
        'pid': os.getpid(),
        'configures': getattr(node, 'configures', 1),
        'stats': {name: getattr(stats, name) for name in (
            'published', 'unpublished', 'mag_published', 'lost', 'other_records',
            'device_resets')},
        'parser': device.parser,
        'supervisor': {'connections': device.connections, 'reconnects': device.reconnects,
                       'stalls': device.stalls, 'state': device.state.value,
                       'last_error': device.last_error},
        'port_events': events,
        'heap': heap_figures(),
    }


def _write(path: str, document: dict) -> None:
    """
    Write ``document`` as JSON to ``path`` whole (a reader never sees half of it).

    ``json.dumps``, not ``json.dump``: to a file, json encodes with closures of
    its own that refer to each other, a reference cycle at every write, which
    twice a second kept the node's collector busy and its old generation full of
    the rig's garbage (3,800 objects a minute, most of the CPython blocks the
    memory curve saw come and go); the C encoder behind ``dumps`` makes none.
    """
    temporary = f'{path}.tmp'
    text = json.dumps(document)
    with open(temporary, 'w') as handle:
        handle.write(text)
    os.replace(temporary, path)


class HeapSnapshots:
    """
    Heap snapshots of the node's own process, at intervals and once at the end.

    The memory curve shows how much the process's heaps hold, not where it
    was allocated; tracemalloc run in the benchmark's process saw the
    simulator's allocations too, which drowned the node's. Here, every
    ``period`` s, a thread writes ``NNNN.tracemalloc`` (a ``tracemalloc``
    snapshot, its tracebacks ``TRACEMALLOC_FRAMES`` deep) and ``NNNN.json``:
    the blocks allocated, the collector's counts and statistics per
    generation, the objects it tracks by type, and the supervisor's counters
    (``counters()``), to put the snapshots against the faults met. The
    collector is not run here: what waits for a full collection is part of
    what the curve sees. The last pair is written as the node ends. Tracing
    slows the node several times and its tables grow the C heap: it is for
    finding where CPython objects are kept, never for timings or the C heap.
    """

    def __init__(self, directory: str, period: float,
                 counters: Callable[[], dict[str, int]]) -> None:
        import tracemalloc
        self._tracemalloc = tracemalloc
        self._directory = directory
        self._period = period
        self._counters = counters
        self._count = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        os.makedirs(directory, exist_ok=True)
        tracemalloc.start(TRACEMALLOC_FRAMES)
        self._thread = threading.Thread(target=self._run, name='heap-snapshots', daemon=True)

    def start(self) -> 'HeapSnapshots':
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self._period):
            self.write()

    def write(self, final: bool = False) -> None:
        """Write one snapshot and its figures (``final``: the one as the node ends)."""
        with self._lock:
            stem = os.path.join(self._directory, f'{self._count:04d}')
            self._count += 1
            types = collections.Counter(type(o).__qualname__ for o in gc.get_objects())
            figures = {
                'time': time.time(), 'final': final, 'python_blocks': sys.getallocatedblocks(),
                'gc_count': gc.get_count(), 'gc_stats': gc.get_stats(),
                'gc_frozen': gc.get_freeze_count(), 'threads': threading.active_count(),
                'counters': self._counters(), 'types': dict(types.most_common(400))}
            self._tracemalloc.take_snapshot().dump(f'{stem}.tracemalloc')
            _write(f'{stem}.json', figures)

    def stop(self) -> None:
        """Stop the thread and write the last snapshot."""
        self._stop.set()
        self._thread.join(self._period + 5.0)
        self.write(final=True)


def _counters(made: list) -> dict[str, int]:
    """Return the supervisor's connections, reconnects and stalls so far (none before)."""
    node = made[0] if made else None
    core = None if node is None else (
        node.core if node.core is not None else getattr(node, 'last_core', None))
    if core is None:
        return {}
    device = core.supervisor.status()
    return {'connections': device.connections, 'reconnects': device.reconnects,
            'stalls': device.stalls}


class LinkEvents(QuietObserver):
    """A hot-path observer that notes every link up ('anchor'); it times nothing."""

    def connected(self) -> None:
        """Note the re-anchoring: every record is published from now on."""
        _note('anchor')


def main() -> int:
    """Run the driver node, observed; write its counters as it runs and once at the end."""
    # As the node's own main: a benchmark stopped or killed takes its node with it
    # (one outlived a memory curve stopped with SIGTERM, streaming on until found).
    lifetime.die_with_parent()
    path = os.environ.get(STATS_ENV)
    if not path:
        print(f'{STATS_ENV} must name the file for the counters', file=sys.stderr)
        return 2
    made: list[ImuDriverNode] = []
    arguments = sys.argv[1:sys.argv.index('--ros-args')] if '--ros-args' in sys.argv \
        else sys.argv[1:]
    kind = ObservedLifecycleNode if '--lifecycle' in arguments else ImuDriverNode

    def make_node() -> ImuDriverNode:
        node = kind(timings=LinkEvents(), port_factory=ObservedPort)
        node.create_timer(DUMP_PERIOD, lambda: _write(path, _snapshot(node, False)))
        made.append(node)
        return node

    traced = os.environ.get(TRACEMALLOC_ENV)
    snapshots = HeapSnapshots(traced, float(os.environ.get(
        TRACEMALLOC_PERIOD_ENV, TRACEMALLOC_PERIOD)),
        lambda: _counters(made)).start() if traced else None
    code = node_main.run(make_node)
    if made:
        _write(path, _snapshot(made[0], True))
    if snapshots is not None:
        lifetime.cancel_deadline()  # the last snapshot is no part of the stop
        snapshots.stop()
    return code


if __name__ == '__main__':
    sys.exit(main())
